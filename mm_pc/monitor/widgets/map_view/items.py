"""The map's small graphics items: its view box, light line sets, dots and one path's live end."""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QRectF, Qt, Signal
from PySide6.QtGui import QColor, QIcon, QPainterPath, QPen, QPixmap
from PySide6.QtWidgets import (
    QGraphicsEllipseItem,
    QGraphicsItem,
)

from mm_pc.monitor.model.path_decimator import PathDecimator

__all__ = ["DrawnPath", "Lines", "MapViewBox", "arrow_segments", "colour_icon", "sensor_dot"]


def arrow_segments(tail, direction, length: float, head: float) -> list:
    """Line segments (pairs of points) of an arrow from ``tail`` along unit ``direction``."""
    tx, ty = tail
    dx, dy = direction
    hx, hy = tx + length * dx, ty + length * dy
    segs = [(tx, ty), (hx, hy)]
    for sign in (1.0, -1.0):
        a = math.atan2(dy, dx) + math.pi + sign * math.radians(25)
        segs += [(hx, hy), (hx + head * math.cos(a), hy + head * math.sin(a))]
    return segs


def colour_icon(colour: str) -> QIcon:
    pm = QPixmap(12, 12)
    pm.fill(QColor(colour))
    return QIcon(pm)


class MapViewBox(pg.ViewBox):
    """ViewBox that tells when the user dragged the map (to leave follow mode)."""

    user_panned = Signal()

    def mouseDragEvent(self, ev, axis=None):  # noqa: N802 - pyqtgraph API
        super().mouseDragEvent(ev, axis)
        if ev.button() in (Qt.MouseButton.LeftButton, Qt.MouseButton.MiddleButton):
            self.user_panned.emit()


class Lines(QGraphicsItem):
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


def sensor_dot(colour: str, size_px: float = 8.0) -> QGraphicsEllipseItem:
    """A filled circle of ``size_px`` on the screen whatever the zoom, white rimmed."""
    dot = QGraphicsEllipseItem(-size_px / 2, -size_px / 2, size_px, size_px)
    dot.setFlag(QGraphicsItem.GraphicsItemFlag.ItemIgnoresTransformations)
    dot.setBrush(QColor(colour))
    dot.setPen(QPen(QColor("white")))
    return dot


class DrawnPath:
    """One drawn path: its decimator and the curve of its newest end.

    What the raster (:class:`PathRaster`) holds is not drawn again: the
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
        self.live = Lines(self.pen)
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
