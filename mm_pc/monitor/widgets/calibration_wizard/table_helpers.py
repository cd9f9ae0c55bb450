"""The pages' small parts: an error label, a read-only table, a row set in place, a value
± its standard error."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QHeaderView,
    QLabel,
    QTableWidget,
    QTableWidgetItem,
)

from mm_pc.monitor.widgets.style import ERROR_STYLE


def error_label() -> QLabel:
    label = QLabel("")
    label.setStyleSheet(ERROR_STYLE)
    label.setWordWrap(True)
    label.hide()
    return label


def make_table(columns: list[str]) -> QTableWidget:
    table = QTableWidget(0, len(columns))
    table.setHorizontalHeaderLabels(columns)
    table.verticalHeader().setVisible(False)
    table.setEditTriggers(QTableWidget.NoEditTriggers)
    table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
    return table


def set_row(table: QTableWidget, row: int, values: list[str]) -> None:
    for c, v in enumerate(values):
        item = table.item(row, c)
        if item is None:
            item = QTableWidgetItem(v)
            if c:
                item.setTextAlignment(Qt.AlignRight | Qt.AlignVCenter)
            table.setItem(row, c, item)
        elif item.text() != v:
            item.setText(v)


def plus_minus(value: float, se: float | None, fmt: str) -> str:
    return format(value, fmt) + ("" if se is None else f" ± {format(se, fmt)}")
