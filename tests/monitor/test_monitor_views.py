"""Graphs, data list, registers, resolution panel and log dialog of mm-monitor.

Data comes from the ground-truth simulator (sim_replies -> ctx.on_reply);
the register and resolution tests marked ``ros`` talk to one real mm-beagle
(emulated sensors) through a real RosBridge, started once for the module.
"""

from __future__ import annotations

import re
import time
from types import SimpleNamespace

import numpy as np
import pytest
from fakes import wait_until
from PySide6.QtCore import QItemSelectionModel, Qt
from PySide6.QtGui import QGuiApplication, QImage

from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.csv_export import COLUMNS
from mm_pc.monitor.model.peak_decimator import bucket_size
from mm_pc.monitor.model.session import MonitorSession, sensor_columns
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES
from mm_pc.monitor.widgets.data_list import DataListView, HistoryTableModel
from mm_pc.monitor.widgets.graphs_view import GraphsView
from mm_pc.monitor.widgets.log_dialog import HEADER, LogDialog, format_entry
from mm_pc.monitor.widgets.registers_view import FIELDS, RegistersView, decode_status, status_bits
from mm_pc.monitor.widgets.resolution_panel import ResolutionPanel, validate_cpi


@pytest.fixture
def make_ctx(feed):
    """``make_ctx(seconds=30, rate_hz=100, name="figure_eight", bridge=None)``: a context
    that has taken in that much of a simulated run."""

    def make(seconds: float = 30.0, rate_hz: float = 100.0, name="figure_eight", bridge=None):
        ctx = MonitorContext(MonitorSession(), bridge=bridge)
        feed(ctx, name=name, rate_hz=rate_hz, seconds=seconds)
        return ctx

    return make


def more_replies(ctx, count: int) -> None:
    """``count`` further replies (10 ms apart) continuing the session's last totals."""
    prev = {d: ctx.session._prev[d] for d in ctx.session.devices}
    for i in range(1, count + 1):
        readings = []
        for k, dev in enumerate(ctx.session.devices):
            p = prev[dev]
            readings.append(
                Reading(
                    id=dev, stamp_ns=p.stamp_ns + i * 10_000_000, seq=p.seq + 10 * i,
                    x_total=p.x_total + 1e-4 * i * (k + 1), y_total=p.y_total + 2e-3 * i,
                    cpi=p.cpi, samples=10,
                )
            )
        ctx.on_reply(Reply(tuple(readings)))


def distinct_colours(img: QImage, step: int = 7) -> int:
    colours = set()
    for y in range(0, img.height(), step):
        for x in range(0, img.width(), step):
            colours.add(img.pixel(x, y))
    return len(colours)


# -- graphs ------------------------------------------------------------------------------


def test_graph_curves_equal_the_history_window_in_mm(qtbot, make_ctx):
    ctx = make_ctx(30.0)
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    hist = ctx.session.history
    t = hist.column("t")
    inside = t >= t[-1] - 10.0
    assert view.window_s == 10 and 990 <= inside.sum() <= 1010
    for k in range(2):
        cols = sensor_columns(k)
        for key, fields in (("disp", ("dx", "dy")), ("speed", ("vx", "vy"))):
            for axis, field in zip("xy", fields, strict=True):
                x, y = view.curves[(k, key, axis)].getOriginalDataset()
                np.testing.assert_array_equal(x, t[inside])
                np.testing.assert_array_equal(y, hist.column(cols[field])[inside] * 1e3)
    # the straight parts of a figure eight at 0.2 m/s, 100 Hz: about 2 mm per reply
    _x, y = view.curves[(0, "disp", "y")].getOriginalDataset()
    assert 1.0 < np.median(np.abs(y)) < 3.0
    lo, hi = view.plots[(0, "disp")].viewRange()[0]
    assert (lo, hi) == pytest.approx((t[-1] - 10.0, t[-1] + 1.0))  # X_LEAD of the window ahead


def test_graphs_show_speed_first_with_units_and_the_legend_outside(qtbot, make_ctx):
    ctx = make_ctx(3.0)
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    for k in range(2):
        speed, disp = view.plots[(k, "speed")], view.plots[(k, "disp")]
        # speed is the top row of each sensor's column; the per-reply displacement is
        # second and says that it depends on the request interval
        assert view.canvas.ci.getItem(0, k) is speed and view.canvas.ci.getItem(1, k) is disp
        assert "request interval" in disp.titleLabel.text
        assert speed.getAxis("left").labelText == "speed (mm/s)"
        assert disp.getAxis("left").labelText == "displacement per reply (mm)"
        assert speed.legend is None and disp.legend is None  # nothing drawn over the curves
    assert "X (sensor right)" in view.legend.text() and "Y (sensor forward)" in view.legend.text()
    assert not view.legend.isHidden()


def test_graph_axes_move_only_when_the_data_reach_their_ends(qtbot, make_ctx):
    ctx = make_ctx(30.0)
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    plot = view.plots[(1, "speed")]
    x_ranges, y_ranges = [], []
    for _ in range(25):  # 2.5 s, 0.1 s a frame
        more_replies(ctx, 10)
        view.refresh()
        t = ctx.session.history.column("t")
        (x0, x1), (y0, y1) = plot.viewRange()
        x_ranges.append((x0, x1))
        y_ranges.append((y0, y1))
        assert x1 - 1.0 - 1e-9 <= t[-1] <= x1  # the newest row in the lead at the end
        assert x0 == pytest.approx(x1 - 11.0)
        for axis in "xy":
            cx, cy = view.curves[(1, "speed", axis)].getOriginalDataset()
            assert cx[0] >= x0 and cx[-1] == t[-1]
            i0 = int(np.searchsorted(t, x0))
            np.testing.assert_array_equal(cx, t[i0:])  # every row from the range's start
            assert y0 < cy.min() and cy.max() < y1  # the values in range, with room
    # the time axis moved once a second (when the data reached its end), not every frame
    assert 2 <= len(set(x_ranges)) <= 3
    assert len(set(y_ranges)) <= 3


def test_graph_window_length_is_respected(qtbot, make_ctx):
    ctx = make_ctx(30.0)
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    t = ctx.session.history.column("t")
    for seconds in (1, 5, 3600):
        view.window_box.setValue(seconds)
        view.refresh()
        x, _y = view.curves[(1, "speed", "x")].getOriginalDataset()
        np.testing.assert_array_equal(x, t[t >= t[-1] - seconds])
        assert x[-1] - x[0] <= seconds
    assert len(x) == len(t)  # an hour's window holds all 30 s
    view.window_box.setValue(0)  # below the range: the spin box keeps 1 s
    assert view.window_s == 1


def test_graph_refresh_skips_when_nothing_changed_and_pause_freezes(qtbot, make_ctx):
    ctx = make_ctx(5.0)
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    curve = view.curves[(0, "disp", "x")]
    curve.setData([0.0], [0.0])  # marker: only a redraw would replace it
    view.refresh()
    assert len(curve.getOriginalDataset()[0]) == 1

    view.set_paused(True)
    assert view.pause_button.text() == "Resume"
    assert view.plots[(0, "disp")].vb.state["mouseEnabled"] == [True, True]
    more_replies(ctx, 50)
    view.refresh()
    assert len(curve.getOriginalDataset()[0]) == 1  # paused: nothing redrawn

    view.set_paused(False)  # resume jumps back to live
    t = ctx.session.history.column("t")
    x, _y = curve.getOriginalDataset()
    assert x[-1] == t[-1] and len(x) == int((t >= t[-1] - 10).sum())
    assert view.plots[(0, "disp")].vb.state["mouseEnabled"] == [False, False]


def hour_of_history(ctx, seed=1):
    """Append an hour of 100 Hz rows (random sensor values) to the context's history."""
    hist = ctx.session.history
    rng = np.random.default_rng(seed)
    rows = rng.normal(0.0, 1e-3, (360_000, len(hist.columns)))
    t_last = hist.last("t")
    rows[:, hist.index["t"]] = t_last + (1 + np.arange(360_000)) / 100.0
    hist.extend(rows)
    return hist


def append_rows(hist, count, seed=2):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        row = rng.normal(0.0, 1e-3, len(hist.columns))
        row[hist.index["t"]] = hist.last("t") + 0.01
        hist.append(row)


def reference_peaks(t, y, i0, size):
    """What a min/max-bucket curve must hold: buckets aligned to row numbers, edges as they are."""
    b0, b1 = -(-i0 // size), len(t) // size
    blocks = y[b0 * size : b1 * size].reshape(-1, size)
    mid = np.column_stack((blocks.min(axis=1), blocks.max(axis=1))).ravel()
    ys = np.concatenate((y[i0 : b0 * size], mid, y[b1 * size :]))
    ts = np.concatenate((t[i0 : b0 * size], np.repeat(t[b0 * size : b1 * size : size], 2),
                         t[b1 * size :]))
    return ts, ys


def test_graph_cost_does_not_grow_with_history_or_window(qtbot, make_ctx):
    ctx = make_ctx(1.0)
    hist = hour_of_history(ctx)
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    view.resize(1000, 600)
    view.show()
    t = hist.column("t")
    for seconds in (10, 3600):
        view.window_box.setValue(seconds)
        times = []
        for _ in range(20):
            append_rows(hist, 1)
            t0 = time.perf_counter()
            view.refresh()
            times.append(time.perf_counter() - t0)
        t = hist.column("t")
        x, y = view.curves[(1, "speed", "y")].getOriginalDataset()
        i0 = int(np.searchsorted(t, view.plots[(1, "speed")].viewRange()[0][0]))
        if seconds == 10:  # every row of the shown range (window and lead), nothing else
            assert len(x) == len(t) - i0 <= 1101
            np.testing.assert_array_equal(y, hist.column("s1_vy")[i0:] * 1e3)
        else:  # 360 000 rows drawn as min/max of 256-row buckets, built up frame by frame
            assert bucket_size(len(t) - i0) == 256 and len(x) <= 2 * 1407 + 2 * 256
            rx, ry = reference_peaks(t, hist.column("s1_vy") * 1e3, i0, 256)
            np.testing.assert_array_equal(x, rx)
            np.testing.assert_array_equal(y, ry)
            assert y.max() == hist.column("s1_vy")[i0:].max() * 1e3  # peaks survive
        assert np.percentile(times, 95) < 0.03, (seconds, np.percentile(times, 95))


@pytest.mark.screenshot
def test_graphs_screenshot(qtbot, screenshot, make_ctx):
    ctx = make_ctx(30.0)
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    view.resize(1100, 650)
    view.show()
    view.refresh()
    img = screenshot(view, "graphs.png")
    assert distinct_colours(img) > 20


def test_graphs_built_when_devices_come_late_and_cleared_on_reset(qtbot, feed):
    ctx = MonitorContext(MonitorSession())
    view = GraphsView(ctx)
    qtbot.addWidget(view)
    view.refresh()  # no history yet: nothing to do
    assert view.curves == {}
    feed(ctx, seconds=2.0)
    assert len(view.curves) == 8
    view.refresh()
    ctx.reset()
    assert len(view.curves[(0, "disp", "x")].getOriginalDataset()[0] or []) == 0


# -- data list ---------------------------------------------------------------------------


def test_data_list_rows_newest_first_equal_the_history(qtbot, make_ctx):
    ctx = make_ctx(10.0)
    view = DataListView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    hist = ctx.session.history
    model = view.tables[0].model
    n = len(hist)
    assert model.rowCount() == n == 1000
    assert [model.headerData(c, Qt.Horizontal) for c in range(11)] == [c[0] for c in COLUMNS]
    for r in (0, 1, 500, n - 1):
        for c, (_h, field, scale, fmt) in enumerate(COLUMNS):
            name = field if field == "t" else sensor_columns(0)[field]
            want = hist.column(name)[n - 1 - r] * scale
            if np.isnan(want):  # the quality of a chip without a figure
                assert np.isnan(model.value(r, c))
                assert model.data(model.index(r, c)) == "\u2013"
                continue
            assert model.value(r, c) == want
            assert model.data(model.index(r, c)) == fmt.format(want)
    assert model.value(0, 0) == hist.last("t")  # newest first
    assert view.tables[1].model.rowCount() == 0  # the hidden tab catches up when shown
    view.tabs.setCurrentIndex(1)
    assert view.tables[1].model.value(0, 1) == hist.last("s1_dx") * 1e3


def test_data_list_appends_as_inserted_rows_and_keeps_the_selection(qtbot, make_ctx):
    ctx = make_ctx(5.0)
    view = DataListView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    table = view.tables[0]
    model = table.model
    sel = table.table.selectionModel()
    for r in (3, 4):
        sel.select(model.index(r, 0), QItemSelectionModel.Select | QItemSelectionModel.Rows)
    picked = [model.value(r, 0) for r in (3, 4)]
    more_replies(ctx, 7)
    with qtbot.waitSignal(model.rowsInserted, timeout=1000) as blocker:
        view.refresh()
    assert blocker.args[1:] == [0, 6]  # seven rows at the top
    assert table.selected_rows() == [10, 11]
    assert [model.value(r, 0) for r in (10, 11)] == picked
    ctx.reset()
    assert model.rowCount() == 0


def test_data_list_caps_rows_and_drops_the_oldest(qtbot, make_ctx):
    ctx = make_ctx(2.0)
    model = HistoryTableModel(ctx.session, 0, max_rows=50)
    model.sync()
    assert model.rowCount() == 50
    more_replies(ctx, 20)
    model.sync()
    hist = ctx.session.history
    assert model.rowCount() == 50
    assert model.value(0, 0) == hist.last("t")
    assert model.value(49, 0) == hist.column("t")[len(hist) - 50]


def test_data_list_ctrl_c_copies_the_selected_rows(qtbot, make_ctx):
    ctx = make_ctx(3.0)
    view = DataListView(ctx)
    qtbot.addWidget(view)
    view.show()
    view.refresh()
    table = view.tables[0]
    model = table.model
    sel = table.table.selectionModel()
    for r in (0, 2):
        sel.select(model.index(r, 0), QItemSelectionModel.Select | QItemSelectionModel.Rows)
    QGuiApplication.clipboard().clear()
    table.table.setFocus()
    qtbot.keyClick(table.table, Qt.Key_C, Qt.ControlModifier)
    lines = QGuiApplication.clipboard().text().splitlines()
    assert lines[0].split("\t") == [c[0] for c in COLUMNS]
    assert len(lines) == 3
    for line, r in zip(lines[1:], (0, 2), strict=True):
        cells = line.split("\t")
        assert cells == [model.text(r, c) for c in range(len(COLUMNS))]
        assert float(cells[0]) == pytest.approx(model.value(r, 0), abs=5e-4)


def test_export_shows_write_errors_beside_the_button(qtbot, tmp_path, make_ctx):
    ctx = make_ctx(1.0)
    view = DataListView(ctx)
    qtbot.addWidget(view)
    table = view.tables[0]
    assert not table.export_to(tmp_path / "missing_dir" / "x.csv")
    assert table.message.text().startswith("export failed:")
    assert "No such file or directory" in table.message.text()
    assert "b00020" in table.message.styleSheet()
    assert table.export_to(tmp_path / "ok.csv")
    n = len(ctx.session.history)
    assert table.message.text() == f"{n} rows written to {tmp_path / 'ok.csv'}"


@pytest.mark.screenshot
def test_data_list_screenshot(qtbot, screenshot, make_ctx):
    ctx = make_ctx(10.0)
    view = DataListView(ctx)
    qtbot.addWidget(view)
    view.resize(1000, 550)
    view.show()
    view.refresh()
    view.tables[0].table.selectRow(2)
    img = screenshot(view, "data.png")
    assert distinct_colours(img, 3) > 10


# -- registers and resolution, offline ---------------------------------------------------


def fake_settings(device: str, status: int) -> SimpleNamespace:
    regs = {name: 0x1000 + i for i, name in enumerate(FIELDS)}
    regs["status_register"] = status
    return SimpleNamespace(
        spi_device=device, cpi=1600, x_cpi=1600, y_cpi=1600,
        lifted=bool(status & 0x10), motion=bool(status & 0x80), **regs,
    )


def test_status_decoding():
    assert status_bits(0x0090) == "0000 0000 1001 0000"
    assert decode_status(0x0090) == ["motion", "lift"]
    assert decode_status(0x000C) == ["overflow X", "overflow Y"]
    assert decode_status(0) == []


def test_registers_view_fills_from_the_bridge_signals(qtbot, fake_bridge):
    bridge = fake_bridge
    ctx = MonitorContext(MonitorSession(devices=DEFAULT_DEVICES), bridge=bridge)
    view = RegistersView(ctx)
    qtbot.addWidget(view)
    assert view.request_registers() == 2
    assert bridge.calls == [("settings", d) for d in DEFAULT_DEVICES]
    bridge.settings_received.emit(DEFAULT_DEVICES[1], fake_settings(DEFAULT_DEVICES[1], 0x0090))
    assert view.table.item(0, 1).text() == "0x0090"
    assert view.table.item(12, 1).text() == "0x100C"
    assert view.table.item(0, 0) is None  # the other sensor not read yet
    text = view.status_labels[DEFAULT_DEVICES[1]].text()
    assert "lifted: yes    motion: yes" in text
    assert "bits 15..0: 0000 0000 1001 0000" in text and "bits set: motion, lift" in text
    assert "cpi 1600  (x_cpi 1600, y_cpi 1600)" in text
    bridge.settings_failed.emit(DEFAULT_DEVICES[0], "sensor down: no answer")
    assert view.error.text() == f"{DEFAULT_DEVICES[0]}: sensor down: no answer"


def test_resolution_panel_follows_the_cpi_without_a_slot_per_reply(qtbot, make_ctx):
    """The CPI in force shows within a few refreshes of the panel's own timer; the panel
    does not listen to every reply (at 500 Hz that was 500 queued calls a second)."""
    from PySide6.QtCore import SIGNAL

    ctx = make_ctx(1.0)
    panel = ResolutionPanel(ctx)
    qtbot.addWidget(panel)
    assert ctx.receivers(SIGNAL("reply_processed(PyObject)")) == 0
    row = panel.rows[DEFAULT_DEVICES[0]]
    assert row.current.text() == "now: 1600 CPI"
    from dataclasses import replace

    readings = [
        replace(p, stamp_ns=p.stamp_ns + 10_000_000, seq=p.seq + 10, cpi=800)
        for p in (ctx.session._prev[d] for d in ctx.session.devices)
    ]
    ctx.on_reply(Reply(tuple(readings), received_s=time.monotonic()))
    qtbot.waitUntil(lambda: row.current.text() == "now: 800 CPI", timeout=2000)


def test_registers_and_resolution_disabled_offline(qtbot, make_ctx):
    ctx = make_ctx(1.0)
    view = RegistersView(ctx)
    panel = ResolutionPanel(ctx)
    qtbot.addWidget(view)
    qtbot.addWidget(panel)
    assert not view.refresh_button.isEnabled()
    assert view.request_registers() == 0
    assert "offline" in view.note.text()
    assert panel.title() == "Resolution (CPI)"
    assert "offline" in panel.note.text()
    row = panel.rows[DEFAULT_DEVICES[0]]
    assert not row.set_button.isEnabled() and not row.edit.isEnabled()
    assert row.current.text() == "now: 1600 CPI"
    row.edit.setText("800")
    assert not panel.apply(DEFAULT_DEVICES[0])
    assert row.error.text() == "offline: no node to set the resolution on"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("junk", r"whole number, got 'junk' \(Philips PLN2033 allows 100\.\.6400 in steps of 100"),
        ("", r"the CPI field is empty: type a whole number \(Philips PLN2033 allows"),
        ("0", r"CPI 0 is out of range \(Philips PLN2033 allows 100\.\.6400"),
        ("50", r"CPI 50 is out of range"),
        ("6500", r"CPI 6500 is out of range"),
        ("1234", r"CPI 1234 is not supported by the sensor's encoding \(Philips PLN2033 allows"),
        ("1e3", r"CPI must be a whole number, got '1e3'"),
    ],
)
def test_resolution_refuses_bad_input_without_asking_the_node(
    qtbot, text, message, feed, fake_bridge
):
    bridge = fake_bridge
    ctx = MonitorContext(MonitorSession(), bridge=bridge)
    panel = ResolutionPanel(ctx)
    qtbot.addWidget(panel)
    feed(ctx, seconds=1.0)
    row = panel.rows[DEFAULT_DEVICES[1]]
    row.edit.setText(text)
    qtbot.mouseClick(row.set_button, Qt.LeftButton)
    assert bridge.calls == []
    assert re.search(message, row.error.text()), row.error.text()
    with pytest.raises(ValueError, match=message):
        validate_cpi(text)


def test_resolution_shows_the_answer_of_the_node(qtbot, fake_bridge):
    bridge = fake_bridge
    ctx = MonitorContext(MonitorSession(devices=DEFAULT_DEVICES), bridge=bridge)
    panel = ResolutionPanel(ctx)
    qtbot.addWidget(panel)
    dev = DEFAULT_DEVICES[0]
    row = panel.rows[dev]
    row.edit.setText(" 3200 ")
    qtbot.keyClick(row.edit, Qt.Key_Return)
    assert bridge.calls == [("resolution", dev, 3200)]
    assert validate_cpi(100) == 100 and validate_cpi("6400") == 6400
    bridge.resolution_done.emit(dev, True, f"{dev} set to 3200 CPI", 3200)
    assert row.read_back.text() == "read back: 3200 CPI" and row.error.text() == ""
    bridge.resolution_done.emit(dev, False, "SPI error", 0)
    assert row.error.text() == "SPI error" and row.read_back.text() == ""


# -- log dialog --------------------------------------------------------------------------


def test_log_dialog_shows_the_entries_newest_at_the_bottom(qtbot, make_ctx):
    ctx = make_ctx(2.0)
    dlg = LogDialog(ctx)
    qtbot.addWidget(dlg)
    assert not dlg.isModal()
    log = list(ctx.session.log)
    assert len(log) == 400  # 200 replies x 2 sensors
    assert dlg.lines() == [format_entry(e) for e in log]
    newest = log[-1]
    cells = dlg.lines()[-1].split()
    assert float(cells[0]) == pytest.approx(newest.t, abs=5e-4)
    assert cells[1] == newest.sensor and int(cells[2]) == newest.x_counts
    assert float(cells[4]) == pytest.approx(newest.raw_dx * 1e3, abs=5e-5)
    assert float(cells[7]) == pytest.approx(newest.dy * 1e3, abs=5e-5)
    assert int(cells[10]) == newest.cpi == 1600 and int(cells[11]) == newest.samples == 10

    dlg.pause_box.setChecked(True)
    more_replies(ctx, 5)
    assert dlg.poll() == 0 and len(dlg.lines()) == 400
    dlg.pause_box.setChecked(False)  # resuming adds what came meanwhile
    assert len(dlg.lines()) == 410
    assert dlg.lines()[-1] == format_entry(ctx.session.log[-1])

    text = dlg.copy_all()
    assert text.startswith(HEADER + "\n") and QGuiApplication.clipboard().text() == text
    dlg.clear()
    assert dlg.lines() == []
    more_replies(ctx, 3)
    assert dlg.poll() == 6
    assert dlg.lines() == [format_entry(e) for e in list(ctx.session.log)[-6:]]
    ctx.reset()
    assert dlg.lines() == []


def test_log_dialog_updates_on_its_timer_not_per_reply(qtbot, make_ctx):
    ctx = make_ctx(1.0)
    dlg = LogDialog(ctx)
    qtbot.addWidget(dlg)
    dlg.show()
    assert dlg.timer.isActive() and dlg.timer.interval() == 250
    before = len(dlg.lines())
    more_replies(ctx, 4)
    assert len(dlg.lines()) == before  # nothing per reply
    qtbot.waitUntil(lambda: len(dlg.lines()) == before + 8, timeout=2000)


# -- registers and resolution with a real node ---------------------------------------------


def BEAGLE_PARAMS(tmp):  # noqa: N802 - the name tests/monitor/conftest.py looks for
    """The module-wide mm-beagle: emulated sensors, CPI limited to 3200 by a register map."""
    regmap = tmp / "regmap.yaml"
    regmap.write_text("cpi:\n  max: 3200\n")
    return {"backend": "sim", "sim_trajectory": "straight", "register_map": str(regmap)}


@pytest.fixture(scope="module")
def beagle(qapp, beagle_node):
    """A RosBridge on the module's mm-beagle, its services ready."""
    from mm_pc.monitor.ros_bridge import RosBridge

    bridge = RosBridge(rate_hz=20.0, node_name="views_test_monitor")
    bridge.start()
    try:
        # service readiness is not part of the bridge's API; the test waits on it directly
        wait_until(
            lambda: bridge.state == "connected"
            and all(c.service_is_ready() for c in bridge._clients.values()),
            60, "mm-beagle's services", interval=0.05)  # fmt: skip
        yield bridge
    finally:
        bridge.stop()


def read_settings(qtbot, bridge, device):
    with qtbot.waitSignal(bridge.settings_received, timeout=5000) as blocker:
        bridge.request_settings(device)
    assert blocker.args[0] == device
    return blocker.args[1]


@pytest.mark.ros
@pytest.mark.screenshot
def test_registers_refresh_from_the_real_node(qtbot, beagle, screenshot):
    ctx = MonitorContext(MonitorSession(devices=DEFAULT_DEVICES), bridge=beagle)
    view = RegistersView(ctx)
    qtbot.addWidget(view)
    view.resize(1000, 650)
    view.show()
    assert view.refresh_button.isEnabled()
    qtbot.mouseClick(view.refresh_button, Qt.LeftButton)
    qtbot.waitUntil(lambda: len(view.settings) == 2, timeout=5000)
    for col, dev in enumerate(DEFAULT_DEVICES):
        msg, _stamp = view.settings[dev]
        assert msg.spi_device == dev
        for row, name in enumerate(FIELDS):
            assert view.table.item(row, col).text() == f"0x{getattr(msg, name):04X}"
        assert msg.x_cpi == msg.y_cpi == msg.cpi == 1600
        text = view.status_labels[dev].text()
        assert f"status 0x{msg.status_register:04X}" in text
        assert status_bits(msg.status_register) in text
        assert f"lifted: {'yes' if msg.lifted else 'no'}" in text
        assert f"motion: {'yes' if msg.motion else 'no'}" in text
        assert "cpi 1600  (x_cpi 1600, y_cpi 1600)" in text and "read at " in text
    assert view.error.text() == ""
    img = screenshot(view, "registers.png")
    assert distinct_colours(img, 3) > 5
    assert view.table.item(0, 0).text().startswith("0x")

    view.request_registers(["/dev/spidev9.9"])
    qtbot.waitUntil(lambda: view.error.text() != "", timeout=5000)
    assert view.error.text().startswith("/dev/spidev9.9: unknown sensor id '/dev/spidev9.9'")
    assert "known: /dev/spidev1.0, /dev/spidev1.1" in view.error.text()
    assert view.table.columnCount() == 2


@pytest.mark.ros
def test_resolution_with_the_real_node(qtbot, beagle, monkeypatch):
    ctx = MonitorContext(MonitorSession(), bridge=beagle)
    beagle.data_received.connect(ctx.on_replies)
    try:
        panel = ResolutionPanel(ctx)
        qtbot.addWidget(panel)
        qtbot.waitUntil(lambda: len(panel.rows) == 2, timeout=5000)
        dev = DEFAULT_DEVICES[1]
        row = panel.rows[dev]
        qtbot.waitUntil(lambda: row.current.text() == "now: 1600 CPI", timeout=5000)

        sent = []
        real = beagle.set_resolution
        spy = lambda d, c: (sent.append((d, c)), real(d, c))  # noqa: E731
        monkeypatch.setattr(beagle, "set_resolution", spy)
        for bad in ("junk", "0", "50", "6500", "1234"):
            row.edit.setText(bad)
            qtbot.mouseClick(row.set_button, Qt.LeftButton)
            assert bad in row.error.text() or "whole number" in row.error.text()
        assert sent == []
        assert read_settings(qtbot, beagle, dev).cpi == 1600  # the node was not changed

        row.edit.setText("800")
        qtbot.mouseClick(row.set_button, Qt.LeftButton)
        qtbot.waitUntil(lambda: row.read_back.text() == "read back: 800 CPI", timeout=5000)
        assert row.error.text() == "" and sent == [(dev, 800)]
        assert read_settings(qtbot, beagle, dev).cpi == 800
        qtbot.waitUntil(lambda: row.current.text() == "now: 800 CPI", timeout=5000)

        # 4000 passes the widget's range (100..6400) but this node's register map ends at 3200
        row.edit.setText("4000")
        qtbot.mouseClick(row.set_button, Qt.LeftButton)
        qtbot.waitUntil(lambda: row.error.text() != "", timeout=5000)
        assert row.error.text() == (
            "CPI 4000 is out of range (Philips PLN2033 allows 100..3200 in steps of 100)"
        )
        assert "b00020" in row.error.styleSheet()
        assert row.read_back.text() == "read back: 800 CPI"
        assert read_settings(qtbot, beagle, dev).cpi == 800

        row.edit.setText("1600")
        qtbot.mouseClick(row.set_button, Qt.LeftButton)
        qtbot.waitUntil(lambda: row.read_back.text() == "read back: 1600 CPI", timeout=5000)
    finally:
        beagle.data_received.disconnect(ctx.on_replies)
