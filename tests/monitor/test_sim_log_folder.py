"""mm-monitor --sim (./compile demo) removes its node-log folder /tmp/mm-monitor-XXXX at the
end, Ctrl-C included, and keeps it when the node died or the monitor failed (the message names
the log in it)."""

from __future__ import annotations

from contextlib import ExitStack

import pytest

from mm_pc.monitor.app import _remove_unless_failed


def _folder(tmp_path):
    folder = tmp_path / "mm-monitor-x"
    folder.mkdir()
    (folder / "sim_beagle.log").write_text("log\n")
    return folder


@pytest.mark.parametrize("raised", [None, KeyboardInterrupt])
def test_a_run_that_ends_or_is_stopped_by_ctrl_c_removes_the_folder(tmp_path, raised):
    folder = _folder(tmp_path)
    with pytest.raises(raised) if raised else ExitStack(), ExitStack() as stack:
        stack.push(_remove_unless_failed(folder, []))
        if raised:
            raise raised
    assert not folder.exists()


def test_the_log_stays_when_the_node_died_or_the_monitor_failed(tmp_path):
    folder = _folder(tmp_path)
    with ExitStack() as stack:
        stack.push(_remove_unless_failed(folder, ["the emulated mm-beagle exited (code 1)"]))
    assert folder.exists()
    with pytest.raises(RuntimeError), ExitStack() as stack:
        stack.push(_remove_unless_failed(folder, []))
        raise RuntimeError("the node did not come up; see its log")
    assert (folder / "sim_beagle.log").exists()


def test_an_error_a_stops_keyboard_interrupt_became_removes_the_folder(tmp_path, monkeypatch):
    """shiboken can turn the stop's KeyboardInterrupt into an AttributeError: after a stop
    raised by stop_signals that error is the stop's, so the folder goes; without one the
    same error is a failure and the log stays."""
    from types import SimpleNamespace

    from mm_pc import stop_signals

    for stopped, kept in ((True, False), (False, True)):
        folder = _folder(tmp_path)
        monkeypatch.setattr(stop_signals, "_running", SimpleNamespace(raised=stopped))
        with pytest.raises(AttributeError), ExitStack() as stack:
            stack.push(_remove_unless_failed(folder, []))
            raise AttributeError("'PySide6.QtCore.Qt' has no attribute 'AlignLeft'")
        assert folder.exists() is kept, f"stop raised: {stopped}"
