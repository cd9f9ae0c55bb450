"""The map's paths as one image in screen pixels, drawn incrementally (:class:`PathRaster`).

A repaint is one blit whatever the length of the history; new points are drawn onto the
image, a pan draws only the uncovered strips, a zoom redraws over a few frames.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QImage, QPainter, QPainterPath, QTransform

from mm_pc.monitor.model.screen_rects import Rect, inside, meets, minus, segments_meeting, tiles

__all__ = ["PathRaster"]


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


class PathRaster(pg.GraphicsObject):
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
        if not inside(view, (r[0] + m, r[1] - m, r[2] + m, r[3] - m)):
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
        if self.image is not None and (w, h) == (self.img_w, self.img_h) and meets(old, new):
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
            if self.image is not None and meets(old, new):
                painter = QPainter(image)
                painter.setCompositionMode(QPainter.CompositionMode.CompositionMode_Source)
                painter.drawImage(QPointF(-du, -dv), self.image)
                painter.end()
            self.image = image
        self.prepareGeometryChange()
        self.rect = new
        self.todo = [a for a in self.todo if meets(a.rect, new)]
        for a in self.todo:
            a.rect = (max(a.rect[0], new[0]), min(a.rect[1], new[1]), max(a.rect[2], new[2]),
                      min(a.rect[3], new[3]))
        self.todo += [_Area(r, dict(self.done)) for r in minus(new, old)]
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
                areas += [_Area(t, a.upto) for t in tiles(a.rect, self.TILE_PX)]
            else:
                areas.append(a)
        areas.sort(key=lambda a: -abs((a.rect[0] + a.rect[1]) / 2 - cu)
                   - abs((a.rect[2] + a.rect[3]) / 2 - cv))  # nearest last: popped first
        seen = [a for a in areas if meets(a.rect, view)]
        later = [a for a in areas if not meets(a.rect, view)]
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
            u, v, connect = segments_meeting(u, v, connect, px_rect)
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
