"""Health of the link and the sensors (issue item 8).

* A table from the Beagle node's ``/diagnostics``, one column per sensor and
  one row per quantity in plain words with a tooltip each (state, polls per
  second, typical and worst poll gap, late polls, bus errors, lifts,
  overflows, poller CPU, last error), each column coloured by the status level.
* A plot of the two-sensor residual over time (history column ``residual``,
  metres, drawn in mm; NaN -- and said so -- unless the pose method is
  ``two-sensor``) and of the lift events per sample (``s{k}_lifts``).
* A plot of each sensor's surface-quality figure (history column ``s{k}_quality``: SQUAL
  of a PMW33xx/PMW3901 at the newest poll of each reply) with the chip's threshold as a
  dashed line: below it a poll is treated like a lift. A chip without a figure (the
  PLN2033, an old node or recording) says so ("no quality figure (chip X)") instead of an
  empty plot; the per-sensor "Low-quality polls" row counts the polls below the threshold.
* The session's counters (replies, used, restarts, incomplete) and the
  bridge's (dropped requests, skipped ticks).

``refresh()`` is cheap when nothing changed (history version and counters
compared) and redraws the curves at most ``PLOT_HZ`` times a second. An hour
at 100 Hz is 360 000 rows, far more than the plot has pixels, so the curves
show at most ``MAX_POINTS`` points of the visible time range, each the
*largest* value of its bucket of rows
(:class:`~mm_pc.monitor.model.peak_decimator.PeakDecimator`): a residual peak
or a single lift is never hidden by the thinning. While the plot follows the
data, only the rows added since the last redraw are read (a full column of
an hour's history is ~2.5 ms to read, the table being row-major). The plots
have no grid: with a grid, pyqtgraph's software paint took ~20 ms here.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QHeaderView,
    QLabel,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.chips import chip_key, chip_title, quality_label, quality_threshold
from mm_pc.monitor.model.outages import OutageFinder, with_breaks
from mm_pc.monitor.model.peak_decimator import PeakDecimator, bucket_peak
from mm_pc.monitor.widgets.plot_habits import HoverText, TimePlotBox, nearest_value
from mm_pc.monitor.widgets.style import ROBOT_COLOUR, sensor_colour

__all__ = ["DIAG_COLUMNS", "LEVEL_COLOURS", "HealthView"]

#: (column title, /diagnostics key, tooltip): plain words, each title with its one unit
DIAG_COLUMNS = (
    ("Status", "level", "OK, WARN (look at it), ERROR (the sensor does not work) or STALE "
     "(no report for a while), as the Beagle node judges it"),
    ("State", "state", "the sensor's state in the node: up, down (not answering), ..."),
    ("Polls/s (Hz)", "achieved_rate_hz", "how often the node read the sensor in the last "
     "second (the goal is 1000 per second)"),
    ("Typical gap (µs)", "period_p50_us", "time between two reads of the sensor, median "
     "(the goal is 1000 µs)"),
    ("Worst gap (µs)", "period_p99_us", "time between two reads that only 1 in 100 "
     "exceeded (99th percentile)"),
    ("Late polls", "late_polls", "reads that came later than planned (counts are kept, "
     "the step just covers more time)"),
    ("Bus errors", "spi_errors", "failed SPI transfers to the sensor chip (the read is "
     "repeated)"),
    ("Lifts", "lift_events", "reads in which the sensor saw no surface (lifted off the "
     "ground): its motion is estimated there"),
    ("Low-quality polls", "low_quality_events", "reads in which the chip saw the floor too "
     "poorly to trust its counts (its surface-quality figure, e.g. SQUAL, below the chip's "
     "threshold: a shiny, glass or very dark floor, or too high above it): treated like a "
     "lift, its motion is estimated there. Chips without a quality figure: always 0"),
    ("Overflows", "overflows", "reads in which the chip's counter ran over (counts lost: "
     "should stay 0)"),
    ("Poller CPU (%)", "poller_cpu_percent", "CPU time of the node's read loop, percent of "
     "one core"),
    ("Last error", "last_error", "the newest error the node reported for this sensor"),
    ("Message", "message", "the node's summary of this sensor"),
)
#: columns of free text: drawn elided in the width left, the whole text in the cell's tooltip
TEXT_COLUMNS = ("last_error", "message")
#: diagnostic_msgs/DiagnosticStatus level -> (name, row background)
LEVEL_COLOURS = {
    0: ("OK", "#d9f2d9"),
    1: ("WARN", "#fff0b3"),
    2: ("ERROR", "#f7c6c6"),
    3: ("STALE", "#dddddd"),
}
SESSION_TIP = (
    "replies received: answers of the node; used for the pose: those that moved the map.\n"
    "fresh starts: replies taken as a new starting point (the first one, after a node "
    "restart or a replay) -- their counts are not a motion.\n"
    "missing a sensor: replies without every sensor's data (the next full reply covers "
    "the gap, no count lost); refused: replies with numbers that are not finite.\n"
    "single polls: the node's 1 kHz reads the pose was built from; gaps bridged: stretches "
    "without those reads, crossed in one straight step; replies without polls: "
    "integrated as one step each.\n"
    "CPI changes: a sensor's resolution was changed; each poll is integrated at its own "
    "CPI, so a change is no gap and loses nothing (in a recording made before polls "
    "carried their CPI it is still bridged as a gap).")
BRIDGE_TIP = (
    "requests: questions the monitor sent at the sample rate; replies: answers.\n"
    "unanswered in time: given up after the timeout (the next reply's totals cover them).\n"
    "not sent: at a tick the previous request was still unanswered, so none was sent "
    "(a slow link; no count is lost).\n"
    "replies with an error: the node answered but the call failed.")
PLOT_HZ = 4.0
MAX_POINTS = 2000
#: zoomed in to at most this many rows: thin them afresh (finer than the cache)
ZOOM_ROWS = 50_000
STALE_S = 5.0
#: the plots' least height (px): two plots with their titles and axes readable
PLOTS_MIN_HEIGHT = 280
#: the table's look when its values are old (link lost, or no /diagnostics for STALE_S)
STALE_BACKGROUND = "#e6e6e6"
STALE_TEXT = "#808080"


class HealthView(QWidget):
    """Diagnostics table, residual and lift plots, session and bridge counters."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        pg.setConfigOptions(antialias=False)
        self.diagnostics: dict[str, dict] = {}
        self._diag_time: float | None = None
        self._version = -1
        self._method = ""
        self._last_plot = 0.0
        self._last_fit = 0.0
        self._stats_key: tuple = ()
        self.bridge_stats = None
        self._caches: dict[str, PeakDecimator] = {}
        self._hist_key: tuple = ()
        self._outage_finder = OutageFinder()
        self._outages = np.empty((0, 2))
        #: why the table's values are old ("" while they are fresh); shown in its cells
        self.stale_reason = ""

        # one row per quantity, one column per sensor: twelve quantities side by side did
        # not fit (the last column was cut off); two or four sensors do
        self.table = QTableWidget(len(DIAG_COLUMNS), 0)
        self.table.setEditTriggers(QTableWidget.NoEditTriggers)
        for r, (title, _key, tip) in enumerate(DIAG_COLUMNS):
            item = QTableWidgetItem(title)
            item.setToolTip(tip)
            self.table.setVerticalHeaderItem(r, item)
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.Stretch)
        self.table.verticalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        self.table.setTextElideMode(Qt.ElideRight)
        self.table.setWordWrap(False)
        # every row shown, down to "Message" that explains a WARN: the table never scrolls
        # inside itself (the page scrolls when the window is lower still)
        self.table.setVerticalScrollBarPolicy(Qt.ScrollBarAlwaysOff)
        self._fit_table()
        self.diag_state = QLabel("no /diagnostics received yet")
        self.session_label = QLabel()
        self.session_label.setWordWrap(True)
        self.session_label.setToolTip(SESSION_TIP)
        self.bridge_label = QLabel()
        self.bridge_label.setWordWrap(True)
        self.bridge_label.setToolTip(BRIDGE_TIP)
        self.residual_note = QLabel()
        self.residual_note.setWordWrap(True)

        self.plots = pg.GraphicsLayoutWidget()
        self.plots.setBackground("w")
        # the plots' axes and titles need this much; a lower window scrolls the page
        self.plots.setMinimumHeight(PLOTS_MIN_HEIGHT)
        # the page scrolls with the wheel; Ctrl+wheel zooms time, Ctrl+Shift+wheel values;
        # a double-click shows everything again (plot_habits)
        self.residual_plot = self.plots.addPlot(row=0, col=0, title="Two-sensor residual",
                                                viewBox=self._box())
        # one unit, named once: mm (pyqtgraph's SI prefix showed µm beside a text in m)
        self.residual_plot.setLabel("left", "residual (mm)")
        self.residual_plot.getAxis("left").enableAutoSIPrefix(False)
        # the robot's colour: the residual belongs to no one sensor
        self.residual_curve = self._curve(self.residual_plot, ROBOT_COLOUR)
        self.lift_plot = self.plots.addPlot(row=1, col=0, title="Lifted polls per reply",
                                            viewBox=self._box())
        self.lift_plot.setLabel("left", "lifted polls (count)")
        self.lift_plot.setLabel("bottom", "time (s)")
        for plot in (self.lift_plot, self.residual_plot):
            plot.getAxis("bottom").enableAutoSIPrefix(False)
        self.lift_plot.getAxis("left").enableAutoSIPrefix(False)
        # a count: the axis starts at 0 and shows at least 0..1 (an empty plot ran
        # -0.4..0.4 "(x0.001)")
        self.lift_plot.enableAutoRange(y=False)
        self.lift_plot.setYRange(0.0, 1.0, padding=0.05)
        self.lift_plot.setXLink(self.residual_plot)
        # no legend item over the curves: the title names each sensor's colour
        self.lift_curves: list[pg.PlotDataItem] = []
        self.quality_plot = self.plots.addPlot(row=2, col=0, title="Surface quality",
                                               viewBox=self._box())
        self.quality_plot.setLabel("left", "quality figure")
        self.quality_plot.setLabel("bottom", "time (s)")
        for axis in ("left", "bottom"):
            self.quality_plot.getAxis(axis).enableAutoSIPrefix(False)
        self.quality_plot.setXLink(self.residual_plot)
        self.quality_curves: list[pg.PlotDataItem] = []
        #: sensor index -> the dashed line at its chip's threshold
        self.threshold_lines: dict[int, pg.InfiniteLine] = {}
        #: what the quality plot says about sensors without a figure ('' = all have one)
        self.quality_note = QLabel("")
        self.quality_note.setWordWrap(True)
        self._chips: tuple[str, ...] = ()

        top = QWidget()
        tl = QVBoxLayout(top)
        tl.setContentsMargins(0, 0, 0, 0)
        tl.addWidget(QLabel("<b>Sensors</b> (Beagle node /diagnostics)"))
        tl.addWidget(self.table)
        tl.addWidget(self.diag_state)
        tl.addWidget(self.session_label)
        tl.addWidget(self.bridge_label)
        tl.addWidget(self.residual_note)
        tl.addWidget(self.quality_note)
        split = QSplitter(Qt.Vertical)
        split.addWidget(top)
        split.addWidget(self.plots)
        split.setStretchFactor(1, 2)
        self._top, self._split = top, split
        self._fit_table()
        QVBoxLayout(self).addWidget(split)

        if ctx.bridge is not None:
            ctx.bridge.diagnostics_received.connect(self.on_diagnostics)
            ctx.bridge.stats_updated.connect(self.on_bridge_stats)
        ctx.session_reset.connect(self._invalidate)
        ctx.odometry_changed.connect(self._invalidate)
        ctx.data_state_changed.connect(lambda _s: self._show_stale())
        self.residual_plot.getViewBox().sigXRangeChanged.connect(self._range_changed)
        self._show_counters()

    def _box(self) -> TimePlotBox:
        box = TimePlotBox(page_scroll=True)
        box.on_reset = self.reset_view
        box.readout = HoverText(box)
        box.on_hover = lambda t, b=box: self._hover(b, t)
        return box

    def _hover(self, box: TimePlotBox, t: float | None) -> None:
        """The values of the plot under the mouse at time ``t`` (s; None: it left)."""
        if t is None:
            box.readout.show_text("")
            return
        if box is self.residual_plot.getViewBox():
            named = [("", self.residual_curve, "mm")]
        elif box is self.lift_plot.getViewBox():
            named = [(f"s{k + 1} ", c, "") for k, c in enumerate(self.lift_curves)]
        else:
            named = [(f"s{k + 1} ", c, "") for k, c in enumerate(self.quality_curves)]
        parts, at = [], None
        for name, curve, unit in named:
            x, y = curve.getData()
            tx, v = nearest_value(x, y, t)
            if math.isnan(tx):
                continue
            at = tx
            value = "no data" if math.isnan(v) else f"{v:.4g}"
            parts.append(f"{name}{value}{' ' + unit if unit else ''}")
        box.readout.show_text(f"t = {at:.3f} s: {', '.join(parts)}" if parts else "")

    def reset_view(self) -> None:
        """A double-click on a plot: every plot shows all its data again."""
        for plot in (self.residual_plot, self.quality_plot):
            plot.enableAutoRange()
        self.lift_plot.enableAutoRange(x=True)  # its count axis is set from the data
        for plot in (self.residual_plot, self.lift_plot, self.quality_plot):
            plot.getViewBox().updateAutoRange()  # now, not at the next paint
        self._version = -1
        self._last_plot = 0.0

    @staticmethod
    def _curve(plot, colour: str, name: str | None = None) -> pg.PlotDataItem:
        return plot.plot(pen=pg.mkPen(colour, width=1), name=name, connect="finite")

    # -- inputs -----------------------------------------------------------------------------

    def on_diagnostics(self, status: dict) -> None:
        """One /diagnostics message: {device: {"level", "message", key: value-string}}."""
        self._diag_time = time.monotonic()
        for dev, values in status.items():
            self.diagnostics[dev] = dict(values)
        devices = list(self.diagnostics)
        if self.table.columnCount() != len(devices):
            self.table.setColumnCount(len(devices))
            self.table.setHorizontalHeaderLabels(devices)
            for c, dev in enumerate(devices):
                self.table.horizontalHeaderItem(c).setToolTip(f"sensor {c + 1}: {dev}")
        self.stale_reason = ""
        for c, dev in enumerate(devices):
            self._fill_column(c, self.diagnostics[dev])
        self._fit_table()
        self.diag_state.setText(f"/diagnostics: {len(devices)} sensor(s), updated just now")
        self._show_stale()

    def _stale_reason(self) -> str:
        """Why the table's values are old ("" when they are not)."""
        if self.ctx.data_state == "lost":
            return f"link lost: {self.ctx.no_data_since()}"
        if self._diag_time is not None and time.monotonic() - self._diag_time > STALE_S:
            since = time.strftime("%H:%M:%S", time.localtime(
                time.time() - (time.monotonic() - self._diag_time)))
            return f"no /diagnostics since {since}"
        return ""

    def _show_stale(self) -> None:
        """Grey the table and say why when its values are old: Status says "no data", State
        the reason, instead of the node's last "up" / "WARN"; fresh values restore them."""
        reason = self._stale_reason()
        if reason == self.stale_reason:
            return
        self.stale_reason = reason
        devices = list(self.diagnostics)
        for c, dev in enumerate(devices):
            self._fill_column(c, self.diagnostics[dev])
        if reason:
            self.diag_state.setText(f"/diagnostics: {reason}; the table shows the last "
                                    "values, greyed")
        elif devices:
            self.diag_state.setText("/diagnostics: the values of before, until the next update")

    def resizeEvent(self, event) -> None:  # noqa: N802 - Qt API
        super().resizeEvent(event)
        self._fit_table()  # the labels wrap to another height at another width

    def _needs_fit(self) -> bool:
        """A wrapped label under the table lower than its text needs at its width, or the
        table's pane lower than its least height (the splitter kept an old size)."""
        if self._split.isVisible() and self._split.sizes()[0] < self._top.minimumHeight():
            return True
        return any(lab.isVisible() and lab.height() < lab.heightForWidth(lab.width())
                   for lab in (self.session_label, self.bridge_label, self.residual_note,
                               self.quality_note))

    def _fit_table(self) -> None:
        """The table as high as all its rows and its header (px)."""
        rows = self.table.verticalHeader()
        height = sum(max(rows.sectionSize(r), rows.sectionSizeHint(r))
                     for r in range(self.table.rowCount()))
        height += self.table.horizontalHeader().sizeHint().height() + 2 * self.table.frameWidth()
        if self.table.horizontalScrollBar().isVisible():
            height += self.table.horizontalScrollBar().height()
        self.table.setFixedHeight(height)
        top, split = getattr(self, "_top", None), getattr(self, "_split", None)
        if top is None or split is None or not split.isVisible():
            return  # not laid out yet: the splitter starts from the panes' size hints
        # the splitter keeps the pane's old height when its content grows: the table was
        # drawn over the labels under it; give the pane what it needs, from the plots
        lay = top.layout()
        lay.activate()
        # the wrapped labels' height at this width (the minimum size hint ignores it)
        need = max(lay.totalMinimumSize().height(), lay.totalHeightForWidth(top.width()))
        if top.minimumHeight() != need:
            top.setMinimumHeight(need)  # the page scrolls rather than overlap the rows
            split.updateGeometry()  # the page (scroll area) takes the new least height
            self.updateGeometry()
            QTimer.singleShot(0, self._fit_table)  # the pane's size once the page grew
        sizes = split.sizes()
        if sizes and sizes[0] < need:
            split.setSizes([need, max(PLOTS_MIN_HEIGHT, sum(sizes) - need)])

    def _fill_column(self, c: int, values: dict) -> None:
        level = _level(values.get("level"))
        name, colour = LEVEL_COLOURS.get(level, (str(level), "#ffffff"))
        stale = self.stale_reason
        brush = QBrush(QColor(STALE_BACKGROUND if stale else colour))
        foreground = QBrush(QColor(STALE_TEXT if stale else "#000000"))
        for r, (title, key, tip) in enumerate(DIAG_COLUMNS):
            text = name if key == "level" else str(values.get(key, "–"))
            if stale and key == "level":
                text = "no data"
            elif stale and key == "state":
                text = stale
            item = self.table.item(r, c)
            if item is None:
                item = QTableWidgetItem()
                self.table.setItem(r, c, item)
            item.setText(text)
            item.setToolTip(f"{text}\n{title}: {tip}" if key in TEXT_COLUMNS else f"{title}: {tip}")
            item.setBackground(brush)
            item.setForeground(foreground)

    def on_bridge_stats(self, stats) -> None:
        self.bridge_stats = stats
        self._show_counters()

    def _invalidate(self) -> None:
        self._caches.clear()
        self._outage_finder.reset()
        self._version = -1
        self._last_plot = 0.0

    def _range_changed(self, *_args) -> None:
        """Zoomed or panned: thin the newly visible range on the next refresh."""
        self._version = -1

    # -- drawing ------------------------------------------------------------------------------

    def refresh(self) -> None:
        """Redraw what changed (cheap when nothing did)."""
        self._show_counters()
        self._show_stale()
        now = time.monotonic()
        if now - self._last_fit >= 1.0 / PLOT_HZ:
            self._last_fit = now
            if self._needs_fit():  # a counter's text wrapped to another line
                self._fit_table()
        if self._diag_time is not None and self.ctx.data_state != "lost":
            age = time.monotonic() - self._diag_time
            if age > STALE_S:
                self.diag_state.setText(f"/diagnostics: no update for {age:.0f} s (stale)")
        hist = self.ctx.session.history
        method = self.ctx.session.method
        if hist is None or (hist.version == self._version and method == self._method):
            return
        now = time.monotonic()
        if now - self._last_plot < 1.0 / PLOT_HZ:
            return
        self._last_plot = now
        self._version, self._method = hist.version, method
        self._draw(hist, method)

    def _thinned(
        self, hist, name: str, t_all: np.ndarray, lowest: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """The column ``name`` for the plot's time range, thinned to MAX_POINTS (each point
        the largest of its bucket; ``lowest``: the smallest, so a dip is never hidden)."""
        y_all = hist.column(name)
        cache = self._caches.setdefault(name, PeakDecimator())
        t, y = cache.thinned(t_all, y_all, MAX_POINTS, lowest)
        vb = self.residual_plot.getViewBox()
        if vb.autoRangeEnabled()[0] or len(t_all) == 0:
            return with_breaks(t, y, self._outages)
        x0, x1 = vb.viewRange()[0]
        lo, hi = np.searchsorted(t_all, [x0, x1])
        lo, hi = max(int(lo) - 1, 0), min(int(hi) + 1, len(t_all))
        if hi - lo <= ZOOM_ROWS:
            t, y = bucket_peak(t_all[lo:hi], y_all[lo:hi], MAX_POINTS, lowest)
            return with_breaks(t, y, self._outages)
        keep = (t >= t_all[lo]) & (t <= t_all[hi - 1])
        return with_breaks(t[keep], y[keep], self._outages)

    def _draw(self, hist, method: str) -> None:
        key = (id(hist), hist.dropped_rows)
        if key != self._hist_key:
            self._hist_key = key
            self._caches.clear()
            self._outage_finder.reset()
        t_all = hist.column("t")
        # an outage (no rows for a while) is drawn as a break, not a line across it
        self._outages = self._outage_finder.update(t_all)
        rt, ry = self._thinned(hist, "residual", t_all)
        self.residual_curve.setData(rt, ry * 1e3)
        if method == "two-sensor":
            self.residual_note.setText(
                "Residual (mm): how far the two sensors disagree with one rigid motion; "
                "large values mean slip, a lift or a wrong geometry."
            )
        else:
            self.residual_note.setText(
                f"Residual: only computed by the two-sensor method; the pose method now is "
                f"'{method}', so new samples have none (NaN, not drawn)."
            )
        n = len(self.ctx.session.devices)
        while len(self.lift_curves) < n:
            k = len(self.lift_curves)
            name = self.ctx.session.devices[k]
            pen = sensor_colour(k)
            self.lift_curves.append(self._curve(self.lift_plot, pen, name))
            keys = ", ".join(
                f'<span style="color:{sensor_colour(j)}">&#9644; '
                f'{self.ctx.session.devices[j]}</span>' for j in range(len(self.lift_curves)))
            self.lift_plot.setTitle(f"Lifted polls per reply ({keys})")
        top = 1.0
        for k, curve in enumerate(self.lift_curves[:n]):
            lt, ly = self._thinned(hist, f"s{k}_lifts", t_all)
            curve.setData(lt, ly)
            if np.isfinite(ly).any():
                top = max(top, float(np.nanmax(ly)))
        self.lift_plot.setYRange(0.0, top, padding=0.05)
        self._draw_quality(hist, t_all)

    def _draw_quality(self, hist, t_all: np.ndarray) -> None:
        """Quality curves of the sensors whose chip has a figure, each chip's threshold as a
        dashed line; the others named in :attr:`quality_note`."""
        session = self.ctx.session
        devices = session.devices
        chips = tuple(session.chip(d) for d in devices)
        if chips != self._chips:
            self._chips = chips
            self._build_quality(devices, chips)
        for k, curve in enumerate(self.quality_curves):
            if k < len(chips) and quality_label(chips[k]) and chips[k]:
                qt, qy = self._thinned(hist, f"s{k}_quality", t_all, lowest=True)
                curve.setData(qt, qy)
            else:
                curve.setData([], [])

    def _build_quality(self, devices, chips) -> None:
        while len(self.quality_curves) < len(devices):
            k = len(self.quality_curves)
            self.quality_curves.append(self._curve(self.quality_plot,
                                                   sensor_colour(k)))
        for line in self.threshold_lines.values():
            self.quality_plot.removeItem(line)
        self.threshold_lines.clear()
        with_figure, without, names = [], [], set()
        for k, (dev, chip) in enumerate(zip(devices, chips, strict=True)):
            name = quality_label(chip)
            if not chip or not name:
                without.append(f"{dev}: no quality figure (chip {chip_title(chip)})")
                continue
            pen = sensor_colour(k)
            with_figure.append(f'<span style="color:{pen}">&#9644; {dev} '
                               f'({chip_key(chip).upper()})</span>')
            names.add(name)
            limit = quality_threshold(chip)
            if limit > 0:
                line = pg.InfiniteLine(
                    pos=float(limit), angle=0, movable=False,
                    pen=pg.mkPen(pen, width=1, style=Qt.DashLine),
                    label=f"{name} threshold {limit}", labelOpts={"color": pen, "position": 0.1},
                )  # fmt: skip
                self.quality_plot.addItem(line)
                self.threshold_lines[k] = line
        self.quality_plot.setVisible(bool(with_figure))
        if with_figure:
            self.quality_plot.setTitle(
                f"Surface quality, dashed: the chip's threshold ({', '.join(with_figure)})")
            self.quality_plot.setLabel("left", " / ".join(sorted(names)))
        self.quality_note.setText(
            ("Surface quality: " + "; ".join(without)) if without else "")

    def quality_data(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """What sensor ``k``'s quality curve shows now (t in s, the figure)."""
        if k >= len(self.quality_curves):
            return np.empty(0), np.empty(0)
        x, y = self.quality_curves[k].getOriginalDataset()
        return (np.asarray(x) if x is not None else np.empty(0),
                np.asarray(y) if y is not None else np.empty(0))

    def _show_counters(self) -> None:
        s = self.ctx.session.stats
        b = self.bridge_stats
        key = (s.replies, s.used, s.restarts, s.incomplete, s.rejected, s.baselines, s.polls,
               s.gaps, s.cpi_changes, id(b))
        if key == self._stats_key:
            return
        self._stats_key = key
        self.session_label.setText(
            f"Session: {s.replies} replies received, {s.used} used for the pose; "
            f"{s.baselines} fresh starts, {s.restarts} node restarts; "
            f"{s.incomplete} missing a sensor, {s.rejected} refused; "
            f"pose from {s.polls} single polls, {s.gaps} gaps bridged, "
            f"{s.per_reply} replies without polls; {s.cpi_changes} CPI changes"
        )
        if self.ctx.bridge is None:
            self.bridge_label.setText("Bridge: offline (no ROS connection)")
        elif b is None:
            self.bridge_label.setText("Bridge: no figures yet")
        else:
            self.bridge_label.setText(
                f"Link to the node ({b.state}): {b.requests} requests, {b.replies} replies; "
                f"{b.dropped_requests} requests unanswered in time, "
                f"{b.skipped_ticks} requests not sent (the previous one was still "
                f"unanswered), {b.failed_replies} replies with an error"
            )

    def residual_data(self) -> tuple[np.ndarray, np.ndarray]:
        """What the residual curve shows now (t in s, residual in m; drawn in mm)."""
        x, y = self.residual_curve.getOriginalDataset()
        return (np.asarray(x) if x is not None else np.empty(0),
                np.asarray(y) / 1e3 if y is not None else np.empty(0))


def _level(value) -> int:
    """A diagnostics level as int (it may arrive as int, bytes or text)."""
    if isinstance(value, bytes):
        return int.from_bytes(value, "little")
    try:
        return int(value)
    except (TypeError, ValueError):
        return 3
