"""The coverage grid as a QImage whose changed cells alone are written and repainted.

One changed cell costs the same on a 1000 x 1000 map as on the seed's 81 x 71
(docs/maps-and-fixes.md has the measurement and the image placement).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QRectF
from PySide6.QtGui import QImage, QPainter, QTransform
from PySide6.QtWidgets import (
    QGraphicsItem,
)

from mm_pc.core.maps.coverage_map import CoverageMap
from mm_pc.monitor.widgets.maps_view.palette import DISPLAY_RGB8 as COLORS_RGB8

__all__ = ["CODE_PIXELS", "GridImageItem"]

#: uint32 0xFFRRGGBB per code: a pixel of a Format_RGB32 QImage (the colour-blind-safe
#: display palette, palette.DISPLAY_RGB8, not the seed's greens).
CODE_PIXELS = (
    np.uint32(0xFF000000)
    | (COLORS_RGB8[:, 0].astype(np.uint32) << 16)
    | (COLORS_RGB8[:, 1].astype(np.uint32) << 8)
    | COLORS_RGB8[:, 2].astype(np.uint32)
)
CODE_PIXELS.flags.writeable = False


# --- the grid image ------------------------------------------------------------------------


class GridImageItem(pg.GraphicsObject):
    """A coverage map as a QImage whose pixels are written only where cells changed.

    :meth:`set_map` draws a whole map (O(map), once); :meth:`write_cells` writes
    the given cells and repaints only their rectangles (O(cells)).
    ``pixels_written`` counts the pixels written by :meth:`write_cells`.
    """

    def __init__(self) -> None:
        super().__init__()
        self.setFlag(QGraphicsItem.GraphicsItemFlag.ItemUsesExtendedStyleOption, True)
        self._image = QImage()
        self._pixels = np.zeros((0, 0), dtype=np.uint32)
        self._bits = None
        self.pixels_written = 0

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx) pixels = cells."""
        return self._pixels.shape

    def set_map(self, cmap: CoverageMap) -> None:
        """Show ``cmap`` (all cells) and place it: pixel (ix, iy) -> (x0 + ix*s, y0 + iy*s) m."""
        ny, nx = cmap.shape
        self.prepareGeometryChange()
        if self._pixels.shape != (ny, nx):
            self._image = QImage(nx, ny, QImage.Format.Format_RGB32)
            self._bits = self._image.bits()  # writable view of the image's own memory
            rows = np.frombuffer(self._bits, dtype=np.uint32).reshape(ny, -1)
            self._pixels = rows[:, :nx]
        self._pixels[:] = CODE_PIXELS[cmap.codes]
        s = cmap.cell_size
        x0, y0 = cmap.origin
        self.setTransform(QTransform(s, 0.0, 0.0, s, x0, y0))
        self.update()

    def write_cells(self, changed: Iterable[tuple[int, int, int]]) -> int:
        """Write the pixels of ``changed`` cells ((iy, ix, code); the last code of a cell
        wins) and mark their rectangles dirty; returns the number of pixels written."""
        last = {(iy, ix): code for iy, ix, code in changed}
        if not last:
            return 0
        pixels = self._pixels
        for (iy, ix), code in last.items():
            pixels[iy, ix] = CODE_PIXELS[code]
        if len(last) <= 32:
            for iy, ix in last:
                self.update(QRectF(ix, iy, 1.0, 1.0))
        else:
            cells = np.array(list(last), dtype=np.int64)
            lo, hi = cells.min(axis=0), cells.max(axis=0) + 1
            self.update(QRectF(lo[1], lo[0], hi[1] - lo[1], hi[0] - lo[0]))
        self.pixels_written += len(last)
        return len(last)

    def rgb(self) -> np.ndarray:
        """What the image shows as a (ny, nx, 3) uint8 RGB copy, row 0 = south."""
        p = self._pixels
        return np.stack([(p >> 16) & 255, (p >> 8) & 255, p & 255], axis=-1).astype(np.uint8)

    def boundingRect(self) -> QRectF:  # noqa: N802 - Qt API
        ny, nx = self._pixels.shape
        return QRectF(0.0, 0.0, float(nx), float(ny))

    def paint(self, painter: QPainter, option, widget=None) -> None:
        ny, nx = self._pixels.shape
        if nx == 0 or ny == 0:
            return
        r = option.exposedRect
        left = max(0, math.floor(r.left()))
        top = max(0, math.floor(r.top()))
        right = min(nx, math.ceil(r.right()))
        bottom = min(ny, math.ceil(r.bottom()))
        if right <= left or bottom <= top:
            return
        part = QRectF(left, top, right - left, bottom - top)
        painter.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, False)
        painter.drawImage(part, self._image, part)
