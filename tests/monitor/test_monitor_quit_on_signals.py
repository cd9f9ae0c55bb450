"""mm-monitor's Qt loop ends on SIGINT/SIGTERM even when the signal lands before
``app.exec()`` runs (the quit is queued, not called), and on a signal stop_signals saw
before the monitor's handlers were installed. Deterministic: the signal is sent by the
test at the moment in question, and a 5 s fallback timer tells a lost quit apart."""

from __future__ import annotations

import os
import signal
import time
from types import SimpleNamespace

import pytest

pytest.importorskip("PySide6")

from PySide6.QtCore import QTimer

from mm_pc import stop_signals
from mm_pc.monitor.app import quit_on_signals

FALLBACK_MS = 5000


@pytest.fixture
def handlers_restored():
    saved = {sig: signal.getsignal(sig) for sig in stop_signals.SIGNALS}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


def _exec_seconds(app) -> float:
    """How long app.exec() ran (the fallback ends it after FALLBACK_MS)."""
    fallback = QTimer()
    fallback.setSingleShot(True)
    fallback.timeout.connect(app.quit)
    fallback.start(FALLBACK_MS)
    start = time.monotonic()
    app.exec()
    fallback.stop()
    return time.monotonic() - start


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_before_the_loop_runs_still_ends_it(qapp, handlers_restored, sig):
    stopped_by = quit_on_signals(qapp)
    os.kill(os.getpid(), sig)  # the handler runs here, before exec()
    time.sleep(0.05)
    assert stopped_by == [sig]
    assert _exec_seconds(qapp) < FALLBACK_MS / 1000 / 2, "the quit was lost: the loop ran on"


def test_a_signal_stop_signals_saw_before_quits_at_once(qapp, handlers_restored, monkeypatch):
    monkeypatch.setattr(stop_signals, "_running", SimpleNamespace(seen=signal.SIGTERM))
    stopped_by = quit_on_signals(qapp)
    assert stopped_by == [signal.SIGTERM]
    assert _exec_seconds(qapp) < FALLBACK_MS / 1000 / 2


def test_no_signal_leaves_the_loop_running(qapp, handlers_restored, monkeypatch):
    """The fallback ends it: without a signal nothing quits (so the tests above can fail)."""
    monkeypatch.setattr(stop_signals, "_running", None)
    stopped_by = quit_on_signals(qapp)
    QTimer.singleShot(300, qapp.quit)
    assert 0.25 < _exec_seconds(qapp) < FALLBACK_MS / 1000 / 2
    assert stopped_by == []
