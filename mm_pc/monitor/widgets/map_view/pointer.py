"""The map's cursor readout and distance measure (odom frame, metres).

A small label in the map's top-left corner says where the mouse is (``cursor x +0.123 m
y -0.456 m``). With **Measure** on, a click sets a first point and a second click a
second one: a dashed line joins them and the label adds ``distance 0.523 m (dx +0.500,
dy +0.153)``; between the two clicks the line follows the mouse. A third click starts a
new measure; **Measure** off clears it. Dragging still pans the map.
"""

from __future__ import annotations

import math

import pyqtgraph as pg
from PySide6.QtCore import QPointF, Qt
from PySide6.QtWidgets import QLabel, QPushButton

from mm_pc.monitor.widgets.map_view.items import Lines

__all__ = ["MapPointer", "measure_text"]

#: the measure line (drawn over the paths and the robot)
MEASURE_COLOUR = "#000000"
LABEL_STYLE = "background: rgba(255, 255, 255, 215); color: #222222; padding: 1px 4px"


def measure_text(cursor: tuple[float, float] | None, a: tuple[float, float] | None,
                 b: tuple[float, float] | None) -> str:
    """The label's text: the cursor and, once a first point is set, the distance from it
    to the second point (or to the cursor while there is none)."""
    parts = []
    if cursor is not None:
        parts.append(f"cursor x {cursor[0]:+.3f} m  y {cursor[1]:+.3f} m")
    end = b if b is not None else cursor
    if a is not None and end is not None:
        dx, dy = end[0] - a[0], end[1] - a[1]
        parts.append(f"distance {math.hypot(dx, dy):.3f} m (dx {dx:+.3f}, dy {dy:+.3f})")
    return "   ".join(parts)


class MapPointer:
    """Cursor readout and measure tool of one map (``vb``: its ViewBox, ``view``: the
    PlotWidget the label sits on, ``button``: the checkable Measure button)."""

    def __init__(self, vb: pg.ViewBox, view: pg.PlotWidget, button: QPushButton) -> None:
        self.vb = vb
        self.button = button
        self.cursor: tuple[float, float] | None = None
        self.a: tuple[float, float] | None = None
        self.b: tuple[float, float] | None = None
        pen = pg.mkPen(MEASURE_COLOUR, width=2)
        pen.setStyle(Qt.PenStyle.DashLine)
        self.line = Lines(pen)
        self.line.setZValue(30)
        vb.addItem(self.line, ignoreBounds=True)
        self.label = QLabel("", view.viewport())
        self.label.setStyleSheet(LABEL_STYLE)
        self.label.move(6, 4)
        self.label.hide()
        scene = view.scene()
        scene.sigMouseMoved.connect(self.moved)
        scene.sigMouseClicked.connect(self.clicked)
        button.toggled.connect(self.set_measuring)

    @property
    def measuring(self) -> bool:
        return self.button.isChecked()

    def set_measuring(self, on: bool) -> None:
        """Measure on (clicks set points) or off (the measure is cleared)."""
        self.a = self.b = None
        self._show()

    def _view_point(self, scene_pos: QPointF) -> tuple[float, float] | None:
        if not self.vb.sceneBoundingRect().contains(scene_pos):
            return None
        p = self.vb.mapSceneToView(scene_pos)
        return float(p.x()), float(p.y())

    def moved(self, scene_pos: QPointF) -> None:
        self.cursor = self._view_point(scene_pos)
        self._show()

    def clicked(self, ev) -> None:
        if not self.measuring or ev.button() != Qt.MouseButton.LeftButton or ev.double():
            return
        p = self._view_point(ev.scenePos())
        if p is None:
            return
        if self.a is None or self.b is not None:
            self.a, self.b = p, None
        else:
            self.b = p
        self.cursor = p
        ev.accept()
        self._show()

    def _show(self) -> None:
        end = self.b if self.b is not None else self.cursor
        if self.measuring and self.a is not None and end is not None:
            self.line.setData([self.a[0], end[0]], [self.a[1], end[1]])
            self.line.show()
        else:
            self.line.setData([], [])
            self.line.hide()
        text = measure_text(self.cursor, self.a if self.measuring else None, self.b)
        self.label.setText(text)
        self.label.adjustSize()
        self.label.setVisible(bool(text))
