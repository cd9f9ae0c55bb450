"""Placeholder: being written."""


def toggle_recording(window) -> None:
    window.statusBar().showMessage("recording: not yet available")
