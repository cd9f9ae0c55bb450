"""A recording cut short (a crash, a full disk) replays up to its last whole message, with a
warning that says how much was read; a whole file replays all with no warning (issue 29,
finding 12). The recordings are written by the real recorder, then cut."""

from __future__ import annotations

import logging

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from PySide6.QtWidgets import QMessageBox

from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.io.mcap_reader import read_replies, read_replies_up_to_cut
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import sim_replies
from mm_pc.monitor.replay import load_in_background, start_replay


@pytest.fixture(scope="module")
def run20(tmp_path_factory):
    """20 s of a figure eight at 100 Hz (2001 replies): several chunks of the file."""
    path = tmp_path_factory.mktemp("cut") / "run20.mcap"
    rec = McapRecorder(path)
    for r in sim_replies("figure_eight", 100.0, 20.0):
        rec.write_reply(r)
    rec.close()
    return path, read_replies(path)


def make_window(qtbot, tmp_path) -> MainWindow:
    config = MonitorConfig(rate_hz=100.0, calibration_file=tmp_path / "cal.yaml")
    window = MainWindow(MonitorContext(MonitorSession(), None, config))
    qtbot.addWidget(window)
    window.show()  # the status bar's message is elided to the room it has
    return window


def cut(path, tmp_path, keep: int):
    data = path.read_bytes()
    out = tmp_path / f"cut{keep}.mcap"
    out.write_bytes(data[:keep])
    return out


def test_a_whole_file_replays_all_without_a_warning(qtbot, tmp_path, run20):
    path, whole = run20
    replies, warning = read_replies_up_to_cut(path)
    assert warning == "" and replies == whole and len(whole) == 2001
    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, path, "max", dialog=True)
    assert window.replay_cut_warning == ""
    assert getattr(window, "replay_warning", None) is None
    assert "cut short" not in window.statusBar().currentMessage()
    qtbot.waitUntil(lambda: replayer.done, timeout=20_000)
    assert replayer.position == 2001


@pytest.mark.parametrize("share", [0.25, 0.5, 0.85])  # all in the data (it ends at ~0.9)
def test_a_file_cut_in_its_data_replays_its_whole_replies_with_a_warning(
    share, qtbot, tmp_path, run20, caplog
):
    path, whole = run20
    size = path.stat().st_size
    short = cut(path, tmp_path, int(size * share))
    with pytest.raises(ValueError, match="damaged or incomplete"):
        read_replies(short)  # the strict reader still refuses it
    replies, warning = read_replies_up_to_cut(short)
    n = len(replies)
    assert 0.5 * share * 2001 < n < 2001
    assert replies == whole[:n]  # exactly the recorded replies, in order
    assert f"{short.name} is cut short" in warning and f"{n} replies to replay" in warning
    assert f"at byte {int(size * share)}: read " in warning
    window = make_window(qtbot, tmp_path)
    with caplog.at_level(logging.WARNING, logger="mm_pc.monitor.replay"):
        replayer = start_replay(window, short, "max", dialog=True)
    assert replayer is not None
    box = window.replay_warning
    assert isinstance(box, QMessageBox) and warning in box.text()
    assert "replayed up to its last whole message" in box.text()
    assert any(warning in r.getMessage() for r in caplog.records)
    assert window.statusBar().currentMessage().startswith(warning)
    qtbot.waitUntil(lambda: replayer.done, timeout=20_000)
    assert replayer.position == n
    assert window.statusBar().currentMessage().startswith(warning)  # the end summary too
    box.done(0)


def test_a_file_without_its_last_100_bytes_replays_every_reply(qtbot, tmp_path, run20):
    path, whole = run20
    short = cut(path, tmp_path, path.stat().st_size - 100)  # the index at the end is gone
    replies, warning = read_replies_up_to_cut(short)
    assert replies == whole
    assert "all" in warning and "only the index at its end" in warning
    window = make_window(qtbot, tmp_path)
    replayer = start_replay(window, short, "max")  # the command line: no dialog
    assert window.replay_cut_warning == warning
    qtbot.waitUntil(lambda: replayer.done, timeout=20_000)
    assert replayer.position == 2001


def test_a_file_cut_before_its_first_whole_chunk_is_refused_with_the_reason(
    qtbot, tmp_path, run20
):
    path, _ = run20
    short = cut(path, tmp_path, 2000)
    with pytest.raises(ValueError, match=r"cut short .* before its first whole block"):
        read_replies_up_to_cut(short)
    window = make_window(qtbot, tmp_path)
    load_in_background(window, short, 1.0)  # File > Replay
    qtbot.waitUntil(lambda: getattr(window, "replay_error", None) is not None, timeout=10_000)
    assert "before its first whole block" in window.replay_error.text()
    assert "Error:" not in window.replay_error.text()
    assert getattr(window, "replayer", None) is None
    window.replay_error.done(0)
