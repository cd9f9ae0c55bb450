"""Reading a recording in slices on the GUI thread (File > Replay): the same replies as a
read at once, in many small steps, other timers running between the slices, no automatic
garbage collection inside a slice, errors and cancel handed over."""

from __future__ import annotations

import gc
import time

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from PySide6.QtCore import QTimer

from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.io.mcap_reader import (
    STEP_MESSAGES,
    _indexed_messages,
    read_replies,
    read_replies_up_to_cut_steps,
    run_steps,
)
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.replay import load_in_background
from mm_pc.monitor.replay_load import SlicedRead


@pytest.fixture(scope="module")
def run10(tmp_path_factory):
    """10 s of a figure eight at 100 Hz (1001 replies, 3003 messages)."""
    path = tmp_path_factory.mktemp("load") / "run10.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("figure_eight", 100.0, 10.0):
        rec.write_reply(r)
    rec.close()
    return path


def test_the_stepped_read_gives_the_replies_of_the_read_at_once_in_many_steps(run10):
    steps = read_replies_up_to_cut_steps(run10)
    n = 0
    while True:
        try:
            next(steps)
            n += 1
        except StopIteration as done:
            replies, warning = done.value
            break
    assert warning == ""
    want = read_replies(run10)
    assert replies == want and len(replies) == 1001
    # reading and decoding 3003 messages, a step at most every STEP_MESSAGES of each
    assert n >= 2 * 3003 // STEP_MESSAGES
    assert run_steps(read_replies_up_to_cut_steps(run10)) == (want, "")


def test_indexed_messages_are_mcaps_messages_in_file_order(run10):
    from mcap.reader import make_reader

    with open(run10, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        want = [(s.name if s else None, c.topic, m.sequence, m.log_time, bytes(m.data))
                for s, c, m in reader.iter_messages(log_time_order=False)]  # fmt: skip
        summary = reader.get_summary()
        assert len(summary.chunk_indexes) >= 1
        got = [(s.name if s else None, c.topic, m.sequence, m.log_time, bytes(m.data))
               for s, c, m in _indexed_messages(f, summary)]  # fmt: skip
    assert got == want and len(got) == 3003


def test_file_replay_reads_in_slices_while_the_window_runs(qtbot, tmp_path, run10):
    config = MonitorConfig(rate_hz=100.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), None, config))
    qtbot.addWidget(window)
    ticks = []
    timer = QTimer()
    timer.timeout.connect(lambda: ticks.append(window.replay_reading is not None))
    timer.start(5)
    future = load_in_background(window, run10, "max")
    assert not future.done()  # nothing read yet: the first slice runs from the event loop
    assert "reading run10.mcap" in window.statusBar().currentMessage()
    qtbot.waitUntil(lambda: getattr(window, "replayer", None) is not None, timeout=20_000)
    timer.stop()
    assert sum(ticks) >= 2  # the timer ran while the file was being read
    speed, replies, warning = future.result()
    assert speed == float("inf") and warning == "" and len(replies) == 1001
    assert window.replayer.replies == replies
    assert gc.isenabled()


def _watched(n: int, seen: list, result="done"):
    """n steps that note whether automatic garbage collection was on in each."""
    for _ in range(n):
        seen.append(gc.isenabled())
        time.sleep(0.0002)  # work
        yield
    return result


def test_a_slice_runs_without_automatic_gc_and_hands_over_result_errors_and_cancel(qtbot):
    seen: list[bool] = []
    ends = []
    read = SlicedRead(_watched(300, seen), ends.append, slice_s=0.005)
    qtbot.waitUntil(lambda: bool(ends), timeout=10_000)
    assert ends == [read.future] and read.future.result() == "done"
    assert len(seen) == 300 and not any(seen) and read.slices >= 5  # >= 60 ms of work
    assert gc.isenabled()

    def bad():
        yield
        raise ValueError("x is not a recording")

    ends.clear()
    read = SlicedRead(bad(), ends.append)
    qtbot.waitUntil(lambda: bool(ends), timeout=10_000)
    with pytest.raises(ValueError, match="x is not a recording"):
        read.future.result()
    assert gc.isenabled()

    closed = []

    def endless():
        try:
            while True:
                yield
        finally:
            closed.append(True)

    ends.clear()
    read = SlicedRead(endless(), ends.append)
    qtbot.wait(30)
    read.cancel()
    assert closed == [True] and read.future.cancelled() and not read.timer.isActive()
    qtbot.wait(30)
    assert ends == []
