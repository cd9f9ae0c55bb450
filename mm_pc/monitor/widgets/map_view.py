"""Map / track path view: the robot, its sensors and their paths in the odom frame.

Odom x points right on the screen, y up; everything in metres. The robot is
drawn as an outline with a heading arrow at the session's current pose, each
sensor as a dot with its own axis arrows (sensor +Y = robot forward, sensor
+X = robot right, turned by the mount's yaw error). The paths are the history
columns ``x, y`` (robot) and ``s{k}_wx, s{k}_wy`` (sensor k).

An hour at 100 Hz is 360 000 rows per path, and a robot going round the
same laps puts them all in the view, so the paths are neither handed to
pyqtgraph as they are nor drawn again per frame:

* :class:`PathDecimator` keeps, incrementally (only the rows added since the
  last refresh are looked at), a few decimated copies of a path: level ``k``
  keeps a row only where the path enters a new square cell of
  ``LEVEL_EPS_M[k]`` (0.5 mm, 1 mm, 2 mm, ...), as int32 row numbers. The
  view uses the coarsest level whose cell is below half a screen pixel, so
  what is dropped cannot be seen.
* :class:`_PathRaster` holds the paths up to their newest kept points as one
  image in screen pixels (the view, a margin, and the paths' whole extent
  while that is under 4 Mpx). A repaint is a blit of it; new points are drawn
  onto it; a pan moves it and draws only the strips uncovered (off the
  screen, over the following frames); a zoom draws it anew over a few
  frames, the old image stretched meanwhile.
* one light line per path joins the image's last point to the newest row.

Measured with an hour of figure-eight laps at 100 Hz (360 000 rows x 3
paths), following the robot 1 m wide, in the monitor window (software
rendering, 2 cores, ``mm-bench gui``): Map frame p95 ~15-18 ms with a live
node, ~9 ms without (before: every finished chunk of every lap was a curve
drawn again with each repaint, p95 ~235-410 ms); the first show takes the
hour in over ~40 frames (~1 s); a zoom there draws ~0.2 s over ~17 frames
of <= ~16 ms. Memory: the decimators ~38 MB (int32 row numbers, were
float64 points), the image <= 16 MB (two during a zoom): the Map tab's
first show adds ~70 MB, was ~190 MB.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QIcon, QImage, QPainter, QPainterPath, QPen, QPixmap, QTransform
from PySide6.QtWidgets import (
    QCheckBox,
    QGraphicsEllipseItem,
    QGraphicsItem,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSlider,
    QVBoxLayout,
    QWidget,
)

from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.widgets.style import ROBOT_COLOUR, sensor_colour

__all__ = [
    "MAX_WIDTH_M",
    "MIN_WIDTH_M",
    "MapView",
    "PathDecimator",
]

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

#: Width of the map's left axis (labels like "-123.4" fit).
AXIS_WIDTH_PX = 62

#: Sensor axis arrows and robot heading arrow (m, drawn to scale).
AXIS_ARROW_M = 0.025
HEADING_ARROW_M = 0.10


class _Grow:
    """A growing array (amortised O(1) appends by doubling) of ``dtype`` rows of ``width``."""

    def __init__(self, width: int, dtype=np.float64) -> None:
        self.data = np.empty((256, width), dtype=dtype)
        self.n = 0

    def extend(self, *columns: np.ndarray) -> None:
        """Append rows given column by column (each 1-D, of equal length)."""
        need = self.n + len(columns[0])
        if need > len(self.data):
            grown = np.empty((max(need, 2 * len(self.data)), self.data.shape[1]), self.data.dtype)
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

    A level stores the *row numbers* of its kept points (int32, 4 bytes a
    point), not coordinates: the coordinates stay in the caller's columns,
    which every method that returns points takes as ``x``, ``y`` (the same
    columns, or longer ones, as given to :meth:`update`). Each level is cut
    into boxes of ``BOX`` points with bounding boxes (a box's segments start
    at the last point of the box before), so the segments near a rectangle
    are found without looking at the points far from it (:meth:`runs_in`).
    """

    EPS0_M = 0.0005
    LEVELS = 11
    LEVEL_EPS_M = tuple(0.0005 * 2.0**k for k in range(11))  # 0.5 mm ... 0.512 m
    BOX = 32

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget the path."""
        self.rows_seen = 0
        self._last_cell: tuple[int, int] | None = None  # level-0 cell of the newest finite row
        self._last_point: tuple[float, float] | None = None
        self._last_row = -1
        self._bounds = np.array([np.inf, -np.inf, np.inf, -np.inf])  # xmin, xmax, ymin, ymax
        self._rows = [_Grow(1, np.int32) for _ in range(self.LEVELS)]
        self._boxes = [_Grow(4) for _ in range(self.LEVELS)]  # per completed box

    @property
    def bounds(self) -> tuple[float, float, float, float] | None:
        """(xmin, xmax, ymin, ymax) of every finite point seen (m); None when empty."""
        return tuple(map(float, self._bounds)) if self._last_point is not None else None

    @property
    def nbytes(self) -> int:
        """Bytes held (capacity of the row and box arrays)."""
        return sum(g.data.nbytes for g in (*self._rows, *self._boxes))

    def level_size(self, level: int) -> int:
        """Points kept at ``level``."""
        return self._rows[level].n

    def box_count(self, level: int) -> int:
        """Completed (never changing) boxes of ``level``."""
        return self._boxes[level].n

    def update(self, x: np.ndarray, y: np.ndarray) -> int:
        """Take the rows of ``x``, ``y`` (whole columns, m) beyond ``rows_seen``.

        Returns the number of new rows. Non-finite rows are skipped.
        """
        first = self.rows_seen
        new_x, new_y = x[first:], y[first:]
        self.rows_seen = len(x)
        if not len(new_x):
            return 0
        finite = np.isfinite(new_x) & np.isfinite(new_y)
        rows = np.arange(first, len(x), dtype=np.int32)
        px, py = (new_x, new_y) if finite.all() else (new_x[finite], new_y[finite])
        if not len(px):
            return len(new_x)
        if len(px) < len(rows):
            rows = rows[finite]
        cx = np.floor(px / self.EPS0_M).astype(np.int64)
        cy = np.floor(py / self.EPS0_M).astype(np.int64)
        prev = self._last_cell
        self._last_cell = (int(cx[-1]), int(cy[-1]))
        self._last_point = (float(px[-1]), float(py[-1]))
        self._last_row = int(rows[-1])
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
                rows, cx, cy = rows[keep], cx[keep], cy[keep]
            if not len(rows):
                break
            self._append(k, rows, x, y)
        return len(new_x)

    def _append(self, k: int, rows: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        store, boxes = self._rows[k], self._boxes[k]
        store.extend(rows)
        full = store.n // self.BOX
        if full > boxes.n:
            # a box's bounding box includes the last point of the box before (its first segment)
            rows = store.data[:, 0]
            first = np.arange(boxes.n, full) * self.BOX
            seg = np.empty((len(first), self.BOX + 1), dtype=rows.dtype)
            seg[:, 0] = rows[np.maximum(first - 1, 0)]
            seg[:, 1:] = rows[first[0] : full * self.BOX].reshape(-1, self.BOX)
            bx, by = x[seg], y[seg]  # reduce along the long axis (fast)
            boxes.extend(bx.min(axis=1), bx.max(axis=1), by.min(axis=1), by.max(axis=1))

    @classmethod
    def level_for(cls, pixel_m: float) -> int:
        """The coarsest level whose cell is at most ``PIXEL_FRACTION`` of a pixel."""
        level = 0
        for k, eps in enumerate(cls.LEVEL_EPS_M):
            if eps <= pixel_m * PIXEL_FRACTION:
                level = k
        return level

    def rows(self, level: int, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Row numbers of the points ``start:stop`` kept at ``level`` (a view)."""
        return self._rows[level].view[start:stop, 0]

    def points(self, level: int, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every point kept at ``level``, then the newest point if it was not kept (m)."""
        r = self.rows(level)
        return self._with_last(x[r], y[r])

    def tail_points(
        self, level: int, start: int, x: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The points kept at ``level`` from ``start - 1`` on (joined to those before), and
        the newest point if it was not kept: the line always ends where the path ends."""
        r = self.rows(level, max(0, start - 1))
        return self._with_last(x[r], y[r])

    def runs_in(
        self, level: int, rect: tuple[float, float, float, float], start: int = 0,
        stop: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The polylines, among the segments ending at kept points ``start:stop`` of
        ``level``, that may meet ``rect`` = (xmin, xmax, ymin, ymax) (m).

        Returns (rows, connect): row numbers of the points and, per point, whether
        it is joined to the next (False at the end of each polyline, the form
        ``pyqtgraph.functions.arrayToQPath`` takes). Every segment that meets the
        rectangle is in it (whole boxes are taken: more may be)."""
        n = self._rows[level].n
        stop = n if stop is None else min(stop, n)
        if stop <= start:
            return np.empty(0, np.int32), np.empty(0, bool)
        B = self.BOX  # noqa: N806 - a constant's short name
        done = self._boxes[level].n
        b0, b1 = start // B, min(done, -(-stop // B))
        boxes = self._boxes[level].view[b0:b1]
        x0, x1, y0, y1 = rect
        hit = b0 + np.flatnonzero(
            (boxes[:, 1] >= x0) & (boxes[:, 0] <= x1) & (boxes[:, 3] >= y0) & (boxes[:, 2] <= y1)
        )
        lo = np.maximum(hit * B, start)
        hi = np.minimum((hit + 1) * B, stop)
        if stop > done * B:  # the open box at the end: no bounding box yet, always taken
            lo = np.append(lo, max(done * B, start))
            hi = np.append(hi, stop)
        lo = np.maximum(lo - 1, 0)  # each run starts at the point before its first segment
        if len(lo) > 1:  # join runs that follow each other
            new = np.ones(len(lo), dtype=bool)
            new[1:] = lo[1:] != hi[:-1] - 1
            starts = np.flatnonzero(new)
            lo, hi = lo[starts], np.append(hi[starts[1:] - 1], hi[-1])
        lengths = hi - lo
        total = int(lengths.sum())
        ends = np.cumsum(lengths)
        pos = np.arange(total) - np.repeat(ends - lengths - lo, lengths)
        connect = np.ones(total, dtype=bool)
        connect[ends - 1] = False
        return self._rows[level].data[pos, 0], connect

    def _with_last(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        last = self._last_point
        if last is None or (len(x) and x[-1] == last[0] and y[-1] == last[1]):
            return x, y
        return np.append(x, last[0]), np.append(y, last[1])


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


class _Lines(QGraphicsItem):
    """Lines through points in odom metres with a cosmetic pen: what a PlotCurveItem
    draws, without its per-frame work in Python (it computes its bounds again, from
    the pixel size, whenever the view moves). ``setData``/``getData`` as there.

    ``pad`` (m) is added around the points' box for the pen's width; the view sets
    it when the zoom changes (:meth:`MapView._on_range_changed`).
    """

    def __init__(self, pen: QPen, connect: str = "all") -> None:
        super().__init__()
        self._pen = QPen(pen)
        self._pen.setCosmetic(True)
        self._connect = connect
        self._x = self._y = np.empty(0)
        self._path = QPainterPath()
        self._box = QRectF()
        self.pad = 0.0

    def setData(self, x, y) -> None:  # noqa: N802 - as PlotCurveItem
        self.prepareGeometryChange()
        self._x, self._y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        self._path = (pg.functions.arrayToQPath(self._x, self._y, connect=self._connect)
                      if len(self._x) else QPainterPath())
        self._box = self._path.boundingRect()

    def getData(self) -> tuple[np.ndarray, np.ndarray]:  # noqa: N802 - as PlotCurveItem
        return self._x, self._y

    def set_pad(self, pad: float) -> None:
        if abs(pad - self.pad) > 0.01 * pad:  # a zoom, not the last digits of a pan
            self.prepareGeometryChange()
            self.pad = pad

    def boundingRect(self) -> QRectF:  # noqa: N802 - Qt API
        if not len(self._x):
            return QRectF()
        return self._box.adjusted(-self.pad, -self.pad, self.pad, self.pad)

    def paint(self, painter, option, widget=None) -> None:
        painter.setPen(self._pen)
        painter.drawPath(self._path)


def _dot(colour: str, size_px: float = 8.0) -> QGraphicsEllipseItem:
    """A filled circle of ``size_px`` on the screen whatever the zoom, white rimmed."""
    dot = QGraphicsEllipseItem(-size_px / 2, -size_px / 2, size_px, size_px)
    dot.setFlag(QGraphicsItem.GraphicsItemFlag.ItemIgnoresTransformations)
    dot.setBrush(QColor(colour))
    dot.setPen(QPen(QColor("white")))
    return dot


class _Path:
    """One drawn path: its decimator and the curve of its newest end.

    What the raster (:class:`_PathRaster`) holds is not drawn again: the
    ``live`` curve only joins the last point the raster has to the newest
    point of the path (one or a few points), so a refresh and a repaint cost
    the same after an hour as after a minute.
    """

    def __init__(self, vb, key, colour: str, width: float, columns: tuple[str, str]) -> None:
        self.vb = vb
        self.key = key
        self.columns = columns
        self.pen = pg.mkPen(colour, width=width)
        self.decimator = PathDecimator()
        self.live = _Lines(self.pen)
        self.live.setZValue(5 if key == "robot" else 4)
        self.vb.addItem(self.live, ignoreBounds=True)
        self.visible = True
        self.shown: tuple | None = None  # (level, raster points, rows seen) the live curve shows

    def forget_items(self) -> None:
        """Empty the live curve (drawn anew next time)."""
        self.live.setData(np.empty(0), np.empty(0))
        self.shown = None

    def set_visible(self, on: bool) -> None:
        self.visible = on
        self.forget_items()
        self.live.setVisible(on)

    def draw_live(self, level: int, done: int, x: np.ndarray, y: np.ndarray) -> None:
        """Show the path from kept point ``done - 1`` of ``level`` to its newest point."""
        key = (level, done, self.decimator.rows_seen)
        if key != self.shown:
            self.live.setData(*self.decimator.tail_points(level, done, x, y))
            self.shown = key


Rect = tuple[int, int, int, int]  # (u0, u1, v0, v1): pixels u0 <= u < u1, v0 <= v < v1


def _meets(a: Rect, b: Rect) -> bool:
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]


def _inside(inner: Rect, outer: Rect) -> bool:
    return outer[0] <= inner[0] and inner[1] <= outer[1] and outer[2] <= inner[2] and (
        inner[3] <= outer[3])


def _minus(a: Rect, b: Rect) -> list[Rect]:
    """``a`` without ``b``: up to four rectangles (bands above, below, left, right)."""
    if not _meets(a, b):
        return [a]
    out = []
    if a[2] < b[2]:
        out.append((a[0], a[1], a[2], b[2]))
    if b[3] < a[3]:
        out.append((a[0], a[1], b[3], a[3]))
    v0, v1 = max(a[2], b[2]), min(a[3], b[3])
    if a[0] < b[0]:
        out.append((a[0], b[0], v0, v1))
    if b[1] < a[1]:
        out.append((b[1], a[1], v0, v1))
    return out


def _tiles(r: Rect, size: int) -> list[Rect]:
    return [(u, min(u + size, r[1]), v, min(v + size, r[3]))
            for v in range(r[2], r[3], size) for u in range(r[0], r[1], size)]


class _Area:
    """Drawing the segments near grid rect ``rect`` of the kept points below
    ``upto[key]``, resumable: path ``k`` of the drawing order, its polylines
    (``rows``, ``connect`` from :meth:`PathDecimator.runs_in`) drawn up to ``s``."""

    def __init__(self, rect: Rect, upto: dict) -> None:
        self.rect, self.upto = rect, upto
        self.k = self.s = 0
        self.rows: np.ndarray | None = None
        self.connect: np.ndarray | None = None

    @property
    def fresh(self) -> bool:
        return self.k == 0 and self.rows is None


class _PathRaster(pg.GraphicsObject):
    """The paths up to their newest kept points, as one image in screen pixels.

    Painting it is one blit of the exposed part, whatever the length of the
    history. Pixels are counted on a grid fixed at the last zoom (``grid``
    px: the view box's pixels then); the image covers a rectangle of it:
    the view and ``MARGIN_PX`` around, and, while that stays under
    ``MAX_PIXELS``, the whole extent of the paths with half a view around
    (so following the robot over its old laps never draws anything anew).
    It is changed only where something changed:

    * new kept points: their segments are drawn onto it (a few per frame) and
      only their box on the screen is repainted;
    * a pan (drag or follow) that brings the view within ``MARGIN_PX / 2`` of
      the image's edge: the image is moved (pixels kept) and the strips
      uncovered are drawn from the segments near them
      (:meth:`PathDecimator.runs_in`) -- off the screen, so over the
      following frames, at most ``BUDGET_S`` per refresh;
    * a zoom or a resize: drawn anew, the visible part nearest the centre
      first, ``VISIBLE_BUDGET_S`` per refresh, the old image stretched where
      the new one is not drawn yet (an hour of laps over each other at 1 m
      width: ~0.2 s of drawing, so ~20 frames); the rest over later frames;
    * a path shown or hidden, the paths cleared: drawn anew, the visible part
      at once (nothing else would be right to show).

    Paths are drawn in the order given (the robot last); segments added later
    are drawn over older ones of other paths.
    """

    MARGIN_PX = 128
    MAX_PIXELS = 4_000_000  # 16 MB (a second, stretched, while a zoom is drawn)
    BUDGET_S = 0.004
    VISIBLE_BUDGET_S = 0.008
    TILE_PX = 256
    STEP_POINTS = 16_384  # drawn at once at most (a time budget is checked between steps)

    def __init__(self) -> None:
        super().__init__()
        self.setZValue(3)
        self.image: QImage | None = None
        self.dpr = 1
        self.sx = self.sy = 1.0  # screen px per m (sy < 0: odom y points up)
        self.gx = self.gy = 0.0  # odom point (m) at grid pixel (0, 0)
        self.dx0 = self.dy0 = 0.0  # the view box's transform offsets when the grid was fixed
        self.rect: Rect = (0, 0, 0, 0)  # grid pixels the image covers
        self.view_size = (0.0, 0.0)
        self.level = 0
        self.keys: tuple = ()  # paths drawn, in drawing order
        self.done: dict = {}  # path key -> kept points drawn (at ``level``)
        self.todo: list[_Area] = []  # areas still to draw
        self.stale = True
        # the image before a zoom (image, sx, sy, ox, oy), shown stretched under the tiles
        # in view not drawn yet (``veiled``, odom rects)
        self.preview: tuple | None = None
        self.veiled: list[QRectF] = []
        self._drawing_view = False  # the view's tiles after a new layout are not all drawn
        self.stats = {"full": 0, "moves": 0, "commits": 0, "tiles": 0, "paints": 0,
                      "full_ms": 0.0, "full_frames": 0, "pending": 0, "pending_in_view": 0}

    # -- geometry -------------------------------------------------------------------------

    @property
    def ox(self) -> float:
        """Odom x (m) of the image's left edge."""
        return self.gx + self.rect[0] / self.sx

    @property
    def oy(self) -> float:
        """Odom y (m) of the image's top edge."""
        return self.gy + self.rect[2] / self.sy

    @property
    def img_w(self) -> int:
        return self.rect[1] - self.rect[0]

    @property
    def img_h(self) -> int:
        return self.rect[3] - self.rect[2]

    def boundingRect(self) -> QRectF:  # noqa: N802 - Qt API
        if self.image is None:
            return QRectF()
        return QRectF(self.ox, self.oy + self.img_h / self.sy, self.img_w / self.sx,
                      -self.img_h / self.sy)

    def data_rect(self, r: Rect, pad_px: float = 0.0) -> tuple[float, float, float, float]:
        """Grid pixels ``r`` as (xmin, xmax, ymin, ymax) in odom (m)."""
        u0, u1, v0, v1 = r
        return (self.gx + (u0 - pad_px) / self.sx, self.gx + (u1 + pad_px) / self.sx,
                self.gy + (v1 + pad_px) / self.sy, self.gy + (v0 - pad_px) / self.sy)

    @property
    def nbytes(self) -> int:
        return self.image.sizeInBytes() if self.image is not None else 0

    def invalidate(self) -> None:
        """Draw everything anew at the next :meth:`sync`."""
        self.stale = True

    # -- keeping it up to date --------------------------------------------------------------

    def sync(self, paths: list, columns: dict, level: int, transform: QTransform,
             view_px: tuple[float, float], dpr: int, bounds) -> None:
        """Bring the image up to date with the paths (in drawing order).

        ``transform`` maps odom (m) to the view box's pixels, ``view_px`` is the
        view box's size (logical px), ``columns[key]`` the path's (x, y) columns,
        ``bounds`` (xmin, xmax, ymin, ymax) of all paths (m) or None.
        """
        sx, sy = transform.m11(), transform.m22()
        keys = tuple(p.key for p in paths)
        same_scale = abs(sx / self.sx - 1) < 1e-6 and abs(sy / self.sy - 1) < 1e-6
        if (self.stale or self.image is None or not same_scale or keys != self.keys
                or level != self.level or dpr != self.dpr or view_px != self.view_size):
            # the old image may stand in for a zoom or resize; not for other paths
            keep = not self.stale and keys == self.keys and dpr == self.dpr
            self._layout(paths, level, transform, view_px, dpr, keep)
        view = self._view_rect(transform)
        m = self.MARGIN_PX // 2
        r = self.rect
        if not _inside(view, (r[0] + m, r[1] - m, r[2] + m, r[3] - m)):
            self._move(self._wanted_rect(view, bounds))
        self._commit(paths, columns)
        self._work(paths, columns, view)

    def _view_rect(self, transform: QTransform) -> Rect:
        """The view box in grid pixels, and 2 px around (the blit is rounded to pixels)."""
        u0 = self.dx0 - transform.dx()
        v0 = self.dy0 - transform.dy()
        w, h = self.view_size
        return (math.floor(u0) - 2, math.ceil(u0 + w) + 2, math.floor(v0) - 2,
                math.ceil(v0 + h) + 2)

    def _wanted_rect(self, view: Rect, bounds) -> Rect:
        """The view and a margin; with the paths' extent and half a view around if that fits."""
        m = self.MARGIN_PX
        r = (view[0] - m, view[1] + m, view[2] - m, view[3] + m)
        if bounds is not None and all(map(math.isfinite, bounds)):
            x0, x1, y0, y1 = bounds
            hw, hh = (view[1] - view[0]) // 2 + m, (view[3] - view[2]) // 2 + m
            u0, u1 = sorted(((x0 - self.gx) * self.sx, (x1 - self.gx) * self.sx))
            v0, v1 = sorted(((y0 - self.gy) * self.sy, (y1 - self.gy) * self.sy))
            big = (min(r[0], math.floor(u0) - hw), max(r[1], math.ceil(u1) + hw),
                   min(r[2], math.floor(v0) - hh), max(r[3], math.ceil(v1) + hh))
            if (big[1] - big[0]) * (big[3] - big[2]) * self.dpr**2 <= self.MAX_PIXELS:
                r = big
        return r

    def _layout(self, paths, level, transform, view_px, dpr, keep: bool) -> None:
        """A new grid at the view box's current pixels; everything to be drawn anew.
        ``keep``: the old image, if complete in view, stands in until then."""
        if not keep:
            self.preview = None
        elif self.image is not None and not self.veiled:
            self.preview = (self.image, self.sx, self.sy, self.ox, self.oy)
        self.sx, self.sy = transform.m11(), transform.m22()
        self.dx0, self.dy0 = transform.dx(), transform.dy()
        self.gx, self.gy = -self.dx0 / self.sx, -self.dy0 / self.sy  # grid (0, 0) = view corner
        self.view_size, self.dpr, self.level = view_px, dpr, level
        self.keys = tuple(p.key for p in paths)
        self.done = {p.key: p.decimator.level_size(level) for p in paths}
        self.prepareGeometryChange()
        self.image, self.rect = None, (0, 0, 0, 0)
        self.todo, self.veiled = [], []
        self.stale = False
        self.stats["full"] += 1
        self.stats["full_ms"] = 0.0  # drawing the visible part, over the frames it takes
        self.stats["full_frames"] = 0
        self._drawing_view = True

    def _move(self, new: Rect) -> None:
        """Make the image cover grid rect ``new``: pixels inside both are kept, the rest
        is queued to be drawn."""
        old, d = self.rect, self.dpr
        w, h = new[1] - new[0], new[3] - new[2]
        du, dv = new[0] - old[0], new[2] - old[2]
        if self.image is not None and (w, h) == (self.img_w, self.img_h) and _meets(old, new):
            a = np.frombuffer(self.image.bits(), np.uint32).reshape(h * d, -1)[:, : w * d]
            U, V = du * d, dv * d  # noqa: N806 - device pixels
            a[max(-V, 0) : h * d - max(V, 0), max(-U, 0) : w * d - max(U, 0)] = a[
                max(V, 0) : h * d + min(V, 0), max(U, 0) : w * d + min(U, 0)]
            a[: max(-V, 0)] = 0
            a[h * d - max(V, 0) :] = 0
            a[:, : max(-U, 0)] = 0
            a[:, w * d - max(U, 0) :] = 0
        else:
            image = QImage(w * d, h * d, QImage.Format.Format_ARGB32_Premultiplied)
            image.setDevicePixelRatio(d)
            image.fill(0)
            if self.image is not None and _meets(old, new):
                painter = QPainter(image)
                painter.setCompositionMode(QPainter.CompositionMode.CompositionMode_Source)
                painter.drawImage(QPointF(-du, -dv), self.image)
                painter.end()
            self.image = image
        self.prepareGeometryChange()
        self.rect = new
        self.todo = [a for a in self.todo if _meets(a.rect, new)]
        for a in self.todo:
            a.rect = (max(a.rect[0], new[0]), min(a.rect[1], new[1]), max(a.rect[2], new[2]),
                      min(a.rect[3], new[3]))
        self.todo += [_Area(r, dict(self.done)) for r in _minus(new, old)]
        self.update()
        self.stats["moves"] += 1

    def _work(self, paths, columns, view: Rect) -> None:
        """Draw the queued areas in tiles, nearest the view's centre first: those meeting
        the view (whole: a sliver costs as much as its tile) at once, or within
        ``VISIBLE_BUDGET_S`` while the old image stands in; then the rest within
        ``BUDGET_S``. At least one step is drawn per call."""
        t0 = time.perf_counter()
        cu, cv = (view[0] + view[1]) / 2, (view[2] + view[3]) / 2
        areas = []
        for a in self.todo:
            if a.fresh and (a.rect[1] - a.rect[0] > self.TILE_PX
                            or a.rect[3] - a.rect[2] > self.TILE_PX):
                areas += [_Area(t, a.upto) for t in _tiles(a.rect, self.TILE_PX)]
            else:
                areas.append(a)
        areas.sort(key=lambda a: -abs((a.rect[0] + a.rect[1]) / 2 - cu)
                   - abs((a.rect[2] + a.rect[3]) / 2 - cv))  # nearest last: popped first
        seen = [a for a in areas if _meets(a.rect, view)]
        later = [a for a in areas if not _meets(a.rect, view)]
        budget = self.VISIBLE_BUDGET_S if self.preview is not None else math.inf
        first = True
        while seen and (first or time.perf_counter() - t0 <= budget):
            first = False
            if self._draw_area(seen[-1], paths, columns, t0 + budget):
                seen.pop()
        if self._drawing_view:
            self.stats["full_ms"] += (time.perf_counter() - t0) * 1e3
            self.stats["full_frames"] += 1
            self._drawing_view = bool(seen)
        if not seen:
            self.preview = None
            while later and time.perf_counter() - t0 <= self.BUDGET_S:
                if self._draw_area(later[-1], paths, columns, t0 + self.BUDGET_S):
                    later.pop()
        self.todo = later + seen
        self.veiled = [QRectF(*self._odom_box((a.rect[0] - self.rect[0], a.rect[1] - self.rect[0],
                                               a.rect[2] - self.rect[2], a.rect[3] - self.rect[2]),
                                              0.0)) for a in seen]
        self.stats["pending"] = len(self.todo)
        self.stats["pending_in_view"] = len(seen)

    def finish(self, paths, columns) -> None:
        """Draw every queued area now (tests, screenshots)."""
        for a in self.todo:
            self._draw_area(a, paths, columns, math.inf)
        self.todo, self.veiled, self.preview = [], [], None
        self.stats["pending"] = self.stats["pending_in_view"] = 0

    def _draw_area(self, a: _Area, paths, columns, deadline: float) -> bool:
        """Draw area ``a``, clipped to its rect, in steps of ``STEP_POINTS`` until it is
        done (True) or the clock passes ``deadline`` (s, perf_counter; one step at least)."""
        area = self.data_rect(a.rect, pad_px=4.0)
        u0, v0 = a.rect[0] - self.rect[0], a.rect[2] - self.rect[2]
        clip = (u0, u0 + a.rect[1] - a.rect[0], v0, v0 + a.rect[3] - a.rect[2])
        painter = QPainter(self.image)
        painter.setClipRect(QRectF(clip[0], clip[2], clip[1] - clip[0], clip[3] - clip[2]))
        while a.k < len(paths):
            path = paths[a.k]
            if a.rows is None:
                a.rows, a.connect = path.decimator.runs_in(self.level, area, 0,
                                                           a.upto[path.key])
            if a.s + 1 >= len(a.rows):  # this path is done here: the next
                a.k, a.s, a.rows, a.connect = a.k + 1, 0, None, None
                continue
            end = min(a.s + self.STEP_POINTS, len(a.rows) - 1)
            connect = a.connect[a.s : end + 1].copy()  # to point ``end``: the joining segment
            connect[-1] = False
            self._stroke(painter, path.pen, columns[path.key], a.rows[a.s : end + 1], connect,
                         (clip[0] - 4.0, clip[1] + 4.0, clip[2] - 4.0, clip[3] + 4.0))
            a.s = end
            if time.perf_counter() > deadline:
                break
        painter.end()
        self.update(QRectF(*self._odom_box(clip, 0.0)))
        if a.k < len(paths):
            return False
        self.stats["tiles"] += 1
        return True

    def _odom_box(self, px: tuple, pad: float) -> tuple[float, float, float, float]:
        """Image pixels (u0, u1, v0, v1) as (x, y, width, height) in odom (m), for update()."""
        x0, x1, y0, y1 = self.data_rect((px[0] + self.rect[0], px[1] + self.rect[0],
                                         px[2] + self.rect[2], px[3] + self.rect[2]), pad)
        return x0, y0, x1 - x0, y1 - y0

    def _commit(self, paths, columns) -> None:
        """Draw the segments of the points kept since the last call; repaint only their box."""
        for path in paths:
            dec = path.decimator
            n, done = dec.level_size(self.level), self.done[path.key]
            if n <= done:
                continue
            rows = dec.rows(self.level, max(0, done - 1), n)
            painter = QPainter(self.image)
            box = self._stroke(painter, path.pen, columns[path.key], rows, None)
            painter.end()
            self.done[path.key] = n
            self.stats["commits"] += 1
            if box is not None:
                self.update(QRectF(*self._odom_box(box, 3.0)))

    def _stroke(self, painter: QPainter, pen, xy, rows, connect, px_rect=None):
        """Draw the points at ``rows`` of the columns ``xy`` as polylines (``connect`` as
        for arrayToQPath, None: one line), only the segments that meet ``px_rect`` (image
        pixels (u0, u1, v0, v1); None: all); returns their pixel box (u0, u1, v0, v1)."""
        if len(rows) < 2:
            return None
        u = (xy[0][rows] - self.ox) * self.sx
        v = (xy[1][rows] - self.oy) * self.sy
        if px_rect is not None:
            u, v, connect = _segments_meeting(u, v, connect, px_rect)
            if len(u) < 2:
                return None
        painter.setPen(pen)
        painter.drawPath(pg.functions.arrayToQPath(u, v, connect="all" if connect is None
                                                   else connect))
        return float(u.min()), float(u.max()), float(v.min()), float(v.max())

    # -- painting ---------------------------------------------------------------------------

    def paint(self, painter, option, widget=None) -> None:
        if self.image is None:
            return
        self.stats["paints"] += 1
        t = painter.transform()  # odom -> device
        if self.preview is not None and self.veiled:
            image, sx, sy, ox, oy = self.preview
            veil = QPainterPath()
            for r in self.veiled:
                veil.addRect(r)
            painter.save()
            painter.setClipPath(veil, Qt.ClipOperation.IntersectClip)
            painter.setTransform(QTransform(1 / sx, 0, 0, 1 / sy, ox, oy) * t)
            painter.drawImage(QPointF(0, 0), image)
            painter.restore()
        to_image = QTransform(1 / self.sx, 0, 0, 1 / self.sy, self.ox, self.oy) * t
        if (abs(to_image.m11() - 1) < 1e-6 and abs(to_image.m22() - 1) < 1e-6
                and to_image.m12() == 0 and to_image.m21() == 0):
            # the usual case: same scale as drawn, a blit at whole pixels
            painter.resetTransform()
            painter.drawImage(QPointF(round(to_image.dx()), round(to_image.dy())), self.image)
        else:  # zoomed since the last sync: stretched until the next one
            painter.setTransform(to_image)
            painter.drawImage(QPointF(0, 0), self.image)


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
            # one level of ticks and labels: the axes are redrawn with every pan (follow)
            axis.setStyle(maxTickLevel=1, maxTextLevel=1)
            self.plot.setLabel(side, name)
        # a fixed width: labels growing a digit would resize the map, and a new size
        # means drawing all paths anew
        self.plot.getAxis("left").setWidth(AXIS_WIDTH_PX)
        self.grid = []
        self._grid_key: tuple | None = None  # (pixel size, area) the grid lines were made for
        for z, colour in enumerate(GRID_COLOURS):
            item = _Lines(pg.mkPen(colour, width=1), connect="pairs")
            item.setZValue(-10 + z)
            self.vb.addItem(item, ignoreBounds=True)
            self.grid.append(item)

        self.raster = _PathRaster()
        self.vb.addItem(self.raster, ignoreBounds=True)
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
        self.robot_outline = _Lines(pen)
        self.robot_heading = _Lines(pen, connect="pairs")
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
            dot = _dot(colour)
            axes = _Lines(pg.mkPen(colour, width=2), connect="pairs")
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
        lines = [*self.grid, self.robot_outline, self.robot_heading,
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
        """The points drawn for a path (m, odom), in path order: those of the raster (the
        segments near its area) then the live end, without repeated joining points."""
        path, hist, r = self.paths[key], self.ctx.session.history, self.raster
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
        hist = self.ctx.session.history
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
        hist = self.ctx.session.history
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
        self._draw_paths(hist)
        # our own range changes above need nothing more; rows left over or areas of the
        # raster still to draw (off the screen) bring the next frame here again
        self._dirty = behind or bool(self.raster.todo)
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
                self.raster.invalidate()
            if path.columns[0] in hist.index:
                end = min(len(hist), dec.rows_seen + MAX_ROWS_PER_REFRESH)
                dec.update(hist.column(path.columns[0])[:end], hist.column(path.columns[1])[:end])
                behind |= end < len(hist)
        self._dropped = hist.dropped_rows
        return behind

    def _drawing_order(self) -> list[_Path]:
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
            items["dot"].setPos(m.x, m.y)
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
        """Grid lines over three views' width and height around the view: made again only
        when the view leaves that area or the zoom changes (not with every follow step)."""
        (x0, x1), (y0, y1) = self.vb.viewRange()
        pixel = (x1 - x0) / max(self.vb.width(), 1.0)
        key = self._grid_key
        if key is not None and abs(key[0] / pixel - 1) < 1e-3 and _within((x0, x1, y0, y1), key[1]):
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


def _within(inner, outer) -> bool:
    """(xmin, xmax, ymin, ymax) ``inner`` inside ``outer``."""
    return outer[0] <= inner[0] and inner[1] <= outer[1] and outer[2] <= inner[2] and (
        inner[3] <= outer[3])


def _segments_meeting(u, v, connect, rect):
    """The polylines (points ``u``, ``v``, ``connect`` as for arrayToQPath) cut down to
    the segments whose bounding box meets ``rect`` = (u0, u1, v0, v1)."""
    u0, u1, v0, v1 = rect
    a, b = slice(0, -1), slice(1, None)
    seg = ((np.maximum(u[a], u[b]) >= u0) & (np.minimum(u[a], u[b]) <= u1)
           & (np.maximum(v[a], v[b]) >= v0) & (np.minimum(v[a], v[b]) <= v1))
    if connect is not None:
        seg &= connect[:-1]
    keep = np.zeros(len(u), dtype=bool)
    keep[:-1] = seg
    keep[1:] |= seg
    joined = np.append(seg, False)
    return u[keep], v[keep], joined[keep]


def _show(item, on: bool) -> None:
    """setVisible only on a change (each call into Qt costs; most frames change nothing)."""
    if item.isVisible() != bool(on):
        item.setVisible(bool(on))


def _pose_text(x: float, y: float, yaw: float) -> str:
    return f"x {x:+.3f} m  y {y:+.3f} m  yaw {math.degrees(yaw):+.1f}°"


def _format_length(m: float) -> str:
    return f"{m * 100:.0f} cm" if m < 1 else f"{m:.3g} m"
