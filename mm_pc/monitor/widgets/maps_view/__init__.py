"""The Maps tab (one widget, three files): :mod:`.view`, the grid image (:mod:`.grid_item`)
and the "New map…" dialog (:mod:`.dialog`); its model is :mod:`mm_pc.monitor.model.maps`."""

from mm_pc.monitor.widgets.maps_view.view import MapsView

__all__ = ["MapsView"]
