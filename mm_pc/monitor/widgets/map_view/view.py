"""Map / track path view: the robot, its sensors and their paths in the odom frame.

Odom x points right on the screen, y up; everything in metres. The robot is
drawn as an outline with a heading arrow at the session's current pose, each
sensor as a dot with its own axis arrows (sensor +Y = robot forward, sensor
+X = robot right, turned by the mount's yaw error). The paths are the session's
``map_history`` columns ``x, y`` (robot) and ``s{k}_wx, s{k}_wy`` (sensor k): one
row per reply, or the reply's per-poll poses where it brought its single polls.

An hour at 100 Hz is 360 000 rows per path, so the paths are decimated
(:class:`~mm_pc.monitor.model.path_decimator.PathDecimator`: the coarsest level below half
a pixel) and held as one image (:class:`~.raster.PathRaster`); one light line per path joins
the image's last point to the newest row. Stretches the session stepped over without
single polls (``session.gaps``: ring overrun, a failed fetch) are drawn dashed in
``GAP_COLOUR`` over the path, a node restart as a dashed cross. Measurements:
docs/monitor.md.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QCheckBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSlider,
    QVBoxLayout,
    QWidget,
)

from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.path_decimator import PathDecimator
from mm_pc.monitor.model.screen_rects import inside
from mm_pc.monitor.widgets.map_view.items import (
    DrawnPath,
    Lines,
    MapViewBox,
    arrow_segments,
    colour_icon,
    sensor_dot,
)
from mm_pc.monitor.widgets.map_view.pointer import MapPointer
from mm_pc.monitor.widgets.map_view.raster import PathRaster
from mm_pc.monitor.widgets.style import (
    GAP_COLOUR,
    ROBOT_COLOUR,
    STALE_STYLE,
    sensor_colour,
    stale_text,
)

__all__ = [
    "MAX_WIDTH_M",
    "MIN_WIDTH_M",
    "MapView",
    "PathDecimator",
]

#: Range of the zoom slider: visible width of the map (m), log scale.
MIN_WIDTH_M, MAX_WIDTH_M = 0.2, 200.0
SLIDER_STEPS = 1000
#: the pose readout's tooltip while it is live
POSE_TIP = "the robot's pose in the odom frame: x, y (m) and yaw (deg, counter-clockwise)"
DEFAULT_WIDTH_M = 1.0

#: Grid spacings (m): the 10 cm squares, and coarser lines for zoomed-out views.
GRID_STEPS_M = (0.1, 1.0, 10.0, 100.0)
GRID_COLOURS = ("#e4e4e4", "#c4c4c4", "#9a9a9a", "#707070")
GRID_MIN_PX = 8.0  # a grid level whose lines would be closer than this is hidden

#: Follow mode re-centres once the robot is more than this fraction of the visible
#: width (or height) off the centre. A pan repaints the axes and moves the raster (a
#: sixth of a core at 30 frames/s when it pans every frame, docs/benchmarks.md), so
#: the view stays put while the robot crosses its middle and then jumps to it.
FOLLOW_ZONE = 0.15
#: Most history rows one refresh takes in (an hour arriving at once is taken in over
#: several frames instead of freezing the window for one long one).
MAX_ROWS_PER_REFRESH = 10_000

#: Width of the map's left axis (labels like "-123.4" fit).
AXIS_WIDTH_PX = 62

#: Fit path: the paths' box grown by the robot's reach from its centre (outline and
#: heading arrow, m) on every side, then by this fraction of the width on each side.
ROBOT_EXTENT_M = 0.15
FIT_MARGIN = 0.05

#: Sensor axis arrows and robot heading arrow (m, drawn to scale).
AXIS_ARROW_M = 0.025
HEADING_ARROW_M = 0.10


class MapView(QWidget):
    """Map of the robot, both sensors and their paths (odom frame, metres).

    Toolbar: zoom slider (visible width 0.2 m ... 200 m, log scale), follow
    robot, fit path, show/hide each path, reset path and values.
    Mouse: wheel zooms, drag pans (and ends follow mode); the cursor's odom coordinates
    show in the map's corner, and **Measure** measures a distance by two clicks
    (:mod:`.pointer`).
    """

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self._seen: tuple | None = None
        self._dirty = True
        self._follow_pending = False
        self._refresh_ms: list[float] = []
        self.paths: dict[object, DrawnPath] = {}
        self.path_checks: dict[object, QCheckBox] = {}
        self.sensor_items: list[dict] = []

        self.vb = MapViewBox()
        self.plot = pg.PlotWidget(viewBox=self.vb, background="w")
        self.plot.hideButtons()
        self.plot.setMenuEnabled(False)
        self.vb.setAspectLocked(True)
        self.vb.setLimits(minXRange=MIN_WIDTH_M / 2, maxXRange=MAX_WIDTH_M * 2)
        for side, name in (("bottom", "x (odom) [m]"), ("left", "y (odom) [m]")):
            axis = self.plot.getAxis(side)
            axis.setPen(pg.mkPen("#444444"))
            axis.setTextPen(pg.mkPen("#222222"))
            axis.enableAutoSIPrefix(False)  # metres on both axes, whatever the zoom
            # one level of ticks and labels: the axes are redrawn with every pan (follow)
            axis.setStyle(maxTickLevel=1, maxTextLevel=1)
            self.plot.setLabel(side, name)
        # a fixed width: labels growing a digit would resize the map, and a new size
        # means drawing all paths anew
        self.plot.getAxis("left").setWidth(AXIS_WIDTH_PX)
        self.grid = []
        self._grid_key: tuple | None = None  # (pixel size, area) the grid lines were made for
        for z, colour in enumerate(GRID_COLOURS):
            item = Lines(pg.mkPen(colour, width=1), connect="pairs")
            item.setZValue(-10 + z)
            self.vb.addItem(item, ignoreBounds=True)
            self.grid.append(item)

        self.raster = PathRaster()
        self.vb.addItem(self.raster, ignoreBounds=True)
        pen = pg.mkPen(GAP_COLOUR, width=3)
        pen.setStyle(Qt.PenStyle.DashLine)
        self.gap_lines = Lines(pen, connect="pairs")
        self.gap_lines.setZValue(15)  # over the paths, under the robot
        self.vb.addItem(self.gap_lines, ignoreBounds=True)
        self._gaps_drawn: tuple | None = None
        self._build_toolbar()
        self._build_robot_items()
        self._add_path("robot", "robot", ROBOT_COLOUR, 2.0, ("x", "y"))
        self.pointer = MapPointer(self.vb, self.plot, self.measure_button)

        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addLayout(self.toolbar)
        lay.addWidget(self.plot, 1)

        self.vb.sigRangeChanged.connect(self._on_range_changed)
        self.vb.user_panned.connect(lambda: self.follow_check.setChecked(False))
        ctx.devices_known.connect(self._on_devices)
        ctx.session_reset.connect(self.clear_paths)
        ctx.odometry_changed.connect(self._mark_dirty)
        ctx.calibration_changed.connect(self._mark_dirty)  # the sensors move to the fit
        ctx.data_state_changed.connect(self._show_stale)
        self.vb.setRange(xRange=(-DEFAULT_WIDTH_M / 2, DEFAULT_WIDTH_M / 2),
                         yRange=(-DEFAULT_WIDTH_M / 2, DEFAULT_WIDTH_M / 2), padding=0)
        self._ensure_sensors()

    def _show_stale(self, *_args) -> None:
        """Grey the pose readout while the link is lost or polling paused: the robot may
        move on while the map cannot show it; the tooltip says since when."""
        text = stale_text(self.ctx)
        self.pose_label.setStyleSheet(STALE_STYLE if text else "")
        self.pose_label.setToolTip(f"the last pose known: {text}" if text else POSE_TIP)

    # -- construction ---------------------------------------------------------------------

    def _build_toolbar(self) -> None:
        bar = QHBoxLayout()
        bar.setContentsMargins(0, 0, 0, 0)
        bar.addWidget(QLabel("Zoom"))
        self.zoom_slider = QSlider(Qt.Orientation.Horizontal)
        self.zoom_slider.setRange(0, SLIDER_STEPS)
        self.zoom_slider.setMinimumWidth(80)  # 800 px windows: the map's width decides
        self.zoom_slider.setToolTip(
            f"visible width of the map, {MIN_WIDTH_M:g} m to {MAX_WIDTH_M:g} m (log scale)"
        )
        self.zoom_slider.valueChanged.connect(self._on_slider)
        bar.addWidget(self.zoom_slider)
        self.width_label = QLabel("")
        self.width_label.setMinimumWidth(60)
        bar.addWidget(self.width_label)
        self.follow_check = QCheckBox("Follow robot")
        self.follow_check.setChecked(True)
        self.follow_check.setToolTip(
            "keep the robot in the middle of the view (it re-centres once the robot is "
            f"{FOLLOW_ZONE:.0%} of the view off the centre); dragging the map ends it"
        )
        self.follow_check.toggled.connect(self._on_follow)
        bar.addWidget(self.follow_check)
        self.fit_button = QPushButton("Fit path")
        self.fit_button.setToolTip("zoom to show every path")
        self.fit_button.clicked.connect(self.fit_paths)
        bar.addWidget(self.fit_button)
        self.measure_button = QPushButton("Measure")
        self.measure_button.setCheckable(True)
        self.measure_button.setToolTip("measure a distance: click a first point, then a "
                                       "second; a third click starts again")
        bar.addWidget(self.measure_button)
        bar.addStretch(1)
        self.reset_button = QPushButton("Reset")
        self.reset_button.setToolTip("reset path and values: clear the paths and put the "
                                     "robot back to the origin")
        self.reset_button.clicked.connect(self.ctx.reset)
        bar.addWidget(self.reset_button)
        second = QHBoxLayout()
        second.setContentsMargins(0, 0, 0, 0)
        # the checkboxes name the paths (sensor's colour icons): no "Paths:" label, so the
        # row fits an 800 px window
        self.path_bar = QHBoxLayout()
        second.addLayout(self.path_bar)
        second.addStretch(1)
        self.pose_label = QLabel(_pose_text(0.0, 0.0, 0.0))
        self.pose_label.setToolTip(POSE_TIP)
        second.addWidget(self.pose_label)
        self.toolbar = QVBoxLayout()
        self.toolbar.setSpacing(2)
        self.toolbar.addLayout(bar)
        self.toolbar.addLayout(second)

    def _build_robot_items(self) -> None:
        # Everything on the robot is drawn in base_link inside one group that the pose moves.
        self.body = pg.ItemGroup()
        self.body.setZValue(20)
        self.vb.addItem(self.body, ignoreBounds=True)
        pen = pg.mkPen(ROBOT_COLOUR, width=2)
        self.robot_outline = Lines(pen)
        self.robot_heading = Lines(pen, connect="pairs")
        self.body.addItem(self.robot_outline)
        self.body.addItem(self.robot_heading)
        self._body_key: tuple | None = None
        self._body_size = 0.1
        # A marker of fixed screen size, so the robot can be found when zoomed far out.
        self.robot_marker = pg.ArrowItem(
            angle=180, headLen=14, tailLen=0, brush=ROBOT_COLOUR, pen=pg.mkPen(ROBOT_COLOUR)
        )
        self.robot_marker.setZValue(25)
        self.vb.addItem(self.robot_marker, ignoreBounds=True)

    def _add_path(self, key, label: str, colour: str, width: float, columns) -> None:
        path = DrawnPath(self.vb, key, colour, width, columns)
        self.paths[key] = path
        check = QCheckBox(label)
        check.setIcon(colour_icon(colour))
        check.setChecked(True)
        check.setToolTip(f"show the path of {label} (history columns {columns[0]}, {columns[1]})")
        check.toggled.connect(lambda on, k=key: self.set_path_visible(k, on))
        self.path_bar.addWidget(check)
        check.show()  # the layout would only show it from the event loop
        self.path_checks[key] = check

    def _ensure_sensors(self) -> None:
        """Create the items of sensors not drawn yet (the devices may come late)."""
        devices = self.ctx.session.devices
        for k in range(len(self.sensor_items), len(devices)):
            colour = sensor_colour(k)
            dot = sensor_dot(colour)
            axes = Lines(pg.mkPen(colour, width=2), connect="pairs")
            labels = []
            for text in ("X", "Y"):
                t = pg.TextItem(text, color=colour, anchor=(0.5, 0.5))
                labels.append(t)
            for item in (axes, dot, *labels):
                item.setZValue(1)
                self.body.addItem(item)
            self.sensor_items.append({"dot": dot, "axes": axes, "labels": labels})
            self._add_path(k, f"sensor {k + 1}", colour, 1.0, (f"s{k}_wx", f"s{k}_wy"))
            self.path_checks[k].setToolTip(
                f"show the path of sensor {k + 1} ({devices[k]}), history columns s{k}_wx, s{k}_wy"
            )
            self._dirty = True

    # -- slots ----------------------------------------------------------------------------

    def _mark_dirty(self) -> None:
        self._dirty = True

    def _on_devices(self, _devices) -> None:
        self._ensure_sensors()
        self._dirty = True

    def _on_follow(self, on: bool) -> None:
        self._follow_pending = on
        self._dirty = True

    def _on_range_changed(self, *_args) -> None:
        self._update_grid()
        width = self.visible_width()
        pad = 3.0 * width / max(self.vb.width(), 1.0)  # 3 px: room for the pens' width
        lines = [*self.grid, self.robot_outline, self.robot_heading, self.gap_lines,
                 *(p.live for p in self.paths.values()), *(s["axes"] for s in self.sensor_items)]
        for item in lines:
            item.set_pad(pad)
        self.width_label.setText(_format_length(width))
        value = round(SLIDER_STEPS * math.log(max(width, 1e-9) / MIN_WIDTH_M)
                      / math.log(MAX_WIDTH_M / MIN_WIDTH_M))
        self.zoom_slider.blockSignals(True)
        self.zoom_slider.setValue(max(0, min(SLIDER_STEPS, value)))
        self.zoom_slider.blockSignals(False)
        self._dirty = True

    def _on_slider(self, value: int) -> None:
        self.set_visible_width(MIN_WIDTH_M * (MAX_WIDTH_M / MIN_WIDTH_M) ** (value / SLIDER_STEPS))

    # -- public API ---------------------------------------------------------------------------

    def visible_width(self) -> float:
        """Width of the visible map (m)."""
        (x0, x1), _ = self.vb.viewRange()
        return float(x1 - x0)

    def view_centre(self) -> tuple[float, float]:
        (x0, x1), (y0, y1) = self.vb.viewRange()
        return float(x0 + x1) / 2, float(y0 + y1) / 2

    def set_visible_width(self, width: float, centre: tuple[float, float] | None = None) -> None:
        """Show ``width`` metres across (clamped to 0.2 ... 200 m), about ``centre``
        (default: the robot when following, else the current centre)."""
        width = min(max(float(width), MIN_WIDTH_M), MAX_WIDTH_M)
        if centre is None:
            centre = self._robot_xy() if self.follow_check.isChecked() else self.view_centre()
        self._show(centre, width)

    def _show(self, centre: tuple[float, float], width: float) -> None:
        w_px, h_px = max(self.vb.width(), 1.0), max(self.vb.height(), 1.0)
        height = width * h_px / w_px
        cx, cy = centre
        self.vb.setRange(xRange=(cx - width / 2, cx + width / 2),
                         yRange=(cy - height / 2, cy + height / 2), padding=0)

    def fit_paths(self) -> None:
        """Zoom and pan to show every visible path and the robot (leaves follow mode)."""
        self.follow_check.setChecked(False)
        rx, ry = self._robot_xy()
        boxes = [(rx, rx, ry, ry)]
        for path in self.paths.values():
            if path.visible and path.decimator.bounds is not None:
                boxes.append(path.decimator.bounds)
        arr = np.array(boxes, dtype=float)
        x0, x1 = arr[:, 0].min(), arr[:, 1].max()
        y0, y1 = arr[:, 2].min(), arr[:, 3].max()
        w_px, h_px = max(self.vb.width(), 1.0), max(self.vb.height(), 1.0)
        span = max(x1 - x0, (y1 - y0) * w_px / h_px)
        # room for the robot's outline around the path, and a margin of FIT_MARGIN
        width = (span + 2 * ROBOT_EXTENT_M) * (1 + 2 * FIT_MARGIN)
        self.set_visible_width(width, ((x0 + x1) / 2, (y0 + y1) / 2))

    def set_path_visible(self, key, visible: bool) -> None:
        """Show or hide one path: ``"robot"`` or a sensor index (0-based)."""
        path = self.paths[key]
        if path.visible != bool(visible):
            path.set_visible(bool(visible))
        if self.path_checks[key].isChecked() != bool(visible):
            self.path_checks[key].setChecked(bool(visible))
        self._dirty = True

    def path_data(self, key) -> tuple[np.ndarray, np.ndarray]:
        """The points drawn for a path (m, odom), in path order: those of the raster (the
        segments near its area) then the live end, without repeated joining points."""
        path, hist, r = self.paths[key], self.ctx.session.map_history, self.raster
        if hist is None or not path.visible or key not in r.done:
            return np.empty(0), np.empty(0)
        x, y = hist.column(path.columns[0]), hist.column(path.columns[1])
        rows, _ = path.decimator.runs_in(r.level, r.data_rect(r.rect), 0, r.done[key])
        lx, ly = path.live.getData()
        lx = np.empty(0) if lx is None else np.asarray(lx)
        ly = np.empty(0) if ly is None else np.asarray(ly)
        px, py = np.concatenate((x[rows], lx)), np.concatenate((y[rows], ly))
        keep = np.ones(len(px), dtype=bool)
        keep[1:] = (px[1:] != px[:-1]) | (py[1:] != py[:-1])
        return px[keep], py[keep]

    def finish_drawing(self) -> None:
        """Draw now what the raster still has queued off the screen (drawn over the next
        frames otherwise): for tests and exports."""
        hist = self.ctx.session.map_history
        if hist is None or self.raster.image is None:
            return
        shown = [p for p in self._drawing_order() if p.key in self.raster.done]
        self.raster.finish(shown, {p.key: (hist.column(p.columns[0]), hist.column(p.columns[1]))
                                   for p in shown})

    def clear_paths(self) -> None:
        """Forget the drawn paths (the session was reset)."""
        for path in self.paths.values():
            path.decimator.clear()
            path.forget_items()
        self.raster.invalidate()
        self._seen = None
        self._dirty = True

    def render_stats(self) -> dict:
        """What the last refreshes cost and drew (for benchmarks and tests).

        ``raster``: images drawn whole (``full``, the last in ``full_ms``),
        moved (``shifts``), path ends drawn onto it (``commits``), paints;
        ``memory_mb``: the decimators' arrays and the raster image."""
        ms = np.array(self._refresh_ms[-1000:]) if self._refresh_ms else np.zeros(1)
        hist = self.ctx.session.map_history
        r = self.raster
        return {
            "rows": len(hist) if hist is not None else 0,
            "behind": max((len(hist) - p.decimator.rows_seen for p in self.paths.values()),
                          default=0) if hist is not None else 0,
            "refreshes": len(self._refresh_ms),
            "refresh_p50_ms": float(np.percentile(ms, 50)),
            "refresh_p95_ms": float(np.percentile(ms, 95)),
            "refresh_max_ms": float(ms.max()),
            "points": {k: r.done.get(k, 0) for k in self.paths},
            "levels": {k: r.level if k in r.done else None for k in self.paths},
            "raster": {**r.stats, "size": (r.img_w, r.img_h)},
            "memory_mb": {
                "decimators": sum(p.decimator.nbytes for p in self.paths.values()) / 1e6,
                "raster": r.nbytes / 1e6,
            },
        }

    # -- refresh ----------------------------------------------------------------------------------

    def refresh(self) -> None:
        """Redraw what changed since the last call; returns at once when nothing did."""
        hist = self.ctx.session.map_history
        key = (id(hist), hist.version) if hist is not None else None
        if key == self._seen and not self._dirty:
            return
        t0 = time.perf_counter()
        data_changed = key != self._seen
        self._seen = key
        self._dirty = False
        self._ensure_sensors()
        behind = self._take_rows(hist) if hist is not None else False
        self._draw_robot()
        self._draw_gaps()
        if self.follow_check.isChecked() and (data_changed or self._follow_pending):
            self._follow()
        self._draw_paths(hist)
        # our own range changes above need nothing more; rows left over or areas of the
        # raster still to draw (off the screen) bring the next frame here again
        self._dirty = behind or bool(self.raster.todo)
        self._refresh_ms.append((time.perf_counter() - t0) * 1e3)
        if len(self._refresh_ms) > 20_000:
            del self._refresh_ms[:10_000]

    def _follow(self) -> None:
        """Centre the robot once it leaves the middle of the view (``FOLLOW_ZONE``)."""
        rx, ry = self._robot_xy()
        cx, cy = self.view_centre()
        (x0, x1), (y0, y1) = self.vb.viewRange()
        off = abs(rx - cx) > FOLLOW_ZONE * (x1 - x0) or abs(ry - cy) > FOLLOW_ZONE * (y1 - y0)
        if self._follow_pending or off:
            self._show((rx, ry), self.visible_width())
        self._follow_pending = False

    def _take_rows(self, hist) -> bool:
        """Feed new rows to the decimators; True when some are left for the next frame."""
        behind = False
        for path in self.paths.values():
            dec = path.decimator
            if len(hist) < dec.rows_seen or getattr(self, "_dropped", 0) != hist.dropped_rows:
                dec.clear()  # cleared, or the oldest rows were let go: start again
                path.forget_items()
                self.raster.invalidate()
            if path.columns[0] in hist.index:
                end = min(len(hist), dec.rows_seen + MAX_ROWS_PER_REFRESH)
                dec.update(hist.column(path.columns[0])[:end], hist.column(path.columns[1])[:end])
                behind |= end < len(hist)
        self._dropped = hist.dropped_rows
        return behind

    def _drawing_order(self) -> list[DrawnPath]:
        """The paths, sensors first: the robot's is drawn on top."""
        return [p for k, p in self.paths.items() if k != "robot"] + [self.paths["robot"]]

    def _draw_paths(self, hist) -> None:
        """Bring the raster and the live ends up to date (sensors first, the robot on top)."""
        if hist is None:
            return
        pixel = self.visible_width() / max(self.vb.width(), 1.0)
        level = PathDecimator.level_for(pixel)
        shown = [p for p in self._drawing_order() if p.visible and p.columns[0] in hist.index]
        columns = {p.key: (hist.column(p.columns[0]), hist.column(p.columns[1])) for p in shown}
        dpr = max(1, round(self.plot.devicePixelRatioF()))
        boxes = [p.decimator.bounds for p in shown if p.decimator.bounds is not None]
        bounds = (min(b[0] for b in boxes), max(b[1] for b in boxes), min(b[2] for b in boxes),
                  max(b[3] for b in boxes)) if boxes else None
        self.raster.sync(shown, columns, level, self.vb.childTransform(),
                         (float(self.vb.width()), float(self.vb.height())), dpr, bounds)
        for p in shown:
            p.draw_live(level, self.raster.done[p.key], *columns[p.key])

    def gap_segments(self) -> np.ndarray:
        """The gap marks drawn, as (N, 4) rows x0, y0, x1, y1 (m, odom)."""
        x, y = self.gap_lines.getData()
        return np.column_stack([x[0::2], y[0::2], x[1::2], y[1::2]]) if len(x) else np.empty((0, 4))

    def _draw_gaps(self) -> None:
        """Dashed marks over the stretches without single polls (a cross for a restart)."""
        gaps = self.ctx.session.gaps
        key = (id(gaps), len(gaps), gaps[-1] if gaps else None)
        if key == self._gaps_drawn:
            return
        self._gaps_drawn = key
        pts = []
        for g in gaps:
            if (g.x0, g.y0) != (g.x1, g.y1):
                pts += [(g.x0, g.y0), (g.x1, g.y1)]
            else:  # a restart: the pose did not move; a 2 cm cross where it happened
                pts += [(g.x0 - 0.01, g.y0 - 0.01), (g.x0 + 0.01, g.y0 + 0.01),
                        (g.x0 - 0.01, g.y0 + 0.01), (g.x0 + 0.01, g.y0 - 0.01)]
        arr = np.array(pts, dtype=float).reshape(-1, 2)
        self.gap_lines.setData(arr[:, 0], arr[:, 1])

    def _robot_xy(self) -> tuple[float, float]:
        pose = self.ctx.session.pose
        return pose.x, pose.y

    def _build_body(self) -> None:
        """Robot outline, heading arrow and sensor axes in base_link (m); they move as
        one group carried by the pose. Rebuilt when the geometry or calibration changes."""
        mounts = self._drawn_mounts()
        front = max([m.x for m in mounts] + [0.05]) + 0.025
        half = max([abs(m.y) for m in mounts] + [0.04]) + 0.015
        self._body_size = front + 0.035
        body = np.array([(-0.035, -half), (front, -half), (front, half), (-0.035, half),
                         (-0.035, -half)])
        self.robot_outline.setData(body[:, 0], body[:, 1])
        heading = np.array(arrow_segments((0.0, 0.0), (1.0, 0.0), HEADING_ARROW_M, 0.02))
        self.robot_heading.setData(heading[:, 0], heading[:, 1])
        for k, items in enumerate(self.sensor_items):
            if k >= len(mounts):
                continue
            m = mounts[k]
            items["dot"].setPos(m.x, m.y)
            y_axis = (math.cos(m.yaw), math.sin(m.yaw))  # sensor +Y: robot forward
            x_axis = (math.sin(m.yaw), -math.cos(m.yaw))  # sensor +X: robot right
            arr = np.array(arrow_segments((m.x, m.y), x_axis, AXIS_ARROW_M, 0.006)
                           + arrow_segments((m.x, m.y), y_axis, AXIS_ARROW_M, 0.006))
            items["axes"].setData(arr[:, 0], arr[:, 1])
            for label, (ux, uy) in zip(items["labels"], (x_axis, y_axis), strict=True):
                label.setPos(m.x + 1.35 * AXIS_ARROW_M * ux, m.y + 1.35 * AXIS_ARROW_M * uy)
        self._body_key = (mounts, len(self.sensor_items))

    def _drawn_mounts(self) -> tuple:
        """The sensors as built: the calibration's fitted positions and yaws (else geometry)."""
        session = self.ctx.session
        return session.calibration.built_mounts(session.devices, session.mounts)

    def _draw_robot(self) -> None:
        """Move the robot group to the pose; show details only when they are big enough."""
        if self._body_key != (self._drawn_mounts(), len(self.sensor_items)):
            self._build_body()
        pose = self.ctx.session.pose
        self.body.setPos(pose.x, pose.y)
        self.body.setRotation(math.degrees(pose.yaw))  # CCW in odom (the view flips y)
        pixel = self.visible_width() / max(self.vb.width(), 1.0)
        small = self._body_size / pixel < 25
        _show(self.robot_marker, small)
        self.robot_marker.setPos(pose.x, pose.y)
        if small:
            # ArrowItem: tip at its position, angle 0 points left (-x), angles turn clockwise
            # on the screen; so the tip leads in the heading direction
            self.robot_marker.setStyle(angle=180 - math.degrees(pose.yaw))
        for items in self.sensor_items:
            _show(items["axes"], AXIS_ARROW_M / pixel > 12)
            for label in items["labels"]:
                _show(label, AXIS_ARROW_M / pixel > 30)
        self.pose_label.setText(_pose_text(pose.x, pose.y, pose.yaw_wrapped))

    def _update_grid(self) -> None:
        """Grid lines over three views' width and height around the view: made again only
        when the view leaves that area or the zoom changes (not with every follow step)."""
        (x0, x1), (y0, y1) = self.vb.viewRange()
        pixel = (x1 - x0) / max(self.vb.width(), 1.0)
        key = self._grid_key
        if key is not None and abs(key[0] / pixel - 1) < 1e-3 and inside((x0, x1, y0, y1), key[1]):
            return
        w, h = x1 - x0, y1 - y0
        x0, x1, y0, y1 = x0 - w, x1 + w, y0 - h, y1 + h
        self._grid_key = (pixel, (x0, x1, y0, y1))
        for step, item in zip(GRID_STEPS_M, self.grid, strict=True):
            if step / pixel < GRID_MIN_PX:
                item.setVisible(False)
                continue
            xs = np.arange(math.ceil(x0 / step), math.floor(x1 / step) + 1) * step
            ys = np.arange(math.ceil(y0 / step), math.floor(y1 / step) + 1) * step
            gx = np.empty(2 * (len(xs) + len(ys)))
            gy = np.empty_like(gx)
            nx = 2 * len(xs)
            gx[0:nx:2] = gx[1:nx:2] = xs
            gy[0:nx:2], gy[1:nx:2] = y0, y1
            gx[nx::2], gx[nx + 1 :: 2] = x0, x1
            gy[nx::2] = gy[nx + 1 :: 2] = ys
            item.setData(gx, gy)
            item.setVisible(True)


def _show(item, on: bool) -> None:
    """setVisible only on a change (each call into Qt costs; most frames change nothing)."""
    if item.isVisible() != bool(on):
        item.setVisible(bool(on))


def _pose_text(x: float, y: float, yaw: float) -> str:
    return f"x {x:+.3f} m  y {y:+.3f} m  yaw {math.degrees(yaw):+.1f}°"


def _format_length(m: float) -> str:
    """Always in metres (switching between "100 cm" and "1 m" read as a jump)."""
    return f"{m:.3g} m"
