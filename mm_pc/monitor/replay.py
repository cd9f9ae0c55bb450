"""Placeholder: being written."""


def open_replay(window) -> None:
    window.statusBar().showMessage("replay: not yet available")
