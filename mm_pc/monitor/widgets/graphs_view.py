"""Graphs of each sensor's displacement and speed over time, in a scrolling window.

Per sensor two plots against t (s since the first reply): first the speed
(mm/s, sensor frame X/Y; the displacement of the last 50 ms of replies over the time
their poll stamps span, so it stays flat at 500 Hz), then the displacement per reply (processed:
filtered and calibrated; mm). The displacement per reply depends on the
request interval -- a late reply covers more time and shows a spike while
the speed stays flat -- so it is second and its title says so. The legend
(X, Y colours) is a line above the plots, never over the curves; each value
axis names its one unit. Only the rows inside the window are handed to the curves (found
with a binary search on t), so a redraw costs the same with a minute or an
hour of history; a window of more than 4000 rows is drawn as the minimum
and maximum of 1000-2000 buckets (spikes stay visible), kept from frame to
frame so only newly completed buckets are computed
(:class:`~mm_pc.monitor.model.peak_decimator.PeakDecimator`). An outage (no rows
for a while: link lost, polling paused) is a break in the curves, not a line across
it (a NaN at its middle, drawn with ``connect="finite"``; :mod:`..model.outages`).
The axes are not moved with every frame: the time axis runs ``X_LEAD``
(10 %) of the window ahead of the newest row and moves on only when the data
reach its end (so the curves hold the window and up to the lead more), and
a value axis changes only when the data leave it or fill less than
``Y_SHRINK`` of it. Redrawing the axes' labels with every frame (and
pyqtgraph's auto range, clipping and downsampling in Python) cost most of a
frame: with an hour of history in the monitor window, frame p50 ~15 ->
~6 ms, p95 ~20 -> ~9 ms.
Paused, nothing is redrawn and the plots can be zoomed and panned; resuming
jumps back to the live window.

The mouse (:mod:`.plot_habits`): the wheel zooms time -- live by changing the window
length (the plots stay live), paused around the mouse; Ctrl or Shift + wheel zooms the
value axis (held until a double-click); a double-click resets the view; the time axes of
all plots are linked; hovering a plot reads its values out under the legend.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from mm_pc.monitor.model.outages import OutageFinder, with_breaks
from mm_pc.monitor.model.peak_decimator import PeakDecimator, bucket_size
from mm_pc.monitor.model.session import sensor_columns
from mm_pc.monitor.widgets.plot_habits import TimePlotBox
from mm_pc.monitor.widgets.style import (
    STALE_STYLE,
    sensor_axis_colour,
    sensor_colour,
    stale_text,
)

__all__ = ["AXIS_NAMES", "DEFAULT_WINDOW_S", "PLOTS", "GraphsView"]

DEFAULT_WINDOW_S = 10
MAX_WINDOW_S = 3600
#: (key, title, history fields, unit)
PLOTS = (
    ("speed", "speed", ("vx", "vy"), "mm/s"),
    ("disp", "displacement per reply<br>(∝ request interval)", ("dx", "dy"), "mm"),
)
#: the axes' names in the legend line (sensor frame)
AXIS_NAMES = {"x": "X (sensor right)", "y": "Y (sensor forward)"}
#: the time axis runs this fraction of the window ahead of the newest row and moves only
#: when the data reach its end (its labels are drawn again then, not with every frame)
X_LEAD = 0.1
#: the value axis is set from the data with room of this fraction of their span, and
#: changed only when the data leave it or fill less than Y_SHRINK of it
Y_PAD = 0.1
Y_SHRINK = 0.4
#: every plot's value axis this wide (px): the plots of a column line up, so their linked
#: time axes show the same times one above the other
AXIS_WIDTH_PX = 64
#: a plot is never drawn lower than this (px): below it the page scrolls
MIN_PLOT_HEIGHT = 120


def legend_html(devices: tuple[str, ...] = ()) -> str:
    """The legend line (drawn outside the plots): each sensor's colour (the one it has
    everywhere, :mod:`.style`), X in it and Y in its darker shade."""
    if not devices:
        devices = ("sensor 1",)
    parts = []
    for k, dev in enumerate(devices):
        keys = " ".join(
            f'<span style="color:{sensor_axis_colour(k, a)}">&#9644;&#9644; {a.upper()}</span>'
            for a in ("x", "y"))
        parts.append(f"{dev}: {keys}")
    return ("&nbsp;&nbsp;&nbsp;".join(parts) + f"&nbsp;&nbsp;&nbsp;({AXIS_NAMES['x']}, "
            f"{AXIS_NAMES['y']}; t: seconds since the first reply)")


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
        self._peaks: dict[str, PeakDecimator] = {}  # history column -> its bucket min/max
        self._outages = OutageFinder()
        self._rows_of: tuple = (None, 0)  # (history, dropped_rows) the caches belong to
        self._len = 0
        self._x_range: tuple[float, float] | None = None  # time range shown (s)
        self._y_ranges: dict[tuple[int, str], tuple[float, float]] = {}  # value range per plot
        #: plots whose value axis the user zoomed (held until a double-click)
        self._y_held: set[tuple[int, str]] = set()
        #: the window length before the wheel changed it (restored by a double-click)
        self._window_before_zoom: int | None = None

        self.window_box = QSpinBox()
        self.window_box.setRange(1, MAX_WINDOW_S)
        self.window_box.setValue(DEFAULT_WINDOW_S)
        self.window_box.setSuffix(" s")
        self.window_box.setToolTip("seconds of history shown (1..3600)")
        self.window_box.valueChanged.connect(self._invalidate)
        self.window_box.valueChanged.connect(self._window_typed)
        self._zooming = False
        self.pause_button = QPushButton("Pause")
        self.pause_button.setCheckable(True)
        self.pause_button.setToolTip("freeze the graphs to zoom and pan; resume returns to live")
        self.pause_button.toggled.connect(self.set_paused)
        self.note = QLabel("waiting for data")
        self._note_base = "waiting for data"  # the note without the stale part
        # wraps rather than widen the page: at 800 px it made the tab scroll sideways
        self.note.setWordWrap(True)
        self.note.setAlignment(Qt.AlignRight | Qt.AlignVCenter)
        bar = QHBoxLayout()
        bar.addWidget(QLabel("Window"))
        bar.addWidget(self.window_box)
        bar.addWidget(self.pause_button)
        bar.addStretch(1)
        bar.addWidget(self.note)

        self.legend = QLabel(legend_html())
        self.legend.setWordWrap(True)
        self.legend.setToolTip(
            "Speed is the displacement of the replies of the last 50 ms divided by the "
            "time their poll stamps span; the "
            "displacement per reply grows when a reply comes late (the request interval), "
            "so a spike there with a flat speed is no sensor glitch.")
        self.readout = QLabel("hover a plot to read its values; wheel: zoom time, "
                              "Ctrl+wheel: zoom values, double-click: reset")
        self.readout.setWordWrap(True)
        self.canvas = pg.GraphicsLayoutWidget()
        self.canvas.setBackground("w")
        self.canvas.scene().sigMouseMoved.connect(self._hover)
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.legend)
        lay.addWidget(self.readout)
        lay.addWidget(self.canvas, 1)

        ctx.devices_known.connect(self._build)
        ctx.session_reset.connect(self._on_reset)
        ctx.data_state_changed.connect(self._on_data_state)
        if ctx.session.devices:
            self._build(ctx.session.devices)

    # -- construction ----------------------------------------------------------------

    def _build(self, devices: tuple[str, ...]) -> None:
        if tuple(devices) == self._built_for:
            return
        self.canvas.clear()
        self.curves.clear()
        self.plots.clear()
        self._y_held.clear()
        master = None
        for k, dev in enumerate(devices):
            for row, (key, title, _fields, unit) in enumerate(PLOTS):
                vb = TimePlotBox()
                vb.on_time_zoom = self._zoom_time
                vb.on_value_zoom = lambda pk=(k, key): self._y_held.add(pk)
                vb.on_reset = self.reset_view
                plot = self.canvas.addPlot(row=row, col=k, viewBox=vb)
                if master is None:
                    master = plot
                else:
                    plot.setXLink(master)  # one time axis for every plot
                plot.setTitle(f'<span style="color:{sensor_colour(k)}">{dev}</span><br>{title}',
                              color="#222222")
                self._style(plot, title, unit)
                for axis in ("x", "y"):
                    pen = pg.mkPen(sensor_axis_colour(k, axis), width=1)
                    # no clipping or downsampling by pyqtgraph: the points are the window's
                    # already (min/max buckets when long), and both cost with every frame
                    curve = plot.plot([], [], pen=pen, skipFiniteCheck=True, connect="finite")
                    self.curves[(k, key, axis)] = curve
                plot.disableAutoRange()  # the ranges are set in refresh (rarely)
                if row < len(PLOTS) - 1:  # one time axis per column, under its last plot:
                    plot.hideAxis("bottom")  # the axes' labels are what a range step costs
                self.plots[(k, key)] = plot
        self._built_for = tuple(devices)
        self.legend.setText(legend_html(self._built_for))
        self._fit_canvas()
        self._apply_interaction()
        self._invalidate()

    def _fit_canvas(self) -> None:
        """The canvas never shrinks below what its plots need (pyqtgraph would draw the
        last column past the edge, unseen): a narrower tab scrolls (the window's scroll
        area) to every sensor's plots instead."""
        for plot in self.plots.values():  # the axes' fixed widths in the hints
            plot.layout.invalidate()
        self.canvas.ci.layout.invalidate()
        need = self.canvas.ci.effectiveSizeHint(Qt.MinimumSize)
        frame = 2 * self.canvas.frameWidth() + 4
        self.canvas.setMinimumSize(int(need.width()) + frame,
                                   max(int(need.height()) + frame, MIN_PLOT_HEIGHT * len(PLOTS)))

    @staticmethod
    def _style(plot: pg.PlotItem, title: str, unit: str) -> None:
        # no grid: its translucent lines cost 3-4x the curves' paint time (software raster)
        plot.addLine(y=0.0, pen=pg.mkPen("#bbbbbb", width=1))
        for name in ("left", "bottom"):
            axis = plot.getAxis(name)
            axis.setPen(pg.mkPen("#444444"))
            axis.setTextPen(pg.mkPen("#222222"))
        plot.setLabel("bottom", "t", units="s")
        plot.setLabel("left", f"{title.split('<br>')[0].split(' (')[0]} ({unit})")
        plot.getAxis("left").enableAutoSIPrefix(False)
        plot.getAxis("bottom").enableAutoSIPrefix(False)
        plot.getAxis("left").setWidth(AXIS_WIDTH_PX)

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
            self._invalidate()  # back to the live window and value ranges
            self.refresh()

    def _apply_interaction(self) -> None:
        for plot in self.plots.values():
            plot.setMouseEnabled(x=self.paused, y=self.paused)

    # -- mouse -----------------------------------------------------------------------

    def _zoom_time(self, factor: float) -> bool:
        """A wheel turn on the time axis: live, the window length scaled by ``factor``
        (1..MAX_WINDOW_S s; True); paused, False (the plot zooms around the mouse)."""
        if self.paused:
            return False
        old = self.window_s
        new = round(old * factor)
        if new == old:
            new = old + (1 if factor > 1 else -1)
        new = max(1, min(MAX_WINDOW_S, new))
        if self._window_before_zoom is None:
            self._window_before_zoom = old
        self._zooming = True
        try:
            self.window_box.setValue(new)
        finally:
            self._zooming = False
        self.refresh()
        return True

    def _window_typed(self, _value: int) -> None:
        if not self._zooming:  # a length typed in: a double-click keeps it
            self._window_before_zoom = None

    def reset_view(self) -> None:
        """A double-click: the window length the wheel changed back, the value axes back
        to the data; paused, the time axis back to the window shown when paused."""
        self._y_held.clear()
        if self._window_before_zoom is not None:
            window, self._window_before_zoom = self._window_before_zoom, None
            self.window_box.setValue(window)
        if not self.paused:
            self._invalidate()
            self.refresh()
            return
        rng = self._x_range
        for plot in self.plots.values():
            vb = plot.getViewBox()
            if rng is not None:
                vb.setXRange(*rng, padding=0.0)
            vb.setAutoVisible(y=True)
            vb.enableAutoRange(axis=pg.ViewBox.YAxis)
            vb.updateAutoRange()  # now, not at the next paint

    def _hover(self, pos) -> None:
        """The values of the plot under the mouse (scene position ``pos``) at its time."""
        for (k, key), plot in self.plots.items():
            vb = plot.getViewBox()
            if not vb.sceneBoundingRect().contains(pos):
                continue
            t = vb.mapSceneToView(pos).x()
            title, unit = next((p[1], p[3]) for p in PLOTS if p[0] == key)
            values = []
            shown_t = None
            for axis in ("x", "y"):
                x, y = self.curves[(k, key, axis)].getData()
                if x is None or not len(x):
                    continue
                i = int(np.clip(np.searchsorted(x, t), 1, len(x) - 1)) if len(x) > 1 else 0
                if len(x) > 1 and abs(x[i - 1] - t) < abs(x[i] - t):
                    i -= 1
                shown_t = float(x[i])
                v = "no data" if not np.isfinite(y[i]) else f"{y[i]:.3f}"
                values.append(f"{axis.upper()} {v}")
            if shown_t is None:
                return
            name = title.split("<br>")[0]
            self.readout.setText(f"{self._built_for[k]} {name} at t = {shown_t:.3f} s: "
                                 f"{', '.join(values)} {unit}")
            return

    def _invalidate(self, *_args) -> None:
        self._version = -1
        self._x_range = None
        self._y_ranges = {k: v for k, v in self._y_ranges.items() if k in self._y_held}

    def _on_reset(self) -> None:
        for cache in self._peaks.values():
            cache.clear()
        self._outages.reset()
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
            self._set_note("no samples")
            return
        if (hist, hist.dropped_rows) != self._rows_of or len(t) < self._len:
            for cache in self._peaks.values():
                cache.clear()  # rows were dropped or cleared: bucket numbers moved
            self._outages.reset()
        self._rows_of, self._len = (hist, hist.dropped_rows), len(t)
        outages = self._outages.update(t)
        end = float(t[-1])
        x0, _x1 = self._time_range(end, float(t[0]))
        rows = slice(int(np.searchsorted(t, x0, side="left")), len(t))
        size = bucket_size(rows.stop - rows.start)
        for k in range(len(self._built_for)):
            names = sensor_columns(k)
            for key, _title, fields, _unit in PLOTS:
                lo, hi = np.inf, -np.inf
                for axis, field in zip(("x", "y"), fields, strict=True):
                    cache = self._peaks.setdefault(names[field], PeakDecimator())
                    x, y = cache.window(t, hist.column(names[field]), rows.start, size)
                    x, y = with_breaks(x, y * 1e3, outages)
                    self.curves[(k, key, axis)].setData(x, y)
                    finite = y[np.isfinite(y)]
                    if len(finite):
                        lo, hi = min(lo, float(finite.min())), max(hi, float(finite.max()))
                self._set_value_range((k, key), lo, hi)
        shown = rows.stop - rows.start
        every = f", min/max of {size}-sample buckets" if size > 1 else ""
        nb = "\u00a0"  # "t = 27.5 s" stays on one line when the note wraps
        now = f"t{nb}={nb}{end:.1f}{nb}s"
        self._set_note(f"{shown} of {len(t)} samples in the window{every}, {now}")

    def _on_data_state(self, _state: str) -> None:
        self._set_note(self._note_base)

    def _set_note(self, text: str) -> None:
        """The note above the plots; while the link is lost or polling paused it says so
        (greyed): the curves end at the last data, they do not show the robot stopping."""
        self._note_base = text
        stale = stale_text(self.ctx)
        shown = f"{text}; {stale}" if stale else text
        if shown != self.note.text():  # a new text re-lays the page out
            self.note.setText(shown)
            self.note.setStyleSheet(STALE_STYLE if stale else "")

    def _time_range(self, end: float, first: float = -np.inf) -> tuple[float, float]:
        """The shown time range: ``window_s`` back from the newest row ``end`` (s) -- or
        from the first row ``first`` when the history is shorter (a 3600 s window over a
        minute of data shows that minute, not an empty axis) -- plus a lead of ``X_LEAD``
        of it; moved on only when ``end`` leaves it (or the window changed)."""
        rng = self._x_range
        if rng is None or not rng[0] <= end <= rng[1]:
            start = max(end - self.window_s, first)
            span = max(end - start, min(self.window_s, 1.0))
            rng = self._x_range = (start, end + X_LEAD * span)
            if self.plots:  # the others are linked to the first
                next(iter(self.plots.values())).setXRange(*rng, padding=0.0)
        return rng

    def _set_value_range(self, plot_key, lo: float, hi: float) -> None:
        """Set a plot's value range to hold [lo, hi] with room, changed only when the data
        leave the range or fill less than ``Y_SHRINK`` of it."""
        if not lo <= hi or plot_key in self._y_held:
            return
        span = max(hi - lo, 1e-3)
        old = self._y_ranges.get(plot_key)
        if old is not None and old[0] <= lo and hi <= old[1] and span >= Y_SHRINK * (
                old[1] - old[0]):
            return
        rng = (lo - Y_PAD * span, hi + Y_PAD * span)
        self._y_ranges[plot_key] = rng
        self.plots[plot_key].setYRange(*rng, padding=0.0)
