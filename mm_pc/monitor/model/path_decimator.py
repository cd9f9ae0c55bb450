"""A path decimated at several resolutions, incrementally, as row numbers (no Qt).

The Map view draws an hour of 100 Hz rows per path; :class:`PathDecimator` keeps, for each
level, only the rows where the path enters a new cell, so the view draws what a pixel can
show (docs/monitor.md has the figures).
"""

from __future__ import annotations

import numpy as np

__all__ = ["PIXEL_FRACTION", "Grow", "PathDecimator"]

#: Largest decimation cell allowed, as a fraction of one screen pixel.
PIXEL_FRACTION = 0.5


class Grow:
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
        self._rows = [Grow(1, np.int32) for _ in range(self.LEVELS)]
        self._boxes = [Grow(4) for _ in range(self.LEVELS)]  # per completed box

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
