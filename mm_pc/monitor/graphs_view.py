"""Graphs of each sensor's displacement and speed over time, in a scrolling window.

Per sensor two plots against t (s since the first reply): the displacement
per reply (processed: filtered and calibrated; mm, sensor frame X/Y) and the
speed (mm/s). Only the rows inside the window are handed to the curves (found
with a binary search on t), so a redraw costs the same with a minute or an
hour of history. Paused, nothing is redrawn and the plots can be zoomed and
panned; resuming jumps back to the live window.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import (
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from .session import sensor_columns

__all__ = ["DEFAULT_WINDOW_S", "GraphsView", "window_slice"]

DEFAULT_WINDOW_S = 10
MAX_WINDOW_S = 3600
#: (key, title, history fields, unit)
PLOTS = (
    ("disp", "displacement per sample", ("dx", "dy"), "mm"),
    ("speed", "speed", ("vx", "vy"), "mm/s"),
)
AXIS_COLOURS = {"x": "#d62728", "y": "#1f77b4"}


def window_slice(t: np.ndarray, seconds: float) -> slice:
    """The rows of ``t`` (ascending, s) within ``seconds`` of its newest value."""
    if len(t) == 0:
        return slice(0, 0)
    return slice(int(np.searchsorted(t, t[-1] - seconds, side="left")), len(t))


class GraphsView(QWidget):
    """Displacement and speed of every sensor over the last ``window`` seconds."""

    def __init__(self, ctx, parent=None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self._version = -1
        self._built_for: tuple[str, ...] = ()
        #: (sensor index, plot key, "x" | "y") -> PlotDataItem
        self.curves: dict[tuple[int, str, str], pg.PlotDataItem] = {}
        self.plots: dict[tuple[int, str], pg.PlotItem] = {}

        self.window_box = QSpinBox()
        self.window_box.setRange(1, MAX_WINDOW_S)
        self.window_box.setValue(DEFAULT_WINDOW_S)
        self.window_box.setSuffix(" s")
        self.window_box.setToolTip("seconds of history shown (1..3600)")
        self.window_box.valueChanged.connect(self._invalidate)
        self.pause_button = QPushButton("Pause")
        self.pause_button.setCheckable(True)
        self.pause_button.setToolTip("freeze the graphs to zoom and pan; resume returns to live")
        self.pause_button.toggled.connect(self.set_paused)
        self.note = QLabel("waiting for data")
        bar = QHBoxLayout()
        bar.addWidget(QLabel("Window"))
        bar.addWidget(self.window_box)
        bar.addWidget(self.pause_button)
        bar.addStretch(1)
        bar.addWidget(self.note)

        self.canvas = pg.GraphicsLayoutWidget()
        self.canvas.setBackground("w")
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.canvas, 1)

        ctx.devices_known.connect(self._build)
        ctx.session_reset.connect(self._on_reset)
        if ctx.session.devices:
            self._build(ctx.session.devices)

    # -- construction ----------------------------------------------------------------

    def _build(self, devices: tuple[str, ...]) -> None:
        if tuple(devices) == self._built_for:
            return
        self.canvas.clear()
        self.curves.clear()
        self.plots.clear()
        for k, dev in enumerate(devices):
            for row, (key, title, _fields, unit) in enumerate(PLOTS):
                plot = self.canvas.addPlot(row=row, col=k, title=f"{dev}: {title}")
                self._style(plot, unit)
                legend = plot.addLegend(offset=(5, 5))
                legend.setLabelTextColor("#222222")
                for axis in ("x", "y"):
                    pen = pg.mkPen(AXIS_COLOURS[axis], width=1.5)
                    curve = plot.plot([], [], pen=pen, name=f"{axis.upper()} ({unit})")
                    curve.setClipToView(True)
                    curve.setDownsampling(auto=True, method="peak")
                    self.curves[(k, key, axis)] = curve
                self.plots[(k, key)] = plot
        self._built_for = tuple(devices)
        self._apply_interaction()
        self._invalidate()

    @staticmethod
    def _style(plot: pg.PlotItem, unit: str) -> None:
        plot.showGrid(x=True, y=True, alpha=0.25)
        for name in ("left", "bottom"):
            axis = plot.getAxis(name)
            axis.setPen(pg.mkPen("#444444"))
            axis.setTextPen(pg.mkPen("#222222"))
        plot.setLabel("bottom", "t", units="s")
        plot.setLabel("left", unit)
        plot.getAxis("left").enableAutoSIPrefix(False)
        plot.getAxis("bottom").enableAutoSIPrefix(False)
        plot.titleLabel.setAttr("color", "#222222")

    # -- state -----------------------------------------------------------------------

    @property
    def window_s(self) -> int:
        """Seconds of history shown."""
        return self.window_box.value()

    @property
    def paused(self) -> bool:
        return self.pause_button.isChecked()

    def set_paused(self, paused: bool) -> None:
        """Pause (no redraw; zoom and pan allowed) or resume (back to the live window)."""
        if self.pause_button.isChecked() != bool(paused):
            self.pause_button.setChecked(bool(paused))  # re-enters through toggled
            return
        self.pause_button.setText("Resume" if paused else "Pause")
        self._apply_interaction()
        if not paused:
            for plot in self.plots.values():
                plot.enableAutoRange(axis="y")
            self._invalidate()
            self.refresh()

    def _apply_interaction(self) -> None:
        for plot in self.plots.values():
            plot.setMouseEnabled(x=self.paused, y=self.paused)

    def _invalidate(self, *_args) -> None:
        self._version = -1

    def _on_reset(self) -> None:
        for curve in self.curves.values():
            curve.setData([], [])
        self._invalidate()

    # -- drawing ---------------------------------------------------------------------

    def refresh(self) -> None:
        """Redraw the live window; returns at once when paused or nothing changed."""
        hist = self.ctx.session.history
        if self.paused or hist is None or hist.version == self._version:
            return
        if self._built_for != self.ctx.session.devices:
            self._build(self.ctx.session.devices)
        self._version = hist.version
        t = hist.column("t")
        if len(t) == 0:
            self.note.setText("no samples")
            return
        rows = window_slice(t, self.window_s)
        tw = t[rows]
        for k in range(len(self._built_for)):
            names = sensor_columns(k)
            for key, _title, fields, _unit in PLOTS:
                for axis, field in zip(("x", "y"), fields, strict=True):
                    self.curves[(k, key, axis)].setData(tw, hist.column(names[field])[rows] * 1e3)
        end = float(t[-1])
        for plot in self.plots.values():
            plot.setXRange(end - self.window_s, end, padding=0.0)
        self.note.setText(f"{len(tw)} of {len(t)} samples shown, t = {end:.1f} s")
