"""Detail debugging: pause the polling and ask for one sample by hand (issue item 7).

* "Pause polling" stops the bridge's periodic data requests
  (``RosBridge.set_polling``); "Request sample" sends one request
  (``RosBridge.request_once``). Its reply goes through ``ctx.on_replies`` like
  every reply (the main window connects ``bridge.data_received`` to it), so
  no counts are lost and the map moves; this view only *also* listens to
  ``bridge.data_received`` to recognise the reply to the manual request: the
  newest reply of the next delivery after pressing the button (exact while
  polling is paused).
* The table lists those manual replies: time, and per sensor the counts of
  the interval (``x_counts``/``y_counts``, sensor frame: X right, Y forward),
  the same in mm (at the CPI in force), polls covered and the interval.
* The upper plot shows dX/dY counts per manual request; "Fetch 1 kHz polls"
  asks a sensor's single polls (``get_samples``, continuing after the polls
  fetched before) and draws them in the lower plot -- the seed's "store single
  steps instead of sums".
"""

from __future__ import annotations

import time
from contextlib import suppress
from dataclasses import dataclass

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from mm_pc.core.frames import counts_to_m
from mm_pc.core.polls import FLAG_LIFT, FLAG_LOW_QUALITY
from mm_pc.core.sensor_data import Reply
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.widgets.style import ERROR_STYLE, sensor_axis_colour

__all__ = ["MAX_POLLS_PER_FETCH", "DebugView", "ManualSample"]

MAX_POLLS_PER_FETCH = 2000
SENSOR_FIELDS = ("dX (counts)", "dY (counts)", "dX (mm)", "dY (mm)", "polls", "interval (ms)")


def _pen(k: int, axis: str) -> str:
    """Sensor ``k``'s colour (as on every other tab) for its "dX" or "dY" curve."""
    return sensor_axis_colour(k, "x" if axis == "dX" else "y")


@dataclass(frozen=True)
class ManualSample:
    """One manual reply: wall time, and per sensor (x_counts, y_counts, x_m, y_m, polls, s)."""

    wall_time: float
    sensors: dict[str, tuple[int, int, float, float, int, float]]


class DebugView(QWidget):
    """Pause polling, request single samples, fetch the 1 kHz polls."""

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        pg.setConfigOptions(antialias=False)
        self.samples: list[ManualSample] = []
        self.devices: tuple[str, ...] = ()
        self.next_seq: dict[str, int] = {}
        self.polls: dict[str, object] = {}  # device -> newest GetSamples.Response
        self._awaiting = False
        self._drawn = 0
        bridge = ctx.bridge

        self.pause_button = QPushButton("Pause polling")
        self.pause_button.setCheckable(True)
        self.pause_button.toggled.connect(self.set_paused)
        self.request_button = QPushButton("Request sample")
        self.request_button.setToolTip(
            "one get_sensor_data request now; pause polling first so the next reply is yours"
        )
        self.request_button.clicked.connect(self.request_sample)
        self.clear_button = QPushButton("Clear table")
        self.clear_button.clicked.connect(self.clear)
        for b in (self.pause_button, self.request_button):
            b.setEnabled(bridge is not None)
        self.state = QLabel("offline: no ROS connection" if bridge is None else "")
        self.state.setWordWrap(True)
        self.pause_button.setToolTip("stop the periodic requests, so every reply answers a "
                                     "Request sample")
        self.clear_button.setToolTip("empty the table and the upper plot")
        self.error = QLabel("")
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setWordWrap(True)
        self.error.hide()
        self.fetch_row = QHBoxLayout()
        self.fetch_buttons: dict[str, QPushButton] = {}
        self.polls_label = QLabel("")
        self.polls_label.setWordWrap(True)  # a long summary must not widen the window

        self.table = QTableWidget(0, 1)
        self.table.setEditTriggers(QTableWidget.NoEditTriggers)
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)

        self.plots = pg.GraphicsLayoutWidget()
        self.plots.setBackground("w")
        # each legend in its own row above its plot: inside the plot it covered the data
        self.request_legend = self._legend_row(0)
        self.request_plot = self.plots.addPlot(row=1, col=0, title="Manual requests")
        self.request_plot.setLabel("left", "counts")
        self.request_plot.setLabel("bottom", "request #")
        self.poll_legend = self._legend_row(2)
        self.poll_plot = self.plots.addPlot(row=3, col=0, title="Single 1 kHz polls")
        self.poll_plot.setLabel("left", "counts per poll")
        self.poll_plot.setLabel("bottom", "time since first poll", units="s")
        self.request_curves: dict[tuple[str, str], pg.PlotDataItem] = {}
        self.poll_curves: dict[tuple[str, str], pg.PlotDataItem] = {}

        controls = QHBoxLayout()
        for w in (self.pause_button, self.request_button, self.clear_button):
            controls.addWidget(w)
        controls.addWidget(self.state, 1)
        top = QWidget()
        tl = QVBoxLayout(top)
        tl.setContentsMargins(0, 0, 0, 0)
        tl.addLayout(controls)
        tl.addLayout(self.fetch_row)
        tl.addWidget(self.polls_label)
        tl.addWidget(self.error)
        tl.addWidget(self.table)
        split = QSplitter(Qt.Vertical)
        split.addWidget(top)
        split.addWidget(self.plots)
        split.setStretchFactor(1, 2)
        QVBoxLayout(self).addWidget(split)

        if bridge is not None:
            self.pause_button.setChecked(not bridge.polling)
            # data_received / data_failed only while a manual request waits (_listen): a
            # slot per reply at 500 Hz is CPU the window spends for nothing
            bridge.samples_received.connect(self.on_samples)
            bridge.samples_failed.connect(self._on_samples_failed)
        ctx.devices_known.connect(self._set_devices)
        if ctx.session.devices:
            self._set_devices(ctx.session.devices)

    # -- devices ----------------------------------------------------------------------------

    def _set_devices(self, devices) -> None:
        devices = tuple(devices)
        if devices == self.devices:
            return
        self.devices = devices
        while self.fetch_row.count():
            w = self.fetch_row.takeAt(0).widget()
            if w is not None:
                w.deleteLater()
        self.fetch_buttons.clear()
        for dev in devices:
            b = QPushButton(f"Fetch 1 kHz polls: {dev.rsplit('/', 1)[-1]}")
            b.setToolTip(f"get_samples for {dev}: its single 1 kHz polls, up to "
                         f"{MAX_POLLS_PER_FETCH} after the last fetched")
            b.setEnabled(self.ctx.bridge is not None)
            b.clicked.connect(lambda _c=False, d=dev: self.fetch_polls(d))
            self.fetch_row.addWidget(b)
            self.fetch_buttons[dev] = b
        self.fetch_row.addStretch(1)
        headers = ["time"]
        for dev in devices:
            short = dev.rsplit("/", 1)[-1]
            headers += [f"{short} {f}" for f in SENSOR_FIELDS]
        self.table.setColumnCount(len(headers))
        self.table.setHorizontalHeaderLabels(headers)

    # -- user actions -------------------------------------------------------------------------

    def set_paused(self, paused: bool) -> None:
        """Pause (True) or resume the bridge's periodic requests."""
        self.pause_button.setText("Resume polling" if paused else "Pause polling")
        if self.ctx.bridge is None:
            return
        self.ctx.bridge.set_polling(not paused)
        self.state.setText("polling paused: every reply now answers a manual request"
                           if paused else "polling")

    def request_sample(self) -> None:
        """One data request; its reply (the next one) becomes a table row."""
        if self.ctx.bridge is None:
            return
        self._listen(True)
        self.error.hide()
        self.ctx.bridge.request_once()
        self.state.setText("request sent, waiting for the reply…")

    def fetch_polls(self, device: str) -> None:
        """Ask the node for the single polls of ``device`` after those fetched before."""
        if self.ctx.bridge is None:
            return
        self.ctx.bridge.request_samples(
            device, since_seq=self.next_seq.get(device, 0), max_samples=MAX_POLLS_PER_FETCH
        )
        self.polls_label.setText(f"fetching the polls of {device}…")

    def clear(self) -> None:
        self.samples.clear()
        self.table.setRowCount(0)
        self._drawn = -1

    # -- bridge signals -------------------------------------------------------------------------

    def _listen(self, on: bool) -> None:
        """Wait for (True) or stop waiting for (False) the reply to a manual request."""
        bridge = self.ctx.bridge
        if bridge is None or on == self._awaiting:
            return
        self._awaiting = on
        for signal, slot in (
            (bridge.data_received, self._on_data),
            (bridge.data_failed, self._on_data_failed),
        ):
            if on:
                signal.connect(slot)
            else:
                with suppress(RuntimeError, TypeError):
                    signal.disconnect(slot)

    def _on_data(self, replies: list[Reply]) -> None:
        """The first delivery after the manual request: its newest reply is the answer."""
        if not self._awaiting:
            return
        self._listen(False)
        self.add_manual_reply(replies[-1])

    def _on_data_failed(self, message: str) -> None:
        if self._awaiting:
            self._listen(False)
            self.error.setText(f"manual request failed: {message}")
            self.error.show()

    def add_manual_reply(self, reply: Reply) -> ManualSample:
        """Put one manual reply into the table and the plot."""
        if not self.devices:
            self._set_devices(tuple(r.id for r in reply.readings))
        sensors = {}
        for r in reply.readings:
            xm = float(counts_to_m(r.x_counts, r.cpi)) if r.cpi else float("nan")
            ym = float(counts_to_m(r.y_counts, r.cpi)) if r.cpi else float("nan")
            sensors[r.id] = (r.x_counts, r.y_counts, xm, ym, r.samples, r.interval)
        sample = ManualSample(time.time(), sensors)
        self.samples.append(sample)
        self._add_row(sample)
        self.state.setText(f"{len(self.samples)} manual sample(s)")
        return sample

    def _add_row(self, sample: ManualSample) -> None:
        row = self.table.rowCount()
        self.table.insertRow(row)
        stamp = time.strftime("%H:%M:%S", time.localtime(sample.wall_time))
        cells = [f"{stamp}.{int(sample.wall_time * 1000) % 1000:03d}"]
        for dev in self.devices:
            v = sample.sensors.get(dev)
            if v is None:
                cells += ["–"] * len(SENSOR_FIELDS)
                continue
            xc, yc, xm, ym, n, dt = v
            cells += [str(xc), str(yc), f"{xm * 1e3:.3f}", f"{ym * 1e3:.3f}", str(n),
                      f"{dt * 1e3:.1f}"]
        for c, text in enumerate(cells):
            item = QTableWidgetItem(text)
            if c:
                item.setTextAlignment(Qt.AlignRight | Qt.AlignVCenter)
            self.table.setItem(row, c, item)
        self.table.scrollToBottom()

    def on_samples(self, device: str, res) -> None:
        """A ``GetSamples.Response``: remember where to go on, draw the polls."""
        self.next_seq[device] = int(res.next_seq)
        self.polls[device] = res
        n = len(res.dx)
        flags = np.asarray(res.flags, dtype=np.int64)
        lifts = int(np.count_nonzero(flags & FLAG_LIFT)) if n else 0
        poor = int(np.count_nonzero(flags & FLAG_LOW_QUALITY)) if n else 0
        self.polls_label.setText(
            f"{device}: {n} polls (seq {res.first_seq}..{int(res.next_seq) - 1}), "
            f"{res.dropped} older polls no longer kept by the node (it keeps its newest "
            f"ring_size polls, 65 s at the default), {lifts} lifted, "
            f"{poor} below the chip's quality threshold (treated as lifted), CPI {res.cpi}; "
            f"sums dX {int(np.sum(res.dx))}, dY {int(np.sum(res.dy))} counts"
        )
        self._draw_polls()

    def _on_samples_failed(self, device: str, message: str) -> None:
        self.error.setText(f"polls of {device} not fetched: {message}")
        self.error.show()
        self.polls_label.setText("")

    # -- drawing ------------------------------------------------------------------------------

    def _legend_row(self, row: int) -> pg.LegendItem:
        """A legend laid out in ``row`` of the plots (one line, as many columns as curves)."""
        legend = pg.LegendItem(colCount=4, labelTextColor="#222222")
        self.plots.addItem(legend, row=row, col=0)
        return legend

    def _curve(self, plot, curves, key, pen) -> pg.PlotDataItem:
        curve = curves.get(key)
        if curve is None:
            short = key[0].rsplit("/", 1)[-1]
            curve = plot.plot(pen=pg.mkPen(pen, width=1), symbol="o", symbolSize=5,
                              symbolBrush=pen, symbolPen=None)
            self.request_legend.addItem(curve, f"{short} {key[1]}")
            curves[key] = curve
        return curve

    def _draw_polls(self) -> None:
        stamps = [int(r.stamp_ns[0]) for r in self.polls.values() if len(r.stamp_ns)]
        if not stamps:
            return
        t0 = min(stamps)
        for k, (dev, res) in enumerate(self.polls.items()):
            t = (np.asarray(res.stamp_ns, dtype=np.int64) - t0) / 1e9
            for axis, values in (("dX", res.dx), ("dY", res.dy)):
                curve = self.poll_curves.get((dev, axis))
                if curve is None:
                    short = dev.rsplit("/", 1)[-1]
                    curve = self.poll_plot.plot(pen=pg.mkPen(_pen(k, axis), width=1),
                                                stepMode="right")
                    self.poll_legend.addItem(curve, f"{short} {axis}")
                    self.poll_curves[(dev, axis)] = curve
                curve.setData(t, np.asarray(values, dtype=float))

    def refresh(self) -> None:
        """Redraw the request plot when manual samples were added (cheap otherwise)."""
        bridge = self.ctx.bridge
        if bridge is not None and self.pause_button.isChecked() == bridge.polling:
            # paused or resumed elsewhere (the control dock): show it
            self.pause_button.blockSignals(True)
            self.pause_button.setChecked(not bridge.polling)
            self.pause_button.setText("Resume polling" if not bridge.polling else "Pause polling")
            self.pause_button.blockSignals(False)
        if self._drawn == len(self.samples):
            return
        self._drawn = len(self.samples)
        x = np.arange(1, len(self.samples) + 1)
        for k, dev in enumerate(self.devices):
            for i, axis in enumerate(("dX", "dY")):
                y = [s.sensors.get(dev, (0, 0))[i] for s in self.samples]
                self._curve(self.request_plot, self.request_curves, (dev, axis), _pen(k, axis)) \
                    .setData(x, np.asarray(y, dtype=float))

    def request_data(self, device: str, axis: str) -> tuple[np.ndarray, np.ndarray]:
        """What the request plot shows for a sensor and axis ('dX' or 'dY')."""
        curve = self.request_curves.get((device, axis))
        if curve is None:
            return np.empty(0), np.empty(0)
        x, y = curve.getOriginalDataset()
        return np.asarray(x), np.asarray(y)
