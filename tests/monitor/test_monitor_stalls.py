"""The fixes for GUI-thread stalls (issue 29 item 6), functional: what each one does, not how
fast (the timing lives in ``mm-bench gui``'s ``stalls`` figure)."""

from __future__ import annotations

import multiprocessing
import os
import sys
import time

import pytest
from PySide6.QtCore import Qt, QTimer

from mm_pc.bench.gui import STALL_MS, _Heartbeat, stall_figures
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model import sim_process
from mm_pc.monitor.model.csv_export import (
    csv_chunks,
    csv_columns,
    export_csv,
    history_csv_chunks,
)
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.widgets.data_list import REFRESH_PERIOD_S, DataListView, HistoryTableModel


def test_stall_figures_count_the_gaps_over_100_ms():
    assert stall_figures([10.0, 10.2, 150.0, 99.9, 100.1]) == {
        "longest_ms": 150.0, "count_over_100ms": 2, "ticks": 5,
    }  # fmt: skip
    assert stall_figures([]) == {"longest_ms": 0.0, "count_over_100ms": 0, "ticks": 0}
    assert STALL_MS == 100.0


def test_the_heartbeat_sees_a_blocked_gui_thread(qtbot):
    beat = _Heartbeat()
    beat.start()
    QTimer.singleShot(50, lambda: time.sleep(0.25))  # the GUI thread busy for 250 ms
    qtbot.wait(500)
    figures = beat.stop()
    assert figures["count_over_100ms"] == 1
    assert 250.0 <= figures["longest_ms"] < 1000.0
    assert figures["ticks"] >= 10  # it ticked around the block


def test_csv_export_in_background_writes_what_export_to_writes(qtbot, tmp_path, feed):
    ctx = MonitorContext(MonitorSession())
    feed(ctx, name="figure_eight", rate_hz=100.0, seconds=60.0)  # 6000 rows: 3 steps
    view = DataListView(ctx)
    qtbot.addWidget(view)
    table = view.tables[0]
    n = len(ctx.session.history)
    out = tmp_path / "bg.csv"
    assert table.export_in_background(out)
    # the columns were copied at once: rows arriving meanwhile are not in this file
    assert table.message.text() == f"writing {n} rows to {out} …"
    assert not table.export_button.isEnabled()
    qtbot.waitUntil(lambda: table.export_button.isEnabled(), timeout=20_000)
    assert table.export_done is True
    assert table.message.text() == f"{n} rows written to {out}"
    assert export_csv(ctx.session.history, 0, tmp_path / "now.csv") == n
    assert out.read_text() == (tmp_path / "now.csv").read_text()


def test_csv_export_in_background_shows_its_progress(qtbot, tmp_path, feed, monkeypatch):
    monkeypatch.setattr("mm_pc.monitor.widgets.data_list.PROGRESS_PERIOD_S", 0.0)
    ctx = MonitorContext(MonitorSession())
    feed(ctx, name="figure_eight", rate_hz=100.0, seconds=60.0)
    view = DataListView(ctx)
    qtbot.addWidget(view)
    table = view.tables[0]
    texts: list[str] = []
    show = table.message.setText
    monkeypatch.setattr(table.message, "setText", lambda t: (texts.append(t), show(t)))
    n = len(ctx.session.history)
    out = tmp_path / "bg.csv"
    assert table.export_in_background(out)
    qtbot.waitUntil(lambda: table.export_button.isEnabled(), timeout=20_000)
    shares = [int(t.rsplit(" ", 2)[-2]) for t in texts if t.endswith(" %")]
    assert texts[0] == f"writing {n} rows to {out} …"
    assert texts[1] == f"writing {n} rows to {out} … 0 %"  # the header
    assert 100 * 2500 // n in shares  # the first step's rows
    assert shares == sorted(shares) and shares[-1] <= 100, shares
    assert texts[-1] == f"{n} rows written to {out}"


def test_csv_chunks_write_the_file_of_one_go(tmp_path, feed):
    ctx = MonitorContext(MonitorSession())
    feed(ctx, name="figure_eight", rate_hz=100.0, seconds=10.0)
    cols = csv_columns(ctx.session.history, 1)
    n = len(cols[0])
    steps = list(csv_chunks(cols, tmp_path / "steps.csv", rows=300))
    assert steps == [0, *range(300, n, 300), n]
    assert export_csv(ctx.session.history, 1, tmp_path / "once.csv") == n
    assert (tmp_path / "steps.csv").read_text() == (tmp_path / "once.csv").read_text()


def test_history_chunks_copy_only_the_rows_held_at_the_start(tmp_path, feed):
    ctx = MonitorContext(MonitorSession())
    feed(ctx, name="figure_eight", rate_hz=100.0, seconds=10.0)
    hist = ctx.session.history
    n = len(hist)
    assert export_csv(hist, 0, tmp_path / "once.csv") == n
    steps = history_csv_chunks(hist, 0, tmp_path / "steps.csv", rows=300)
    assert next(steps) == 0
    hist.append(hist.tail(1)[0])  # a row arrives between two steps: not in this file
    assert list(steps) == [*range(300, n, 300), n]
    assert (tmp_path / "steps.csv").read_text() == (tmp_path / "once.csv").read_text()


def test_history_chunks_refuse_a_history_cleared_meanwhile(qtbot, tmp_path, feed):
    ctx = MonitorContext(MonitorSession())
    feed(ctx, name="figure_eight", rate_hz=100.0, seconds=10.0)
    steps = history_csv_chunks(ctx.session.history, 0, tmp_path / "x.csv", rows=300)
    assert next(steps) == 0 and next(steps) == 300
    ctx.session.history.clear()
    with pytest.raises(ValueError, match="cleared or its oldest rows dropped during the export"):
        next(steps)
    # in the view: the reason beside the button, the button back
    feed(ctx, name="figure_eight", rate_hz=100.0, seconds=60.0)
    view = DataListView(ctx)
    qtbot.addWidget(view)
    table = view.tables[0]
    assert table.export_in_background(tmp_path / "y.csv")
    qtbot.wait(1)  # a step or two
    ctx.session.history.clear()
    qtbot.waitUntil(lambda: table.export_button.isEnabled(), timeout=20_000)
    assert table.export_done is False
    assert table.message.text() == ("export failed: the data was cleared or its oldest rows "
                                    "dropped during the export: export again")


def test_csv_export_in_background_says_why_it_failed(qtbot, tmp_path, feed):
    ctx = MonitorContext(MonitorSession())
    feed(ctx, name="figure_eight", rate_hz=100.0, seconds=1.0)
    view = DataListView(ctx)
    qtbot.addWidget(view)
    table = view.tables[0]
    table.export_in_background(tmp_path / "missing_dir" / "x.csv")
    qtbot.waitUntil(lambda: table.export_button.isEnabled(), timeout=20_000)
    assert table.message.text().startswith("export failed:")
    assert "No such file or directory" in table.message.text()
    assert not (tmp_path / "missing_dir").exists() and table.export_done is False


def test_csv_export_in_background_without_data_writes_nothing(qtbot, tmp_path):
    ctx = MonitorContext(MonitorSession())
    view = DataListView(ctx)
    qtbot.addWidget(view)
    view._build(("/a", "/b"))
    table = view.tables[0]
    assert table.export_in_background(tmp_path / "x.csv") is False
    assert table.message.text() == "export failed: no data yet: nothing to export"
    assert table.export_button.isEnabled() and not (tmp_path / "x.csv").exists()


@pytest.mark.skipif(not hasattr(os, "nice"), reason="no os.nice here")
def test_the_simulation_child_runs_at_a_lower_priority():
    import stall_children

    job = sim_process.SimJob(1, target=stall_children.report_niceness)
    deadline = time.monotonic() + 30
    result = None
    while result is None and time.monotonic() < deadline:
        result = job.poll()
        time.sleep(0.02)
    assert result is not None and result[0] == "ok"
    before, after = result[1]
    assert after == min(19, before + sim_process.CHILD_NICE)


def test_a_big_result_is_read_in_slices_one_per_poll():
    import stall_children

    job = sim_process.SimJob(2, target=stall_children.send_big)
    deadline = time.monotonic() + 30
    result, polls = None, 0
    while result is None and time.monotonic() < deadline:
        result = job.poll()
        polls += 1
        time.sleep(0.005)
    assert result == ("ok", bytes(range(256)) * (3_000_000 // 256))
    # never more than READ_SLICE bytes in one poll: the GUI thread never waits for the child
    assert job.slices >= 3_000_000 // sim_process.READ_SLICE and polls > job.slices
    # the result's classes were imported in a poll before the first read
    assert job.warmed and sim_process.RESULT_MODULE in sys.modules
    assert job.done and job.poll() is None


def test_a_child_that_died_without_closing_the_pipe_is_reported():
    import sim_children

    job = sim_process.SimJob(3, target=sim_children.hang)
    # a writing end still open elsewhere (as spawn's fd hand-over keeps one when the child
    # dies before taking it): no EOF will ever come
    recv, keep_open = multiprocessing.Pipe(duplex=False)
    job._recv.close()
    job._recv = recv
    job.process.kill()
    job.process.join(5)
    deadline = time.monotonic() + 10
    result = None
    while result is None and time.monotonic() < deadline:
        result = job.poll()
        time.sleep(0.02)
    keep_open.close()
    assert result is not None and result[0] == "error"
    assert "ended without a result" in result[1] and "exit code -9" in result[1]
    assert job.done and job.poll() is None


class _Clock:
    """``time`` for main_window with a perf_counter the test moves (s)."""

    def __init__(self) -> None:
        self.now = 100.0

    def perf_counter(self) -> float:
        return self.now

    def __getattr__(self, name):
        return getattr(time, name)


def test_the_window_refreshes_the_data_table_at_most_every_period(qapp, tmp_path, feed,
                                                                  monkeypatch):  # fmt: skip
    # a repaint of the table costs ~2000 Python calls (40 ms on a slow PC): at 30 frames a
    # second the Data tab at 500 Hz held the window 80 % of the time; the other views
    # still get every frame
    clock = _Clock()
    monkeypatch.setattr("mm_pc.monitor.main_window.time", clock)
    config = MonitorConfig(rate_hz=100.0, calibration_file=tmp_path / "cal.yaml")
    w = MainWindow(MonitorContext(MonitorSession(), None, config), None)
    w.frame_timer.stop()
    replies = list(sim_replies("figure_eight", 100.0, 2.0))
    feed(w.ctx, replies[:101])  # the first reply is the baseline: 100 rows
    data = w.views["Data"]
    w.tabs.setCurrentIndex(w.tabs.indexOf(data.parentWidget().parentWidget()))
    w.frame()
    model = data.tables[0].model
    assert model.rowCount() == 100
    feed(w.ctx, replies[101:111])
    clock.now += 0.6 * REFRESH_PERIOD_S
    w.frame()
    assert model.rowCount() == 100  # not yet
    clock.now += 0.6 * REFRESH_PERIOD_S
    w.frame()
    assert model.rowCount() == 110
    graphs = w.views["Graphs"]
    calls = []
    monkeypatch.setattr(graphs, "refresh", lambda: calls.append(clock.now))
    w.tabs.setCurrentIndex(w.tabs.indexOf(graphs.parentWidget().parentWidget()))
    for _ in range(3):
        clock.now += 0.01
        w.frame()
    assert len(calls) == 3
    w.close()


def test_the_row_numbers_widen_the_header_without_asking_every_label(qtbot, feed, monkeypatch):
    # Qt's own size hint asked the model for ~200 sections' labels after every insert
    asked = []
    label = HistoryTableModel.headerData

    def counting(self, section, orientation, role=Qt.ItemDataRole.DisplayRole):
        if orientation == Qt.Orientation.Vertical:
            asked.append(section)
        return label(self, section, orientation, role)

    monkeypatch.setattr(HistoryTableModel, "headerData", counting)
    ctx = MonitorContext(MonitorSession())
    replies = list(sim_replies("figure_eight", 100.0, 10.2))
    feed(ctx, replies[:991])  # the first reply is the baseline: 990 rows
    view = DataListView(ctx)
    qtbot.addWidget(view)
    view.resize(900, 500)
    view.show()
    view.refresh()
    qtbot.wait(1)
    table = view.tables[0].table
    header = table.verticalHeader()
    fm = header.fontMetrics()
    assert fm.horizontalAdvance("990") <= header.width() < fm.horizontalAdvance("1000")
    asked.clear()
    feed(ctx, replies[991:1011])  # 990 -> 1010 rows: one more digit
    view.refresh()
    qtbot.wait(1)
    table.viewport().repaint()
    header.viewport().repaint()
    assert header.width() >= fm.horizontalAdvance("1010"), header.width()
    assert header.model().headerData(0, Qt.Orientation.Vertical) == "1010"
    # the visible sections' labels (and a few more), not every section's
    assert 0 < len(asked) < 400, len(asked)
    assert max(asked) < 60, max(asked)
    # a bigger font is measured again at once, not at the next digit
    font = header.font()
    font.setPointSizeF(font.pointSizeF() * 2)
    header.setFont(font)
    assert header.sizeHint().width() >= header.fontMetrics().horizontalAdvance("1010")
