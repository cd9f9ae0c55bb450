"""The REC figure's size: what the file would measure if the recording stopped now.

The mcap writer keeps up to 1 MiB in memory before it writes a compressed chunk, so the
file on disk stays at 0 bytes for minutes at 15 Hz; the recorder counts what it hands to
the writer (:mod:`mm_pc.monitor.io.mcap_size`) instead.
"""

from __future__ import annotations

import re
from itertools import pairwise

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from mm_pc.monitor import recording
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.io.mcap_reader import read_replies
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.recording import recording_text, start_recording, stop_recording

#: before the first chunk is on disk the open chunk is counted at the compression ratio of
#: a sample (the first 256 kB of records): measured within 0.5 % (6 s at 15 Hz) and 3 %
#: (60 s at 15 Hz) of the closed file; after a chunk, at that chunk's ratio (0.03 %)
BEFORE_FIRST_CHUNK = 0.03
AFTER_CHUNKS = 0.005


def make_window(qtbot, tmp_path) -> MainWindow:
    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), None, config))
    qtbot.addWidget(window)
    return window


def shown_kb(text: str) -> int:
    match = re.fullmatch(r"● REC \d\d:\d\d (\d+) kB", text)
    assert match, text
    return int(match.group(1))


def test_rec_size_grows_every_second_at_15_hz_and_ends_at_the_files_size(
    qtbot, tmp_path, monkeypatch
):
    monkeypatch.setattr(recording, "UPDATE_MS", 50)  # the 1 s update, faster
    window = make_window(qtbot, tmp_path)
    path = tmp_path / "slow.mcap"
    assert start_recording(window, path)
    recorder = window.ctx.recorder
    label = window._recording_label
    replies = list(sim_replies("figure_eight", 15.0, 6.0))
    shown = []
    for second in range(6):  # six seconds of replies, one update after each
        for r in replies[15 * second : 15 * (second + 1)]:
            window.ctx.on_reply(r)
        expected = recording_text(0.0, recorder.size_bytes()).split()[-2:]
        qtbot.waitUntil(lambda e=expected: label.text().split()[-2:] == e, timeout=5000)
        shown.append(shown_kb(label.text()))
        assert path.stat().st_size == 0  # nothing on disk yet: the old figure said 0 kB
    assert shown[0] > 0
    assert all(b > a for a, b in pairwise(shown)), shown
    before = recorder.size_bytes()
    assert stop_recording(window) == path
    final = path.stat().st_size
    assert abs(final - before) <= BEFORE_FIRST_CHUNK * final, (before, final)
    assert abs(shown[-1] * 1000 - final) <= BEFORE_FIRST_CHUNK * final + 500, (shown, final)
    assert read_replies(path) == replies[:90]


def test_with_chunks_on_disk_the_size_counts_them_and_the_open_one(tmp_path):
    path = tmp_path / "long.mcap"
    rec = McapRecorder(path, rate_hz=100.0)
    disk_sizes, estimates = [], []
    for i, r in enumerate(sim_replies("figure_eight", 100.0, 60.0)):
        rec.write_reply(r)
        if i % 500 == 499:
            rec._file.flush()
            disk_sizes.append(path.stat().st_size)
            estimates.append(rec.size_bytes())
    assert disk_sizes[0] < 100 < 100_000 < disk_sizes[-1]  # the header; then chunks
    assert all(b > a for a, b in pairwise(estimates))
    assert all(e > d for e, d in zip(estimates, disk_sizes, strict=True))
    before = rec.size_bytes()
    rec.close()
    final = path.stat().st_size
    assert abs(final - before) <= AFTER_CHUNKS * final, (before, final)
    assert rec.size_bytes() == final  # closed: the file's own size


def test_the_counted_bytes_are_the_writers_own_chunk(tmp_path):
    # the record sizes of mcap_size against the mcap writer's buffer (a private attribute:
    # this test fails, rather than the figure drifting, if a new mcap changes its records)
    rec = McapRecorder(tmp_path / "a.mcap")
    chunk = rec._writer._Writer__chunk_builder
    assert rec._size._open == chunk.count
    for r in sim_replies("straight", 50.0, 1.0):
        rec.write_reply(r)
    rec.write_live("/tf", "tf2_msgs/msg/TFMessage", b"\x00\x01\x00\x00\x00\x00\x00\x00")
    assert rec._size._open == chunk.count > 10_000
    rec.close()


def test_an_empty_recording_shows_what_its_file_will_measure(tmp_path):
    for target in (tmp_path / "empty.mcap", tmp_path / "bag"):  # a file, a rosbag2 folder
        rec = McapRecorder(target)
        before = rec.size_bytes()
        rec.close()
        final = rec.file.stat().st_size
        assert final > 5000  # the schemas and channels, repeated in the summary
        assert abs(final - before) <= 100, (before, final)  # the metadata's times' digits
