"""Map / track path view: the robot, its sensors and their paths in the odom frame.

Odom x points right on the screen, y up; everything in metres. The robot is
drawn as an outline with a heading arrow at the session's current pose, each
sensor as a dot with its own axis arrows (sensor +Y = robot forward, sensor
+X = robot right, turned by the mount's yaw error). The paths are the history
columns ``x, y`` (robot) and ``s{k}_wx, s{k}_wy`` (sensor k).

An hour at 100 Hz is 360 000 rows per path, so the paths are not handed to
pyqtgraph as they are. :class:`PathDecimator` keeps, incrementally (only the
rows added since the last refresh are looked at), a few decimated copies of a
path: level ``k`` keeps a row only where the path enters a new square cell of
``LEVEL_EPS_M[k]`` (0.5 mm, 2 mm, 8 mm, ...). The view shows the coarsest
level whose cell is below half a screen pixel, so what is dropped cannot be
seen, and only the part near the visible area when that is still many points.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QColor, QIcon, QPixmap
from PySide6.QtWidgets import (
    QCheckBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSlider,
    QVBoxLayout,
    QWidget,
)

from .context import MonitorContext

__all__ = [
    "MAX_WIDTH_M",
    "MIN_WIDTH_M",
    "ROBOT_COLOUR",
    "SENSOR_COLOURS",
    "MapView",
    "PathDecimator",
    "sensor_colour",
]

#: Colours on the white map (also used by the direction widgets).
ROBOT_COLOUR = "#1f3a93"
SENSOR_COLOURS = ("#e67e22", "#2e8b57", "#8e44ad", "#c0392b")

#: Range of the zoom slider: visible width of the map (m), log scale.
MIN_WIDTH_M, MAX_WIDTH_M = 0.2, 200.0
SLIDER_STEPS = 1000
DEFAULT_WIDTH_M = 1.0

#: Grid spacings (m): the 10 cm squares, and coarser lines for zoomed-out views.
GRID_STEPS_M = (0.1, 1.0, 10.0, 100.0)
GRID_COLOURS = ("#e4e4e4", "#c4c4c4", "#9a9a9a", "#707070")
GRID_MIN_PX = 6.0  # a grid level whose lines would be closer than this is hidden

#: Most points a path may hand to pyqtgraph before it is cut to the visible area.
POINT_BUDGET = 20_000
#: Largest decimation cell allowed, as a fraction of one screen pixel.
PIXEL_FRACTION = 0.5

#: Sensor axis arrows and robot heading arrow (m, drawn to scale).
AXIS_ARROW_M = 0.025
HEADING_ARROW_M = 0.10


def sensor_colour(k: int) -> str:
    """Colour of sensor ``k`` (0-based) on the map and in the direction widgets."""
    return SENSOR_COLOURS[k % len(SENSOR_COLOURS)]


class _Grow:
    """A float64 array that grows by doubling (amortised O(1) appends)."""

    def __init__(self, width: int) -> None:
        self.data = np.empty((256, width))
        self.n = 0

    def extend(self, rows: np.ndarray) -> None:
        need = self.n + len(rows)
        if need > len(self.data):
            grown = np.empty((max(need, 2 * len(self.data)), self.data.shape[1]))
            grown[: self.n] = self.data[: self.n]
            self.data = grown
        self.data[self.n : need] = rows
        self.n = need

    @property
    def view(self) -> np.ndarray:
        return self.data[: self.n]


class PathDecimator:
    """Multi-resolution, incrementally decimated copy of one path (no Qt).

    Level ``k`` keeps a point where the path enters a new square cell of side
    ``LEVEL_EPS_M[k]`` (cells are nested: 4 x 4 cells of level k make one of
    level k+1), so every kept point is a point of the path, the first is
    always kept, and a dropped point lies in the cell of the kept point before
    it (at most ``sqrt(2) * eps`` away from the drawn line).
    Points are stored in chunks of ``CHUNK`` with bounding boxes so the part
    near a view rectangle is found without looking at every point.
    """

    EPS0_M = 0.0005
    LEVELS = 6
    LEVEL_EPS_M = (0.0005, 0.002, 0.008, 0.032, 0.128, 0.512)  # EPS0_M * 4**k
    CHUNK = 2048

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget the path."""
        self.rows_seen = 0
        self._last_cell: np.ndarray | None = None  # level-0 cell of the newest finite row
        self._last_point: tuple[float, float] | None = None
        self._bounds = np.array([np.inf, -np.inf, np.inf, -np.inf])  # xmin, xmax, ymin, ymax
        self._points = [_Grow(2) for _ in range(self.LEVELS)]
        self._boxes = [_Grow(4) for _ in range(self.LEVELS)]  # xmin, xmax, ymin, ymax

    @property
    def last_point(self) -> tuple[float, float] | None:
        """The newest finite point of the path (m), kept or not."""
        return self._last_point

    @property
    def bounds(self) -> tuple[float, float, float, float] | None:
        """(xmin, xmax, ymin, ymax) of every finite point seen (m); None when empty."""
        return tuple(map(float, self._bounds)) if self._last_point is not None else None

    def level_size(self, level: int) -> int:
        return self._points[level].n

    def update(self, x: np.ndarray, y: np.ndarray) -> int:
        """Take the rows of ``x``, ``y`` (whole columns, m) beyond ``rows_seen``.

        Returns the number of new rows. Non-finite rows are skipped.
        """
        new_x, new_y = x[self.rows_seen :], y[self.rows_seen :]
        self.rows_seen = len(x)
        if not len(new_x):
            return 0
        pts = np.column_stack((new_x, new_y))
        finite = np.isfinite(pts).all(axis=1)
        if not finite.all():
            pts = pts[finite]
        if not len(pts):
            return len(new_x)
        cells = np.floor(pts / self.EPS0_M).astype(np.int64)
        prev = self._last_cell
        self._last_cell = cells[-1].copy()
        self._last_point = (float(pts[-1, 0]), float(pts[-1, 1]))
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        b = self._bounds
        b[:] = min(b[0], lo[0]), max(b[1], hi[0]), min(b[2], lo[1]), max(b[3], hi[1])
        for k in range(self.LEVELS):
            ck = cells >> (2 * k)  # floor division by 4**k: the nested coarser cell
            keep = np.empty(len(ck), dtype=bool)
            keep[1:] = (ck[1:] != ck[:-1]).any(axis=1)
            keep[0] = prev is None or bool(((prev >> (2 * k)) != ck[0]).any())
            pts, cells = pts[keep], cells[keep]
            self._append(k, pts)
            if not len(pts):
                break
        return len(new_x)

    def _append(self, k: int, pts: np.ndarray) -> None:
        if not len(pts):
            return
        store, boxes = self._points[k], self._boxes[k]
        store.extend(pts)
        full = store.n // self.CHUNK
        if full > boxes.n:
            done = store.data[boxes.n * self.CHUNK : full * self.CHUNK].reshape(
                -1, self.CHUNK, 2
            )
            lo, hi = done.min(axis=1), done.max(axis=1)
            boxes.extend(np.column_stack((lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1])))

    def level_for(self, pixel_m: float) -> int:
        """The coarsest level whose cell is at most ``PIXEL_FRACTION`` of a pixel."""
        level = 0
        for k, eps in enumerate(self.LEVEL_EPS_M):
            if eps <= pixel_m * PIXEL_FRACTION:
                level = k
        return level

    def points(
        self, level: int, rect: tuple[float, float, float, float] | None = None,
        budget: int = POINT_BUDGET,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The points of ``level`` to draw: ``(x, y, connect)``.

        All of them when there are at most ``budget`` or no ``rect``
        (``connect`` None: one polyline); else only the chunks (and, if still
        too many, the points and their neighbours) inside ``rect`` =
        (xmin, xmax, ymin, ymax), with ``connect[i]`` False where the line
        breaks after point i.
        """
        pts = self._points[level].view
        n = len(pts)
        if n <= budget or rect is None:
            return self._with_last(pts[:, 0], pts[:, 1], None, True)
        idx = self._chunk_indices(level, rect, n)
        if len(idx) > budget:
            sel = pts[idx]
            inside = _inside(sel, rect)
            near = inside.copy()
            near[1:] |= inside[:-1]
            near[:-1] |= inside[1:]
            idx = idx[near]
        connect = np.zeros(len(idx), dtype=bool)
        connect[:-1] = np.diff(idx) == 1
        sel = pts[idx]
        return self._with_last(sel[:, 0], sel[:, 1], connect, len(idx) and idx[-1] == n - 1)

    def _with_last(self, x, y, connect, joined: bool):
        """Append the newest point when the decimation dropped it, so the line ends where
        the robot is; ``joined``: the points end with the level's newest kept point."""
        last = self._last_point
        if last is None or (len(x) and x[-1] == last[0] and y[-1] == last[1]):
            return x, y, connect
        x, y = np.append(x, last[0]), np.append(y, last[1])
        if connect is not None:
            connect = np.append(connect, False)
            if len(connect) > 1:
                connect[-2] = bool(joined)
        return x, y, connect

    def _chunk_indices(self, level: int, rect, n: int) -> np.ndarray:
        c = self.CHUNK
        boxes = self._boxes[level].view
        x0, x1, y0, y1 = rect
        hit = (boxes[:, 1] >= x0) & (boxes[:, 0] <= x1) & (boxes[:, 3] >= y0) & (boxes[:, 2] <= y1)
        ids = list(np.flatnonzero(hit))
        if len(boxes) * c < n:
            ids.append(len(boxes))  # the growing last chunk: always considered
        parts, prev = [], -2
        for i in ids:
            start = i * c if (i == prev + 1 or i == 0) else i * c - 1  # join to the point before
            parts.append(np.arange(start, min((i + 1) * c, n)))
            prev = i
        return np.concatenate(parts) if parts else np.empty(0, dtype=np.int64)


def _inside(pts: np.ndarray, rect) -> np.ndarray:
    x0, x1, y0, y1 = rect
    x, y = pts[:, 0], pts[:, 1]
    return (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)


def _rotate(points: np.ndarray, yaw: float, x: float, y: float) -> np.ndarray:
    """base_link points (N, 2) -> odom, for a robot at (x, y, yaw)."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty_like(points)
    out[:, 0] = x + c * points[:, 0] - s * points[:, 1]
    out[:, 1] = y + s * points[:, 0] + c * points[:, 1]
    return out


def _arrow_segments(tail, direction, length: float, head: float) -> list:
    """Line segments (pairs of points) of an arrow from ``tail`` along unit ``direction``."""
    tx, ty = tail
    dx, dy = direction
    hx, hy = tx + length * dx, ty + length * dy
    segs = [(tx, ty), (hx, hy)]
    for sign in (1.0, -1.0):
        a = math.atan2(dy, dx) + math.pi + sign * math.radians(25)
        segs += [(hx, hy), (hx + head * math.cos(a), hy + head * math.sin(a))]
    return segs


def _colour_icon(colour: str) -> QIcon:
    pm = QPixmap(12, 12)
    pm.fill(QColor(colour))
    return QIcon(pm)


class _MapViewBox(pg.ViewBox):
    """ViewBox that tells when the user dragged the map (to leave follow mode)."""

    user_panned = Signal()

    def mouseDragEvent(self, ev, axis=None):  # noqa: N802 - pyqtgraph API
        super().mouseDragEvent(ev, axis)
        if ev.button() in (Qt.MouseButton.LeftButton, Qt.MouseButton.MiddleButton):
            self.user_panned.emit()


class _Path:
    """One drawn path: its decimator, its curve and what was last drawn."""

    def __init__(self, key, colour: str, width: float, columns: tuple[str, str]) -> None:
        self.key = key
        self.columns = columns
        self.decimator = PathDecimator()
        self.curve = pg.PlotCurveItem(pen=pg.mkPen(colour, width=width), skipFiniteCheck=True)
        self.curve.setZValue(5 if key == "robot" else 4)
        self.drawn: tuple | None = None  # (level, clip rect or None, rows) last drawn
        self.shown_points = 0


class MapView(QWidget):
    """Map of the robot, both sensors and their paths (odom frame, metres).

    Toolbar: zoom slider (visible width 0.2 m ... 200 m, log scale), follow
    robot, fit path, show/hide each path, reset path and values.
    Mouse: wheel zooms, drag pans (and ends follow mode).
    """

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self._seen: tuple | None = None
        self._dirty = True
        self._follow_pending = False
        self._refresh_ms: list[float] = []
        self.paths: dict[object, _Path] = {}
        self.path_checks: dict[object, QCheckBox] = {}
        self.sensor_items: list[dict] = []

        self.vb = _MapViewBox()
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
            self.plot.setLabel(side, name)
        self.grid = []
        for z, colour in enumerate(GRID_COLOURS):
            item = pg.PlotCurveItem(pen=pg.mkPen(colour, width=1), connect="pairs",
                                    skipFiniteCheck=True)
            item.setZValue(-10 + z)
            self.vb.addItem(item, ignoreBounds=True)
            self.grid.append(item)

        self._build_toolbar()
        self._build_robot_items()
        self._add_path("robot", "robot", ROBOT_COLOUR, 2.0, ("x", "y"))

        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addLayout(self.toolbar)
        lay.addWidget(self.plot, 1)

        self.vb.sigRangeChanged.connect(self._on_range_changed)
        self.vb.user_panned.connect(lambda: self.follow_check.setChecked(False))
        ctx.devices_known.connect(self._on_devices)
        ctx.session_reset.connect(self.clear_paths)
        ctx.odometry_changed.connect(self._mark_dirty)
        self.vb.setRange(xRange=(-DEFAULT_WIDTH_M / 2, DEFAULT_WIDTH_M / 2),
                         yRange=(-DEFAULT_WIDTH_M / 2, DEFAULT_WIDTH_M / 2), padding=0)
        self._ensure_sensors()

    # -- construction ---------------------------------------------------------------------

    def _build_toolbar(self) -> None:
        bar = QHBoxLayout()
        bar.setContentsMargins(0, 0, 0, 0)
        bar.addWidget(QLabel("Zoom"))
        self.zoom_slider = QSlider(Qt.Orientation.Horizontal)
        self.zoom_slider.setRange(0, SLIDER_STEPS)
        self.zoom_slider.setMinimumWidth(140)
        self.zoom_slider.setToolTip(
            f"visible width of the map, {MIN_WIDTH_M:g} m to {MAX_WIDTH_M:g} m (log scale)"
        )
        self.zoom_slider.valueChanged.connect(self._on_slider)
        bar.addWidget(self.zoom_slider)
        self.width_label = QLabel("")
        self.width_label.setMinimumWidth(60)
        bar.addWidget(self.width_label)
        self.follow_check = QCheckBox("Follow robot")
        self.follow_check.setToolTip("keep the robot in the centre; dragging the map ends it")
        self.follow_check.toggled.connect(self._on_follow)
        bar.addWidget(self.follow_check)
        self.fit_button = QPushButton("Fit path")
        self.fit_button.setToolTip("zoom to show every path")
        self.fit_button.clicked.connect(self.fit_paths)
        bar.addWidget(self.fit_button)
        bar.addStretch(1)
        self.reset_button = QPushButton("Reset path and values")
        self.reset_button.setToolTip("clear the paths and put the robot back to the origin")
        self.reset_button.clicked.connect(self.ctx.reset)
        bar.addWidget(self.reset_button)
        second = QHBoxLayout()
        second.setContentsMargins(0, 0, 0, 0)
        second.addWidget(QLabel("Paths:"))
        self.path_bar = QHBoxLayout()
        second.addLayout(self.path_bar)
        second.addStretch(1)
        self.pose_label = QLabel("")
        second.addWidget(self.pose_label)
        self.toolbar = QVBoxLayout()
        self.toolbar.setSpacing(2)
        self.toolbar.addLayout(bar)
        self.toolbar.addLayout(second)

    def _build_robot_items(self) -> None:
        pen = pg.mkPen(ROBOT_COLOUR, width=2)
        self.robot_outline = pg.PlotCurveItem(pen=pen, skipFiniteCheck=True)
        self.robot_heading = pg.PlotCurveItem(pen=pen, connect="pairs", skipFiniteCheck=True)
        # A marker of fixed screen size, so the robot can be found when zoomed far out.
        self.robot_marker = pg.ArrowItem(
            angle=180, headLen=14, tailLen=0, brush=ROBOT_COLOUR, pen=pg.mkPen(ROBOT_COLOUR)
        )
        for z, item in enumerate((self.robot_outline, self.robot_heading, self.robot_marker)):
            item.setZValue(20 + z)
            self.vb.addItem(item, ignoreBounds=True)

    def _add_path(self, key, label: str, colour: str, width: float, columns) -> None:
        path = _Path(key, colour, width, columns)
        self.vb.addItem(path.curve, ignoreBounds=True)
        self.paths[key] = path
        check = QCheckBox(label)
        check.setIcon(_colour_icon(colour))
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
            dot = pg.ScatterPlotItem(size=8, brush=pg.mkBrush(colour), pen=pg.mkPen("w"))
            axes = pg.PlotCurveItem(pen=pg.mkPen(colour, width=2), connect="pairs",
                                    skipFiniteCheck=True)
            labels = []
            for text in ("X", "Y"):
                t = pg.TextItem(text, color=colour, anchor=(0.5, 0.5))
                labels.append(t)
            for item in (axes, dot, *labels):
                item.setZValue(30)
                self.vb.addItem(item, ignoreBounds=True)
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
            if path.curve.isVisible() and path.decimator.bounds is not None:
                boxes.append(path.decimator.bounds)
        arr = np.array(boxes, dtype=float)
        x0, x1 = arr[:, 0].min(), arr[:, 1].max()
        y0, y1 = arr[:, 2].min(), arr[:, 3].max()
        margin = 0.1  # room for the robot outline
        w_px, h_px = max(self.vb.width(), 1.0), max(self.vb.height(), 1.0)
        width = max(x1 - x0, (y1 - y0) * w_px / h_px) + 2 * margin
        self.set_visible_width(width, ((x0 + x1) / 2, (y0 + y1) / 2))

    def set_path_visible(self, key, visible: bool) -> None:
        """Show or hide one path: ``"robot"`` or a sensor index (0-based)."""
        path = self.paths[key]
        path.curve.setVisible(bool(visible))
        path.drawn = None
        if self.path_checks[key].isChecked() != bool(visible):
            self.path_checks[key].setChecked(bool(visible))
        self._dirty = True

    def path_data(self, key) -> tuple[np.ndarray, np.ndarray]:
        """The points the curve of a path currently holds (m, odom)."""
        x, y = self.paths[key].curve.getData()
        if x is None:
            return np.empty(0), np.empty(0)
        return np.asarray(x), np.asarray(y)

    def clear_paths(self) -> None:
        """Forget the drawn paths (the session was reset)."""
        for path in self.paths.values():
            path.decimator.clear()
            path.curve.setData(np.empty(0), np.empty(0))
            path.drawn = None
            path.shown_points = 0
        self._seen = None
        self._dirty = True

    def render_stats(self) -> dict:
        """What the last refreshes cost and drew (for benchmarks and tests)."""
        ms = np.array(self._refresh_ms[-1000:]) if self._refresh_ms else np.zeros(1)
        hist = self.ctx.session.history
        return {
            "rows": len(hist) if hist is not None else 0,
            "refreshes": len(self._refresh_ms),
            "refresh_p50_ms": float(np.percentile(ms, 50)),
            "refresh_p95_ms": float(np.percentile(ms, 95)),
            "refresh_max_ms": float(ms.max()),
            "points": {k: p.shown_points for k, p in self.paths.items()},
            "levels": {k: (p.drawn[0] if p.drawn else None) for k, p in self.paths.items()},
        }

    # -- refresh ----------------------------------------------------------------------------------

    def refresh(self) -> None:
        """Redraw what changed since the last call; returns at once when nothing did."""
        hist = self.ctx.session.history
        key = (id(hist), hist.version) if hist is not None else None
        if key == self._seen and not self._dirty:
            return
        t0 = time.perf_counter()
        data_changed = key != self._seen
        self._seen = key
        self._dirty = False
        self._ensure_sensors()
        if data_changed and hist is not None:
            self._take_rows(hist)
        self._draw_robot()
        self._draw_sensors()
        if self.follow_check.isChecked() and (data_changed or self._follow_pending):
            self._follow_pending = False
            self._show(self._robot_xy(), self.visible_width())
        self._draw_paths()
        self._dirty = False  # our own range changes above need nothing more
        self._refresh_ms.append((time.perf_counter() - t0) * 1e3)
        if len(self._refresh_ms) > 20_000:
            del self._refresh_ms[:10_000]

    def _take_rows(self, hist) -> None:
        for path in self.paths.values():
            dec = path.decimator
            if len(hist) < dec.rows_seen or getattr(self, "_dropped", 0) != hist.dropped_rows:
                dec.clear()  # cleared, or the oldest rows were let go: start again
                path.drawn = None
            if path.columns[0] in hist.index:
                dec.update(hist.column(path.columns[0]), hist.column(path.columns[1]))
        self._dropped = hist.dropped_rows

    def _draw_paths(self) -> None:
        (x0, x1), (y0, y1) = self.vb.viewRange()
        width, height = x1 - x0, y1 - y0
        pixel = width / max(self.vb.width(), 1.0)
        view = (x0, x1, y0, y1)
        for path in self.paths.values():
            if not path.curve.isVisible():
                continue
            dec = path.decimator
            level = dec.level_for(pixel)
            rows = dec.rows_seen
            if path.drawn is not None:
                lvl, clip, drawn_rows = path.drawn
                same_data = drawn_rows == rows and lvl == level
                if same_data and (clip is None or _contains(clip, view)):
                    continue
            clip = None
            if dec.level_size(level) > POINT_BUDGET:
                clip = (x0 - width, x1 + width, y0 - height, y1 + height)
            x, y, connect = dec.points(level, clip)
            path.curve.setData(x, y, connect="all" if connect is None else connect)
            path.drawn = (level, clip, rows)
            path.shown_points = len(x)

    def _robot_xy(self) -> tuple[float, float]:
        pose = self.ctx.session.pose
        return pose.x, pose.y

    def _draw_robot(self) -> None:
        pose = self.ctx.session.pose
        mounts = self.ctx.session.mounts
        front = max([m.x for m in mounts] + [0.05]) + 0.025
        half = max([abs(m.y) for m in mounts] + [0.04]) + 0.015
        body = np.array([(-0.035, -half), (front, -half), (front, half), (-0.035, half),
                         (-0.035, -half)])
        outline = _rotate(body, pose.yaw, pose.x, pose.y)
        self.robot_outline.setData(outline[:, 0], outline[:, 1])
        segs = np.array(_arrow_segments((0.0, 0.0), (1.0, 0.0), HEADING_ARROW_M, 0.02))
        heading = _rotate(segs, pose.yaw, pose.x, pose.y)
        self.robot_heading.setData(heading[:, 0], heading[:, 1])
        self.robot_marker.setPos(pose.x, pose.y)
        # ArrowItem: angle 0 points left, positive angles turn clockwise on the screen
        self.robot_marker.setStyle(angle=180 - math.degrees(pose.yaw))
        pixel = self.visible_width() / max(self.vb.width(), 1.0)
        self.robot_marker.setVisible(bool((front + 0.035) / pixel < 25))

    def _draw_sensors(self) -> None:
        pose = self.ctx.session.pose
        mounts = self.ctx.session.mounts
        for k, items in enumerate(self.sensor_items):
            if k >= len(mounts):
                continue
            m = mounts[k]
            (sx, sy), = _rotate(np.array([(m.x, m.y)]), pose.yaw, pose.x, pose.y)
            items["dot"].setData([sx], [sy])
            a = pose.yaw + m.yaw
            y_axis = (math.cos(a), math.sin(a))  # sensor +Y: robot forward
            x_axis = (math.sin(a), -math.cos(a))  # sensor +X: robot right
            segs = (_arrow_segments((sx, sy), x_axis, AXIS_ARROW_M, 0.006)
                    + _arrow_segments((sx, sy), y_axis, AXIS_ARROW_M, 0.006))
            arr = np.array(segs)
            items["axes"].setData(arr[:, 0], arr[:, 1])
            for label, (ux, uy) in zip(items["labels"], (x_axis, y_axis), strict=True):
                label.setPos(sx + 1.35 * AXIS_ARROW_M * ux, sy + 1.35 * AXIS_ARROW_M * uy)
            pixel = self.visible_width() / max(self.vb.width(), 1.0)
            detail = bool(AXIS_ARROW_M / pixel > 12)
            items["axes"].setVisible(detail)
            for label in items["labels"]:
                label.setVisible(bool(AXIS_ARROW_M / pixel > 30))
        self.pose_label.setText(
            f"x {pose.x:+.3f} m  y {pose.y:+.3f} m  yaw {math.degrees(pose.yaw_wrapped):+.1f}°"
        )

    def _update_grid(self) -> None:
        (x0, x1), (y0, y1) = self.vb.viewRange()
        pixel = (x1 - x0) / max(self.vb.width(), 1.0)
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
            item.setData(gx, gy, connect="pairs")
            item.setVisible(True)


def _contains(outer, inner) -> bool:
    return outer[0] <= inner[0] and inner[1] <= outer[1] and outer[2] <= inner[2] and (
        inner[3] <= outer[3]
    )


def _format_length(m: float) -> str:
    return f"{m * 100:.0f} cm" if m < 1 else f"{m:.3g} m"
