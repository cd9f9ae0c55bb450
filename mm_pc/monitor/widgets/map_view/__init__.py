"""The Map tab: robot, sensors and their paths in the odom frame (one widget, three files).

:mod:`.view` is the widget, :mod:`.raster` the image the paths are drawn on; the pure
parts are :mod:`mm_pc.monitor.model.path_decimator` and ``screen_rects``.
"""

from mm_pc.monitor.widgets.map_view.view import MAX_WIDTH_M, MIN_WIDTH_M, MapView

__all__ = ["MAX_WIDTH_M", "MIN_WIDTH_M", "MapView"]
