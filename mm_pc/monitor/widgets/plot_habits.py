"""How the monitor's time plots answer the mouse: the habits of PlotJuggler, Foxglove and
rqt_plot.

* The wheel zooms the **time** axis only, around the mouse; with Ctrl or Shift held the
  **value** axis instead.
* A double-click resets the view (what "reset" means is the owner's: :attr:`on_reset`).
* A plot in a page that scrolls (the Health tab) leaves the plain wheel to the page: it
  zooms time with Ctrl held, the value axis with Ctrl+Shift.
* Hovering reads values out: :attr:`TimePlotBox.on_hover` is told the time under the
  mouse (None when it leaves); :class:`HoverText` shows a text in the plot's corner.

The owner may take a time zoom itself (:attr:`TimePlotBox.on_time_zoom`: the live Graphs
change their window length instead, so they stay live). Wheel steps scale a range by
``1.02 ** (-delta / 8)``: one notch (120) is x0.74, as pyqtgraph's own wheel zoom.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPoint, QPointF, Qt
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import QAbstractScrollArea, QApplication, QGraphicsView

__all__ = ["HoverText", "TimePlotBox", "nearest_value", "wheel_axis", "wheel_scale"]

VALUE_MODIFIERS = Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier


def wheel_axis(modifiers, page_scroll: bool) -> int | None:
    """Which axis a wheel turn with ``modifiers`` zooms: 0 time, 1 value, None none (the
    page scrolls)."""
    ctrl = bool(modifiers & Qt.KeyboardModifier.ControlModifier)
    shift = bool(modifiers & Qt.KeyboardModifier.ShiftModifier)
    if page_scroll:
        if not ctrl:
            return None
        return 1 if shift else 0
    return 1 if (ctrl or shift) else 0


def wheel_scale(delta: float) -> float:
    """The factor a wheel turn of ``delta`` (1/8 degree; +120 a notch away from the user)
    scales a range by (< 1: zoom in)."""
    return 1.02 ** (-delta / 8.0)


class TimePlotBox(pg.ViewBox):
    """A ViewBox with the monitor's wheel and double-click habits (see the module).

    ``page_scroll``: a plain wheel is left to the page. ``on_time_zoom(factor)`` may take
    a time zoom (return True when it did); ``on_value_zoom()`` is told after a value zoom;
    ``on_reset()`` is called on a double-click (default: auto range both axes).
    """

    def __init__(self, page_scroll: bool = False, **kw) -> None:
        super().__init__(**kw)
        self.page_scroll = page_scroll
        self.on_time_zoom: Callable[[float], bool] | None = None
        self.on_value_zoom: Callable[[], None] | None = None
        self.on_reset: Callable[[], None] | None = None
        self.on_hover: Callable[[float | None], None] | None = None
        self.setAcceptHoverEvents(True)

    def hoverEvent(self, ev) -> None:  # noqa: N802 - pyqtgraph API
        if self.on_hover is None:
            return
        if ev.isExit():
            self.on_hover(None)
        else:
            self.on_hover(float(self.mapToView(ev.pos()).x()))

    def wheelEvent(self, ev, axis=None) -> None:  # noqa: N802 - Qt API
        if axis is None:
            axis = wheel_axis(ev.modifiers(), self.page_scroll)
        if axis is None:
            self._scroll_page(ev)
            return
        s = wheel_scale(ev.delta())
        if axis == 0 and self.on_time_zoom is not None and self.on_time_zoom(s):
            ev.accept()
            return
        # whether or not the mouse may pan it (the live Graphs may not), the wheel zooms
        centre = self.mapToView(ev.pos())
        self._resetTarget()
        self.scaleBy([s, None] if axis == 0 else [None, s], centre)
        ev.accept()
        mask = [axis == 0, axis == 1]
        self.sigRangeChangedManually.emit(mask)
        if axis == 1 and self.on_value_zoom is not None:
            self.on_value_zoom()

    def _scroll_page(self, ev) -> None:
        """Hand a wheel turn to the scroll area around the plot's view (the page). Handed
        on explicitly: Qt would pass an ignored wheel event up only when it came from the
        window system, and the plot's own view would swallow it first."""
        widget = ev.widget()
        area = widget.parentWidget() if widget is not None else None
        while area is not None and (isinstance(area, QGraphicsView)
                                    or not isinstance(area, QAbstractScrollArea)):
            area = area.parentWidget()
        if area is None:
            ev.ignore()
            return
        delta = ev.delta()
        vertical = ev.orientation() == Qt.Orientation.Vertical
        bar = area.verticalScrollBar() if vertical else area.horizontalScrollBar()
        turn = QWheelEvent(QPointF(0, 0), QPointF(ev.screenPos()), QPoint(0, 0),
                           QPoint(0, delta) if vertical else QPoint(delta, 0),
                           Qt.MouseButton.NoButton, ev.modifiers(), Qt.ScrollPhase.NoScrollPhase,
                           False)
        QApplication.sendEvent(bar, turn)
        ev.setAccepted(turn.isAccepted())

    def mouseClickEvent(self, ev) -> None:  # noqa: N802 - Qt API
        if ev.double() and ev.button() == Qt.MouseButton.LeftButton:
            ev.accept()
            if self.on_reset is not None:
                self.on_reset()
            else:
                self.enableAutoRange()
            return
        super().mouseClickEvent(ev)


def nearest_value(x: np.ndarray | None, y: np.ndarray | None, t: float) -> tuple[float, float]:
    """(time, value) of the point of the curve ``x, y`` nearest to ``t`` (NaN, NaN: none)."""
    if x is None or y is None or not len(x):
        return math.nan, math.nan
    i = int(np.clip(np.searchsorted(x, t), 0, len(x) - 1))
    if i > 0 and abs(x[i - 1] - t) < abs(x[i] - t):
        i -= 1
    return float(x[i]), float(y[i])


class HoverText(pg.TextItem):
    """A text in the top-left corner of a ViewBox (screen position, not data), hidden
    while empty: what the mouse reads out of the plot."""

    def __init__(self, vb: pg.ViewBox) -> None:
        super().__init__("", color="#222222", fill=pg.mkBrush(255, 255, 255, 215), anchor=(0, 0))
        self.setParentItem(vb)
        self.setPos(4, 2)
        self.setZValue(100)
        self.hide()

    def show_text(self, text: str) -> None:
        self.setText(text)
        self.setVisible(bool(text))
