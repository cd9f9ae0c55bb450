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
``LEVEL_EPS_M[k]`` (0.5 mm, 1 mm, 2 mm, ...). The view shows the coarsest
level whose cell is below half a screen pixel, so what is dropped cannot be
seen. Each level is cut into chunks of 1024 points; a completed chunk is a
curve of its own that is drawn once and then left alone (only chunks near
the visible area get a curve), and only the growing end is updated per row.
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
GRID_MIN_PX = 8.0  # a grid level whose lines would be closer than this is hidden

#: Largest decimation cell allowed, as a fraction of one screen pixel.
PIXEL_FRACTION = 0.5
#: Follow mode re-centres once the robot is this many pixels off the centre.
FOLLOW_SLACK_PX = 3.0
#: Most history rows one refresh takes in (an hour arriving at once is taken in over
#: several frames instead of freezing the window for one long one).
MAX_ROWS_PER_REFRESH = 10_000

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

    def extend(self, *columns: np.ndarray) -> None:
        """Append rows given column by column (each 1-D, of equal length)."""
        need = self.n + len(columns[0])
        if need > len(self.data):
            grown = np.empty((max(need, 2 * len(self.data)), self.data.shape[1]))
            grown[: self.n] = self.data[: self.n]
            self.data = grown
        for j, col in enumerate(columns):
            self.data[self.n : need, j] = col
        self.n = need

    @property
    def view(self) -> np.ndarray:
        return self.data[: self.n]


class PathDecimator:
    """Multi-resolution, incrementally decimated copy of one path (no Qt).

    Level ``k`` keeps a point where the path enters a new square cell of side
    ``LEVEL_EPS_M[k]`` = 0.5 mm * 2**k (cells are nested: 2 x 2 cells of level
    k make one of level k+1), so every kept point is a point of the path, the
    first is always kept, and a dropped point lies in the cell of the kept
    point before it (at most ``sqrt(2) * eps`` away from the drawn line).
    Each level is cut into chunks of ``CHUNK`` points with bounding boxes: a
    completed chunk never changes, so it can be drawn once and left alone,
    and the chunks near a view rectangle are found without looking at points.
    """

    EPS0_M = 0.0005
    LEVELS = 11
    LEVEL_EPS_M = tuple(0.0005 * 2.0**k for k in range(11))  # 0.5 mm ... 0.512 m
    CHUNK = 1024

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget the path."""
        self.rows_seen = 0
        self._last_cell: tuple[int, int] | None = None  # level-0 cell of the newest finite row
        self._last_point: tuple[float, float] | None = None
        self._bounds = np.array([np.inf, -np.inf, np.inf, -np.inf])  # xmin, xmax, ymin, ymax
        self._points = [_Grow(2) for _ in range(self.LEVELS)]
        self._boxes = [_Grow(4) for _ in range(self.LEVELS)]  # per completed chunk

    @property
    def last_point(self) -> tuple[float, float] | None:
        """The newest finite point of the path (m), kept or not."""
        return self._last_point

    @property
    def bounds(self) -> tuple[float, float, float, float] | None:
        """(xmin, xmax, ymin, ymax) of every finite point seen (m); None when empty."""
        return tuple(map(float, self._bounds)) if self._last_point is not None else None

    def level_size(self, level: int) -> int:
        """Points kept at ``level``."""
        return self._points[level].n

    def chunk_count(self, level: int) -> int:
        """Completed (never changing) chunks of ``level``."""
        return self._boxes[level].n

    def update(self, x: np.ndarray, y: np.ndarray) -> int:
        """Take the rows of ``x``, ``y`` (whole columns, m) beyond ``rows_seen``.

        Returns the number of new rows. Non-finite rows are skipped.
        """
        new_x, new_y = x[self.rows_seen :], y[self.rows_seen :]
        self.rows_seen = len(x)
        if not len(new_x):
            return 0
        finite = np.isfinite(new_x) & np.isfinite(new_y)
        px, py = (new_x, new_y) if finite.all() else (new_x[finite], new_y[finite])
        if not len(px):
            return len(new_x)
        cx = np.floor(px / self.EPS0_M).astype(np.int64)
        cy = np.floor(py / self.EPS0_M).astype(np.int64)
        prev = self._last_cell
        self._last_cell = (int(cx[-1]), int(cy[-1]))
        self._last_point = (float(px[-1]), float(py[-1]))
        b = self._bounds
        b[:] = min(b[0], px.min()), max(b[1], px.max()), min(b[2], py.min()), max(b[3], py.max())
        for k in range(self.LEVELS):
            # Points kept at level k-1 are the only candidates at level k (nested cells),
            # and the row before a candidate shares the cell of the candidate before it.
            kx, ky = cx >> k, cy >> k  # floor division by 2**k: the enclosing cell of level k
            keep = np.empty(len(kx), dtype=bool)
            np.not_equal(kx[1:], kx[:-1], out=keep[1:])
            keep[1:] |= ky[1:] != ky[:-1]
            keep[0] = prev is None or (prev[0] >> k, prev[1] >> k) != (int(kx[0]), int(ky[0]))
            if not keep.all():
                px, py, cx, cy = px[keep], py[keep], cx[keep], cy[keep]
            if not len(px):
                break
            self._append(k, px, py)
        return len(new_x)

    def _append(self, k: int, px: np.ndarray, py: np.ndarray) -> None:
        store, boxes = self._points[k], self._boxes[k]
        store.extend(px, py)
        full = store.n // self.CHUNK
        if full > boxes.n:
            done = store.data[boxes.n * self.CHUNK : full * self.CHUNK].reshape(
                -1, self.CHUNK, 2
            )
            x, y = done[:, :, 0], done[:, :, 1]  # reduce along the long axis (fast)
            boxes.extend(x.min(axis=1), x.max(axis=1), y.min(axis=1), y.max(axis=1))

    def level_for(self, pixel_m: float) -> int:
        """The coarsest level whose cell is at most ``PIXEL_FRACTION`` of a pixel."""
        level = 0
        for k, eps in enumerate(self.LEVEL_EPS_M):
            if eps <= pixel_m * PIXEL_FRACTION:
                level = k
        return level

    def points(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """Every point kept at ``level``, then the newest point if it was not kept (m)."""
        pts = self._points[level].view
        return self._with_last(pts[:, 0], pts[:, 1])

    def chunk_points(self, level: int, c: int) -> tuple[np.ndarray, np.ndarray]:
        """Completed chunk ``c`` of ``level``, starting at the last point of chunk c-1
        (so that consecutive chunks drawn apart still join). Views, not copies."""
        pts = self._points[level].data[max(0, c * self.CHUNK - 1) : (c + 1) * self.CHUNK]
        return pts[:, 0], pts[:, 1]

    def live_points(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """The growing part of ``level`` after the completed chunks (joined to them), and
        the newest point if it was not kept: the line always ends where the path ends."""
        start = max(0, self._boxes[level].n * self.CHUNK - 1)
        pts = self._points[level].view[start:]
        return self._with_last(pts[:, 0], pts[:, 1])

    def chunks_in(self, level: int, rect: tuple[float, float, float, float]) -> np.ndarray:
        """Indices of the completed chunks of ``level`` whose box meets
        ``rect`` = (xmin, xmax, ymin, ymax)."""
        b = self._boxes[level].view
        x0, x1, y0, y1 = rect
        return np.flatnonzero((b[:, 1] >= x0) & (b[:, 0] <= x1) & (b[:, 3] >= y0) & (b[:, 2] <= y1))

    def _with_last(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        last = self._last_point
        if last is None or (len(x) and x[-1] == last[0] and y[-1] == last[1]):
            return x, y
        return np.append(x, last[0]), np.append(y, last[1])


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
    """One drawn path: its decimator and its curves in the view box.

    The completed chunks of the level in use that lie near the view are one
    curve each and are never touched again while level and area stay; only
    the ``live`` curve (the growing end, at most one chunk) changes with
    every new row, so a refresh costs the same after an hour as after a minute.
    """

    def __init__(self, vb, key, colour: str, width: float, columns: tuple[str, str]) -> None:
        self.vb = vb
        self.key = key
        self.columns = columns
        self.pen = pg.mkPen(colour, width=width)
        self.z = 5 if key == "robot" else 4
        self.decimator = PathDecimator()
        self.live = self._curve()
        self.chunks: dict[int, pg.PlotCurveItem] = {}
        self.visible = True
        self.level: int | None = None  # level drawn; None: draw everything anew
        self.clip: tuple | None = None  # area whose chunks are drawn (m)
        self.done = 0  # completed chunks of the level already considered
        self.rows = -1  # decimator rows the live curve shows

    def _curve(self) -> pg.PlotCurveItem:
        curve = pg.PlotCurveItem(pen=self.pen, skipFiniteCheck=True)
        curve.setZValue(self.z)
        self.vb.addItem(curve, ignoreBounds=True)
        return curve

    def forget_items(self) -> None:
        """Remove the chunk curves and empty the live one (drawn anew next time)."""
        for curve in self.chunks.values():
            self.vb.removeItem(curve)
        self.chunks.clear()
        self.live.setData(np.empty(0), np.empty(0))
        self.level = self.clip = None
        self.rows = -1

    def set_visible(self, on: bool) -> None:
        self.visible = on
        self.forget_items()  # hidden paths are not kept up to date; shown ones start anew
        self.live.setVisible(on)

    def draw(self, level: int, view: tuple, clip: tuple) -> None:
        """Bring the curves up to date for ``level``; ``view`` is the visible area and
        ``clip`` the larger area to draw chunks for when the view leaves the last one."""
        dec = self.decimator
        if level != self.level:
            self.forget_items()
            self.level = level
        count = dec.chunk_count(level)
        if self.clip is None or not _contains(self.clip, view):
            self.clip = clip
            wanted = set(dec.chunks_in(level, clip).tolist())
            for c in set(self.chunks) - wanted:
                self.vb.removeItem(self.chunks.pop(c))
            self._add_chunks(wanted - set(self.chunks))
            self.done = count
        elif count > self.done:
            new = dec.chunks_in(level, self.clip)
            self._add_chunks(new[new >= self.done].tolist())
            self.done = count
        if dec.rows_seen != self.rows:
            self.live.setData(*dec.live_points(level))
            self.rows = dec.rows_seen

    def _add_chunks(self, chunks) -> None:
        for c in chunks:
            curve = self._curve()
            curve.setData(*self.decimator.chunk_points(self.level, c))
            self.chunks[c] = curve

    def data(self) -> tuple[np.ndarray, np.ndarray]:
        """The points drawn, in path order, without the repeated joining points."""
        curves = [self.chunks[c] for c in sorted(self.chunks)] + [self.live]
        parts = [c.getData() for c in curves]
        parts = [(np.asarray(x), np.asarray(y)) for x, y in parts if x is not None and len(x)]
        if not parts:
            return np.empty(0), np.empty(0)
        x = np.concatenate([p[0] for p in parts])
        y = np.concatenate([p[1] for p in parts])
        keep = np.ones(len(x), dtype=bool)
        keep[1:] = (x[1:] != x[:-1]) | (y[1:] != y[:-1])
        return x[keep], y[keep]

    @property
    def shown_points(self) -> int:
        return sum(len(c.getData()[0] if c.getData()[0] is not None else ())
                   for c in [*self.chunks.values(), self.live])


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
        self.follow_check.setChecked(True)
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
        self.pose_label = QLabel(_pose_text(0.0, 0.0, 0.0))
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
        self.robot_outline = pg.PlotCurveItem(pen=pen, skipFiniteCheck=True)
        self.robot_heading = pg.PlotCurveItem(pen=pen, connect="pairs", skipFiniteCheck=True)
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
        path = _Path(self.vb, key, colour, width, columns)
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
        margin = 0.1  # room for the robot outline
        w_px, h_px = max(self.vb.width(), 1.0), max(self.vb.height(), 1.0)
        width = max(x1 - x0, (y1 - y0) * w_px / h_px) + 2 * margin
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
        """The points drawn for a path (m, odom), in path order."""
        return self.paths[key].data()

    def clear_paths(self) -> None:
        """Forget the drawn paths (the session was reset)."""
        for path in self.paths.values():
            path.decimator.clear()
            path.forget_items()
        self._seen = None
        self._dirty = True

    def render_stats(self) -> dict:
        """What the last refreshes cost and drew (for benchmarks and tests)."""
        ms = np.array(self._refresh_ms[-1000:]) if self._refresh_ms else np.zeros(1)
        hist = self.ctx.session.history
        return {
            "rows": len(hist) if hist is not None else 0,
            "behind": max((len(hist) - p.decimator.rows_seen for p in self.paths.values()),
                          default=0) if hist is not None else 0,
            "refreshes": len(self._refresh_ms),
            "refresh_p50_ms": float(np.percentile(ms, 50)),
            "refresh_p95_ms": float(np.percentile(ms, 95)),
            "refresh_max_ms": float(ms.max()),
            "points": {k: p.shown_points for k, p in self.paths.items()},
            "levels": {k: p.level for k, p in self.paths.items()},
            "chunk_curves": {k: len(p.chunks) for k, p in self.paths.items()},
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
        behind = self._take_rows(hist) if hist is not None else False
        self._draw_robot()
        if self.follow_check.isChecked() and (data_changed or self._follow_pending):
            self._follow()
        self._draw_paths()
        self._dirty = behind  # our own range changes above need nothing more
        self._refresh_ms.append((time.perf_counter() - t0) * 1e3)
        if len(self._refresh_ms) > 20_000:
            del self._refresh_ms[:10_000]

    def _follow(self) -> None:
        """Centre the robot; a drift below ``FOLLOW_SLACK_PX`` is left alone (a pan
        repaints the whole map, which far out is most of the frame budget)."""
        rx, ry = self._robot_xy()
        cx, cy = self.view_centre()
        pixel = self.visible_width() / max(self.vb.width(), 1.0)
        if self._follow_pending or math.hypot(rx - cx, ry - cy) > FOLLOW_SLACK_PX * pixel:
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
            if path.columns[0] in hist.index:
                end = min(len(hist), dec.rows_seen + MAX_ROWS_PER_REFRESH)
                dec.update(hist.column(path.columns[0])[:end], hist.column(path.columns[1])[:end])
                behind |= end < len(hist)
        self._dropped = hist.dropped_rows
        return behind

    def _draw_paths(self) -> None:
        (x0, x1), (y0, y1) = self.vb.viewRange()
        width, height = float(x1 - x0), float(y1 - y0)
        pixel = width / max(self.vb.width(), 1.0)
        view = (x0, x1, y0, y1)
        clip = (x0 - width, x1 + width, y0 - height, y1 + height)
        for path in self.paths.values():
            if path.visible:
                path.draw(path.decimator.level_for(pixel), view, clip)

    def _robot_xy(self) -> tuple[float, float]:
        pose = self.ctx.session.pose
        return pose.x, pose.y

    def _build_body(self) -> None:
        """Robot outline, heading arrow and sensor axes in base_link (m); they move as
        one group carried by the pose. Rebuilt when the geometry changes."""
        mounts = self.ctx.session.mounts
        front = max([m.x for m in mounts] + [0.05]) + 0.025
        half = max([abs(m.y) for m in mounts] + [0.04]) + 0.015
        self._body_size = front + 0.035
        body = np.array([(-0.035, -half), (front, -half), (front, half), (-0.035, half),
                         (-0.035, -half)])
        self.robot_outline.setData(body[:, 0], body[:, 1])
        heading = np.array(_arrow_segments((0.0, 0.0), (1.0, 0.0), HEADING_ARROW_M, 0.02))
        self.robot_heading.setData(heading[:, 0], heading[:, 1])
        for k, items in enumerate(self.sensor_items):
            if k >= len(mounts):
                continue
            m = mounts[k]
            items["dot"].setData([m.x], [m.y])
            y_axis = (math.cos(m.yaw), math.sin(m.yaw))  # sensor +Y: robot forward
            x_axis = (math.sin(m.yaw), -math.cos(m.yaw))  # sensor +X: robot right
            arr = np.array(_arrow_segments((m.x, m.y), x_axis, AXIS_ARROW_M, 0.006)
                           + _arrow_segments((m.x, m.y), y_axis, AXIS_ARROW_M, 0.006))
            items["axes"].setData(arr[:, 0], arr[:, 1])
            for label, (ux, uy) in zip(items["labels"], (x_axis, y_axis), strict=True):
                label.setPos(m.x + 1.35 * AXIS_ARROW_M * ux, m.y + 1.35 * AXIS_ARROW_M * uy)
        self._body_key = (mounts, len(self.sensor_items))

    def _draw_robot(self) -> None:
        """Move the robot group to the pose; show details only when they are big enough."""
        if self._body_key != (self.ctx.session.mounts, len(self.sensor_items)):
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


def _show(item, on: bool) -> None:
    """setVisible only on a change (each call into Qt costs; most frames change nothing)."""
    if item.isVisible() != bool(on):
        item.setVisible(bool(on))


def _contains(outer, inner) -> bool:
    return outer[0] <= inner[0] and inner[1] <= outer[1] and outer[2] <= inner[2] and (
        inner[3] <= outer[3]
    )


def _pose_text(x: float, y: float, yaw: float) -> str:
    return f"x {x:+.3f} m  y {y:+.3f} m  yaw {math.degrees(yaw):+.1f}°"


def _format_length(m: float) -> str:
    return f"{m * 100:.0f} cm" if m < 1 else f"{m:.3g} m"
