"""Placeholder: being written (owner: see the task list)."""

from __future__ import annotations

from PySide6.QtWidgets import QDialog


class FilterDialog(QDialog):
    def __init__(self, ctx, parent=None) -> None:
        super().__init__(parent)
        self.ctx = ctx
