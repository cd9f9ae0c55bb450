"""PNG export of what the monitor shows (the current tab's plots/tables, or the whole window)."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QRect
from PySide6.QtWidgets import QAbstractItemView, QFileDialog, QGraphicsView, QWidget

from mm_pc.monitor.settings import last_folder, remember_folder

__all__ = ["content_rect", "export_current_view", "grab_png"]

#: the kind of file dialog (``settings.last_folder``) the PNG export remembers
FOLDER_KIND = "export"


def grab_png(widget: QWidget, path: str | Path, rect: QRect | None = None) -> Path:
    """Render ``widget`` (or its ``rect``, widget pixels) as on screen into a PNG file.

    Raises OSError when the file cannot be written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    image = widget.grab(rect) if rect is not None else widget.grab()
    if not image.save(str(path), "PNG"):
        raise OSError(f"could not write {path}")
    return path


def content_rect(view: QWidget) -> QRect | None:
    """The part of ``view`` that shows data: the union of its visible plots (QGraphicsView)
    and tables, without the rows of buttons, check boxes and sliders above or beside them.

    None when the view has no such child (then the whole view is exported).
    """
    rect = QRect()
    for cls in (QGraphicsView, QAbstractItemView):
        for child in view.findChildren(cls):
            if not child.isVisibleTo(view) or child.width() < 2 or child.height() < 2:
                continue
            top_left = child.mapTo(view, child.rect().topLeft())
            rect = rect.united(QRect(top_left, child.size()))
    return rect if rect.isValid() else None


def export_current_view(window, name: str | None = None) -> Path | None:
    """Save the current tab's plots and tables as PNG (None if cancelled or not written).

    ``name``: the file; None asks with a dialog that starts in the folder the last
    export went to (``settings.last_folder("export")``, never the working directory).
    """
    view = window.current_view()
    title = window.tabs.tabText(window.tabs.currentIndex()).lower()
    if name is None:
        start = str(Path(last_folder(FOLDER_KIND)) / f"mouse-monitor-{title}.png")
        name, _ = QFileDialog.getSaveFileName(
            window, "Export view as PNG", start, "PNG images (*.png)"
        )
    if not name:
        return None
    try:
        path = grab_png(view, name, content_rect(view))
    except OSError as e:
        window.statusBar().showMessage(str(e), 8000)
        return None
    remember_folder(FOLDER_KIND, path)
    window.statusBar().showMessage(f"saved {path}", 5000)
    return path
