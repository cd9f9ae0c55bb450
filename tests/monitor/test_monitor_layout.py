"""Every view at 1024x700 and 800x600: the window fits the screen, no text is cut off.

The real MainWindow (offscreen Qt, no node) fed by the simulated figure eight; at each
size every tab is shown in turn and every visible label, button, combo box, line-edit
placeholder, table header and cell and the status bar's message is measured: its text
must fit the width it has (font metrics), or be elided ("…") with the whole text in a
tooltip, or wrap.
"""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")

from PySide6.QtCore import QRect, Qt
from PySide6.QtWidgets import (
    QAbstractButton,
    QAbstractScrollArea,
    QBoxLayout,
    QComboBox,
    QFormLayout,
    QGraphicsView,
    QGridLayout,
    QLabel,
    QLineEdit,
    QStatusBar,
    QStyle,
    QStyleOptionComboBox,
    QTableView,
    QWidget,
)

from mm_pc.core.calibration import Calibration, SensorCalibration
from mm_pc.monitor.context import MonitorConfig, MonitorContext
from mm_pc.monitor.main_window import MainWindow
from mm_pc.monitor.model.session import MonitorSession

ELLIPSIS = "…"
#: the end-of-replay summary, the longest message the status bar shows
REPLAY_SUMMARY = (
    "replay of run.mcap ended: 801 of 801 replies; pose from 16020 single polls, "
    "0 replies per reply, 0 gap(s); live data waits for Back to live"
)
SIZES = ((1024, 700), (800, 600))


def _plain(text: str) -> str:
    from PySide6.QtGui import QTextDocument

    if "<" in text and ">" in text:
        doc = QTextDocument()
        doc.setHtml(text)
        return doc.toPlainText()
    return text


def _elided_ok(shown: str, tooltip: str) -> bool:
    """Elided on purpose: the text ends (or is cut) with "…" and the tooltip has the rest."""
    return ELLIPSIS in shown and bool(tooltip.strip())


def _widest_line(fm, text: str) -> int:
    return max((fm.horizontalAdvance(line) for line in text.replace("&&", "&").split("\n")),
               default=0)


def _visible(w: QWidget, window: QWidget) -> bool:
    """Shown and on screen (a scroll area's opaque viewport hides the area's own region)."""
    if not (w.isVisibleTo(window) and w.isVisible()):
        return False
    port = w.viewport() if isinstance(w, QAbstractScrollArea) else None
    return not w.visibleRegion().isEmpty() or (port is not None
                                               and not port.visibleRegion().isEmpty())


def _label_problem(label: QLabel) -> str | None:
    text = _plain(label.text())
    if not text.strip() or (label.pixmap() is not None and not label.pixmap().isNull()):
        return None
    if _elided_ok(text, label.toolTip()):
        return None
    room = label.contentsRect().width() - 2 * max(label.margin(), 0) - max(label.indent(), 0)
    if label.wordWrap():  # each word must fit, and every line must be shown
        words = text.split()
        word = max(words, key=label.fontMetrics().horizontalAdvance)
        need = label.fontMetrics().horizontalAdvance(word)
        if need > room:
            return f"wrapped label {text!r}: the word {word!r} needs {need} px in {room} px"
        tall = label.heightForWidth(label.width())
        if tall > label.height() + 1:
            return f"wrapped label {text!r}: {tall} px high in {label.height()} px"
        return None
    need = _widest_line(label.fontMetrics(), text)
    return None if need <= room else f"label {text!r}: {need} px in {room} px"


def _button_problem(button: QAbstractButton) -> str | None:
    text = button.text().replace("&", "")
    if not text.strip() or _elided_ok(text, button.toolTip()):
        return None
    need = button.fontMetrics().horizontalAdvance(text)
    if not button.icon().isNull():
        need += button.iconSize().width() + 4
    room = button.width() - 8  # the style's frame and margins (about 4 px a side)
    return None if need <= room else f"button {text!r}: {need} px in {room} px"


def _combo_problem(box: QComboBox) -> str | None:
    """The widest item must fit: the user may pick any of them."""
    items = [box.itemText(i) for i in range(box.count())]
    text = max(items, key=box.fontMetrics().horizontalAdvance, default="")
    if not text:
        return None
    opt = QStyleOptionComboBox()
    box.initStyleOption(opt)
    field: QRect = box.style().subControlRect(
        QStyle.CC_ComboBox, opt, QStyle.SC_ComboBoxEditField, box
    )
    need = box.fontMetrics().horizontalAdvance(text)
    return None if need <= field.width() else f"combo {text!r}: {need} px in {field.width()} px"


def _line_edit_problem(edit: QLineEdit) -> str | None:
    """A placeholder (it cannot be scrolled) or the text of a read-only field must fit;
    what the user typed (or may edit, a file path) scrolls with the cursor, as in every
    Qt field."""
    if isinstance(edit.parent(), QComboBox):
        return None
    if edit.text() and not edit.isReadOnly():
        return None
    text = edit.text() or edit.placeholderText()
    if not text:
        return None
    m = edit.textMargins()
    room = edit.contentsRect().width() - m.left() - m.right() - 6  # the frame's padding
    need = edit.fontMetrics().horizontalAdvance(text)
    what = "field" if edit.text() else "placeholder"
    return None if need <= room else f"{what} {text!r}: {need} px in {room} px"


def _table_problems(table: QTableView) -> list[str]:
    model = table.model()
    if model is None:
        return []
    out = []
    fm = table.fontMetrics()
    header = table.horizontalHeader()
    hfm = header.fontMetrics()
    last_row = min(model.rowCount(), 50)
    for col in range(model.columnCount()):
        if table.isColumnHidden(col):
            continue
        width = table.columnWidth(col)
        title = str(model.headerData(col, Qt.Horizontal, Qt.DisplayRole) or "")
        tip = str(model.headerData(col, Qt.Horizontal, Qt.ToolTipRole) or "")
        if header.isVisible() and title and not _elided_ok(title, tip):
            need = _widest_line(hfm, title) + 8  # the section's margins (4 px a side)
            if need > width:
                out.append(f"header {title!r}: {need} px in {width} px")
        for row in range(last_row):
            idx = model.index(row, col)
            text = model.data(idx, Qt.DisplayRole)
            if text is None:
                continue
            text = str(text)
            need = fm.horizontalAdvance(text) + 6  # the cell's margins
            if need > width and not model.data(idx, Qt.ToolTipRole):
                out.append(f"cell {title!r} {text!r}: {need} px in {width} px")
                break
    return out


def _legend_problems(view: QGraphicsView) -> list[str]:
    """A pyqtgraph legend's names end inside the legend's column (or the view)."""
    import pyqtgraph as pg

    out = []
    for item in view.items():
        if not isinstance(item, pg.LegendItem) or not item.isVisible():
            continue
        box = item.parentItem()
        edge = (box.sceneBoundingRect().right() if box is not None
                else view.viewport().width())
        edge = min(edge, view.viewport().width())
        for _sample, label in item.items:
            if not label.isVisible():
                continue
            right = label.item.sceneBoundingRect().right()
            if right > edge + 1:
                out.append(f"legend {label.text!r}: ends at {right:.0f} px, room to {edge:.0f}")
    return out


def _overlaps(host: QWidget) -> list[str]:
    """Widgets of one box/grid/form layout drawn over each other (a layout squeezed
    below what its items need: the Health table over the labels under it)."""
    lay = host.layout()
    if not isinstance(lay, (QBoxLayout, QGridLayout, QFormLayout)):
        return []
    shown = [w for w in host.children()
             if isinstance(w, QWidget) and w.isVisible() and lay.indexOf(w) >= 0
             and not w.isWindow()]
    out = []
    for i, a in enumerate(shown):
        for b in shown[i + 1:]:
            both = a.geometry().intersected(b.geometry())
            if both.width() > 1 and both.height() > 1:
                out.append(f"{_path(a)} overlaps {_path(b)} by {both.width()}x{both.height()} px")
    return out


def clipped_texts(window: QWidget) -> list[str]:
    """What the shown widgets of ``window`` cut off, one line each."""
    found: list[str] = []
    for w in window.findChildren(QWidget):
        if not _visible(w, window):
            continue
        problem = None
        if isinstance(w, QLabel):
            problem = _label_problem(w)
        elif isinstance(w, QAbstractButton) and w.metaObject().className() in (
            "QPushButton", "QCheckBox", "QRadioButton", "QToolButton"
        ) and not (w.metaObject().className() == "QToolButton" and w.autoRaise()):
            problem = _button_problem(w)
        elif isinstance(w, QComboBox):
            problem = _combo_problem(w)
        elif isinstance(w, QLineEdit):
            problem = _line_edit_problem(w)
        elif isinstance(w, QTableView):
            found += [f"{type(w).__name__}: {p}" for p in _table_problems(w)]
        elif isinstance(w, QGraphicsView):
            found += [f"{type(w).__name__}: {p}" for p in _legend_problems(w)]
        if problem:
            found.append(f"{type(w.window()).__name__}/{_path(w)}: {problem}")
        found += _overlaps(w)
    bar = window.statusBar() if hasattr(window, "statusBar") else None  # a dialog has none
    if bar is None:
        return found
    shown = QStatusBar.currentMessage(bar)  # what is drawn (the bar may elide it)
    if shown and not _elided_ok(shown, bar.toolTip()):
        room = bar.width() - sum(
            c.width() for c in bar.findChildren(QLabel) if c.isVisible()
        ) - 12
        need = bar.fontMetrics().horizontalAdvance(shown)
        if need > room:
            found.append(f"status bar message: {need} px in {room} px")
    return found


def _path(w: QWidget) -> str:
    names = []
    while w is not None and len(names) < 3:
        names.append(w.objectName() or type(w).__name__)
        w = w.parentWidget()
    return "/".join(reversed(names))


@pytest.fixture
def window(qapp, feed, tmp_path):
    config = MonitorConfig(rate_hz=15.0, calibration_file=tmp_path / "cal.yaml")
    w = MainWindow(MonitorContext(MonitorSession(), None, config), None)
    feed(w.ctx, rate_hz=50.0, seconds=3.0)
    # a whole-mount calibration from the default file: the Pose panel's longest summary
    cal = Calibration({dev: SensorCalibration(angle_offset=-0.0123, scale_x=1.0123,
                                              scale_y=0.9876, x=0.049, y=-0.0395 * (1 - 2 * k))
                       for k, dev in enumerate(w.ctx.session.devices)},
                      method="", date="2026-12-03T17:30:00")
    w.ctx.set_calibration(cal, "/home/someone/.config/mouse-monitor/calibration.yaml")
    w.show()
    yield w
    w.close()


def settle(qapp, w, rounds: int = 4) -> None:
    for _ in range(rounds):
        w.frame()
        qapp.processEvents()


def DIAGNOSTICS(w) -> dict:  # noqa: N802 - a constant's shape, made per window
    """A /diagnostics round as the bridge hands it over: a WARN with its message."""
    return {dev: {"level": "1", "state": "up", "polls_per_s": "1000.2",
                  "message": "late polls: 12 % of the reads came late", "last_error": ""}
            for dev in w.ctx.session.devices}


class _StoppedReplay:
    """What the replay bar reads of a replayer: a 25 s recording stopped at 12.5 s."""

    def __init__(self) -> None:
        from PySide6.QtCore import QObject, Signal

        class _Signals(QObject):
            finished = Signal()

        self._signals = _Signals()
        self.finished = self._signals.finished
        self.total_s, self.played_s, self.speed = 25.0, 12.5, 1.0
        self.replies, self.position = [None] * 100, 50
        self.done, self.running, self.seeking = True, False, False


def _show_replay_bar(w) -> None:
    """The replay bar of a stopped replay (its widest state: Back to live shown)."""
    from mm_pc.monitor.replay import replay_bar

    replay_bar(w).attach(_StoppedReplay(), "2026-12-03-figure-eight-at-500-hz.mcap", True,
                         ("0.5x", "1x", "2x", "5x", "max"), "1x")


def _fill_debug(w) -> None:
    """Manual samples and fetched polls on the Debug tab (its table and legends)."""
    import numpy as np

    from mm_pc.monitor.model.sim_feed import sim_replies

    debug = w.views["Debug"]
    for r in list(sim_replies("figure_eight", 20, seconds=1))[:4]:
        debug.add_manual_reply(r)

    class Polls:
        first_seq, next_seq, dropped, cpi = 4000, 4300, 0, 1600
        dx = dy = np.arange(300) % 5
        flags = np.zeros(300, dtype=np.int64)
        stamp_ns = 1_700_000_000_000_000_000 + np.arange(300) * 1_000_000

    for dev in w.ctx.session.devices:
        debug.on_samples(dev, Polls())


def _walk(qapp, w, size) -> dict[str, list[str]]:
    w.resize(*size)
    settle(qapp, w)
    _show_replay_bar(w)
    _fill_debug(w)
    w.statusBar().showMessage(REPLAY_SUMMARY)
    w.views["Health"].on_diagnostics(DIAGNOSTICS(w))
    maps = w.views["Maps"]
    maps.progress.show()  # what "Simulate mowing run" shows while it builds
    maps.cancel_button.show()
    maps.source = "sim"  # the simulated run's view (its legend), without running one
    maps._show_source()
    per_tab = {}
    for i in range(w.tabs.count()):
        w.tabs.setCurrentIndex(i)
        settle(qapp, w)
        per_tab[w.tabs.tabText(i)] = clipped_texts(w)
    return per_tab


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_no_text_is_cut_off_on_any_tab(window, qapp, size):
    per_tab = _walk(qapp, window, size)
    report = [f"{tab}: {p}" for tab, problems in per_tab.items() for p in problems]
    print(f"{size}: {len(report)} clipped texts")
    assert not report, "\n".join(report)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_map_keeps_a_usable_size_and_graphs_scroll(window, qapp, size):
    window.resize(*size)
    settle(qapp, window)
    window.tabs.setCurrentIndex(0)
    settle(qapp, window)
    map_view, scroll = window.views["Map"], window.tabs.currentWidget()
    assert window.compact == (size[0] < 960)
    # the map's toolbar fits: no sideways scrolling, the map has most of the width
    assert map_view.minimumSizeHint().width() <= scroll.viewport().width()
    assert map_view.width() >= 0.55 * size[0], (map_view.width(), size)
    window.tabs.setCurrentIndex(6)  # Maps, building a run: its toolbar fits too
    maps = window.views["Maps"]
    maps.progress.show()
    maps.cancel_button.show()
    settle(qapp, window)
    assert maps.minimumSizeHint().width() <= window.tabs.currentWidget().viewport().width()
    window.tabs.setCurrentIndex(1)
    settle(qapp, window)
    graphs, scroll = window.views["Graphs"], window.tabs.currentWidget()
    assert len(graphs.plots) == 4  # two sensors, two plots each
    canvas = graphs.canvas
    for (k, key), plot in graphs.plots.items():  # sensor 2's plots are drawn inside the canvas
        right = plot.sceneBoundingRect().right()
        assert right <= canvas.viewport().width() + 1, (k, key, right, canvas.width())
    if graphs.width() > scroll.viewport().width():  # what does not fit scrolls
        assert scroll.horizontalScrollBar().maximum() > 0


def test_health_shows_the_message_row_at_1024_by_700(window, qapp):
    window.resize(1024, 700)
    health = window.views["Health"]
    health.on_diagnostics(DIAGNOSTICS(window))
    window.tabs.setCurrentIndex(window.tabs.indexOf(window.tabs.widget(5)))
    assert window.tabs.tabText(window.tabs.currentIndex()) == "Health"
    settle(qapp, window)
    table, page = health.table, window.tabs.currentWidget()
    last = table.rowCount() - 1
    assert table.verticalHeaderItem(last).text() == "Message"
    cell = table.visualRect(table.model().index(last, 0))
    assert cell.bottom() <= table.viewport().height(), (cell, table.viewport().height())
    bottom = table.viewport().mapTo(page.viewport(), cell.bottomLeft()).y()
    assert 0 <= bottom <= page.viewport().height(), (bottom, page.viewport().height())


def test_the_whole_window_fits_a_small_screen_at_first_start(qapp):
    from mm_pc.monitor import main_window

    avail = QRect(0, 0, 1024, 700 - 30)  # a 1024x700 screen less a panel
    assert main_window.first_size(avail, frame=(0, 30, 0, 0)) == (1024, 700 - 30 - 30)
    big = QRect(0, 0, 1600, 1000)
    assert main_window.first_size(big, frame=(4, 30, 4, 4)) == main_window.DEFAULT_SIZE


def test_narrow_windows_stack_the_docks_and_wide_ones_put_them_back(window, qapp):
    window.resize(800, 600)
    settle(qapp, window)
    assert window.compact
    assert window.dockWidgetArea(window.direction_dock) == Qt.LeftDockWidgetArea
    assert window.direction_dock.y() > window.control_dock.y()  # under it, both shown
    assert window.direction_dock.isVisible() and window.control_dock.isVisible()
    window.resize(1280, 800)
    settle(qapp, window)
    assert not window.compact
    assert window.dockWidgetArea(window.direction_dock) == Qt.RightDockWidgetArea
    window.resize(800, 600)
    settle(qapp, window)
    window.reset_layout()  # the default size on this screen, docks stacked if it is narrow
    settle(qapp, window)
    assert window.compact == (window.width() < 960)
    side = Qt.LeftDockWidgetArea if window.compact else Qt.RightDockWidgetArea
    assert window.dockWidgetArea(window.direction_dock) == side


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_a_calibration_put_in_force_after_start_is_shown_whole(window, qapp, size):
    """The Pose panel's calibration summary after Clear and a new calibration (the wizard's
    Save, Load…) while the window is shown: every line visible. In a real X window the
    form layout kept the one-line height of "none (identity)" and cut the summary."""
    window.resize(*size)
    settle(qapp, window)
    cal, source = window.ctx.session.calibration, window.ctx.calibration_source
    panel = window.calibration_panel
    panel.clear()
    settle(qapp, window)
    window.ctx.set_calibration(cal, source)
    settle(qapp, window)
    label = panel.label
    assert label.text().count("\n") >= 3  # the head, the file and a line per sensor
    assert label.height() >= label.heightForWidth(label.width())
    assert not [p for p in clipped_texts(window) if "Calibration:" in p]
