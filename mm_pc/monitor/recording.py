"""The window's File > Record: pick the file, attach a recorder, show that it records.

While it records, the status bar shows ``● REC 01:23 1.4 MB`` (the file in its
tooltip): the time since it started and the file's size so far, updated every second.
The size is what the file would measure if the recording stopped now
(:meth:`~mm_pc.monitor.io.mcap_writer.McapRecorder.size_bytes`): the writer keeps up to
1 MiB in memory before it writes a compressed chunk, so the size on disk would stay at
0 kB for minutes at 15 Hz and then jump.

The recording itself (the MCAP layout, serialisation, reading back) is Qt-free in
:mod:`mm_pc.monitor.io` (:class:`~mm_pc.monitor.io.mcap_writer.McapRecorder`).
"""

from __future__ import annotations

import contextlib
import time
import warnings
from datetime import datetime
from pathlib import Path

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QFileDialog, QLabel

from mm_pc.monitor.io.bag_format import live_topics
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.settings import last_folder, remember_folder

__all__ = ["recording_text", "start_recording", "stop_recording", "toggle_recording"]

#: how often the status bar's REC figure is updated (ms)
UPDATE_MS = 1000


def recording_text(elapsed_s: float, size_bytes: int) -> str:
    """``● REC 01:23 1.4 MB`` (hours shown from the first hour on)."""
    secs = int(max(elapsed_s, 0.0))
    h, m, sec = secs // 3600, secs // 60 % 60, secs % 60
    clock = f"{h}:{m:02d}:{sec:02d}" if h else f"{m:02d}:{sec:02d}"
    if size_bytes < 1_000_000:
        size = f"{size_bytes / 1e3:.0f} kB"
    elif size_bytes < 1_000_000_000:
        size = f"{size_bytes / 1e6:.1f} MB"
    else:
        size = f"{size_bytes / 1e9:.2f} GB"
    return f"● REC {clock} {size}"


def _update_indicator(window) -> None:
    recorder = window.ctx.recorder
    began = getattr(window, "_recording_began", None)
    if recorder is None or began is None:
        return
    _set_indicator(window, recording_text(time.monotonic() - began, recorder.size_bytes()))


def _set_indicator(window, text: str | None) -> None:
    label = getattr(window, "_recording_label", None)
    if text is None:
        if label is not None:
            window.statusBar().removeWidget(label)
            label.deleteLater()
            window._recording_label = None
        return
    if label is None:
        label = QLabel()
        label.setStyleSheet("color: #b00020; font-weight: bold")
        window.statusBar().addPermanentWidget(label)
        window._recording_label = label
        timer = QTimer(label)  # goes with the label
        timer.setInterval(UPDATE_MS)
        timer.timeout.connect(lambda: _update_indicator(window))
        timer.start()
    label.setText(text)
    recorder = window.ctx.recorder
    if recorder is not None:
        label.setToolTip(
            f"recording to {recorder.path}: time since it started, and the "
            "file's size if it stopped now"
        )


def start_recording(window, path: str | Path, live: bool = True) -> bool:
    """Record every reply from now on to ``path`` (``*.mcap`` or a rosbag2 folder), and
    with ``live`` and a bridge also the live topics
    (:func:`~mm_pc.monitor.io.bag_format.live_topics` of the watched node); False (nothing
    attached) on an error, which is shown in the status bar."""
    ctx = window.ctx
    if ctx.recorder is not None:
        window.statusBar().showMessage(f"already recording to {ctx.recorder.path}", 8000)
        return False
    try:
        recorder = McapRecorder(path, beagle=ctx.config.beagle, rate_hz=ctx.config.rate_hz)
    except (OSError, ValueError) as e:
        window.statusBar().showMessage(f"cannot record to {path}: {e}", 10000)
        return False

    def failed(message: str) -> None:
        # called from inside ctx.on_reply: detach after it returns
        QTimer.singleShot(0, lambda: _stop_after_error(window, recorder, message))

    recorder.on_error = failed
    ctx.recorder = recorder
    if ctx.bridge is not None:  # single polls fetched by anyone (the debug view) go in too
        ctx.bridge.samples_received.connect(recorder.write_samples)
        if live:
            ctx.bridge.record_topics(live_topics(ctx.config.beagle), recorder.write_live)
    window.record_action.setText("Stop &recording")
    window._recording_began = time.monotonic()
    _set_indicator(window, recording_text(0.0, recorder.size_bytes()))
    window.statusBar().showMessage(f"recording to {recorder.path}")
    return True


def _stop_after_error(window, recorder: McapRecorder, message: str) -> None:
    if window.ctx.recorder is recorder:
        stop_recording(window)
    window.statusBar().showMessage(message, 15000)


def stop_recording(window) -> Path | None:
    """Stop and close the recording; the file's path (None when nothing was recorded)."""
    recorder = window.ctx.recorder
    if recorder is None:
        return None
    window.ctx.recorder = None
    if window.ctx.bridge is not None:
        with contextlib.suppress(RuntimeError, TypeError), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            window.ctx.bridge.samples_received.disconnect(recorder.write_samples)
        window.ctx.bridge.stop_recording_topics()
    recorder.close()
    window.record_action.setText("&Record…")
    _set_indicator(window, None)
    if recorder.error:
        window.statusBar().showMessage(recorder.error, 15000)
    else:
        window.statusBar().showMessage(
            f"recorded {recorder.replies} replies to {recorder.path}", 8000
        )
    return recorder.path


def toggle_recording(window) -> None:
    """File > Record: ask for a file and start, or stop the running recording."""
    if window.ctx.recorder is not None:
        stop_recording(window)
        return
    default = Path(last_folder("recording")) / datetime.now().strftime(
        "mouse-monitor-%Y%m%d-%H%M%S.mcap"
    )
    name, _ = QFileDialog.getSaveFileName(
        window, "Record replies to", str(default), "MCAP recordings (*.mcap);;All files (*)"
    )
    if name:
        remember_folder("recording", name)
        start_recording(window, name)
