"""PNG export of what the monitor shows (the current tab, or the whole window)."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import QFileDialog, QWidget

__all__ = ["export_current_view", "grab_png"]


def grab_png(widget: QWidget, path: str | Path) -> Path:
    """Render ``widget`` as it is on screen (offscreen too) into a PNG file.

    Raises OSError when the file cannot be written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not widget.grab().save(str(path), "PNG"):
        raise OSError(f"could not write {path}")
    return path


def export_current_view(window) -> Path | None:
    """Ask for a file name and save the current tab as PNG (None if cancelled)."""
    view = window.tabs.currentWidget()
    title = window.tabs.tabText(window.tabs.currentIndex()).lower()
    name, _ = QFileDialog.getSaveFileName(
        window, "Export view as PNG", f"mouse-monitor-{title}.png", "PNG images (*.png)"
    )
    if not name:
        return None
    try:
        path = grab_png(view, name)
    except OSError as e:
        window.statusBar().showMessage(str(e), 8000)
        return None
    window.statusBar().showMessage(f"saved {path}", 5000)
    return path
