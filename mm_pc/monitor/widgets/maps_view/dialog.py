""""New map…": the settings of a new live coverage map.

Every field is checked before anything changes; the view adopts the map on success.
"""

from __future__ import annotations

from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QVBoxLayout,
    QWidget,
)

from mm_pc.core.maps.coverage_map import (
    CoverageMap,
)
from mm_pc.monitor.model.maps import FILLS, MAX_CELLS, MAX_SIDE_CELLS, MapSettings, make_map
from mm_pc.monitor.widgets.style import ERROR_STYLE, parse_number

__all__ = ["NewMapDialog"]

# --- "New map…" ------------------------------------------------------------------------------



def _parse_positive(text: str, what: str) -> float:
    v = parse_number(text, what)
    if v <= 0:
        raise ValueError(f"{what} must be > 0, got {text.strip()}")
    return v


def _parse_cells(text: str, what: str) -> int:
    try:
        n = int(text.strip())
    except ValueError:
        raise ValueError(f"{what} must be a whole number of cells, got {text!r}") from None
    if not 1 <= n <= MAX_SIDE_CELLS:
        raise ValueError(f"{what} must be 1..{MAX_SIDE_CELLS} cells, got {n}")
    return n


class _Field(QWidget):
    """A line edit with a red error label under it (beside it, a long reason was squeezed
    into a sliver of the dialog's width)."""

    def __init__(self, text: str, tip: str) -> None:
        super().__init__()
        self.edit = QLineEdit(text)
        self.edit.setToolTip(tip)
        self.edit.setMaximumWidth(90)
        self.error = QLabel("")
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setWordWrap(True)
        self.error.hide()
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(2)
        lay.addWidget(self.edit)
        lay.addWidget(self.error)

    def set_error(self, message: str) -> None:
        self.error.setText(message)
        self.error.setVisible(bool(message))


class NewMapDialog(QDialog):
    """Settings of a new live coverage map; "Create" validates them.

    Bad input leaves the dialog open with a red message beside the field and
    does not touch the view's map. On success :attr:`map` and :attr:`settings`
    hold the new map and the view adopts it (:meth:`MapsView.set_live_map`).
    """

    def __init__(self, view: QWidget, parent: QWidget | None = None) -> None:
        # view: the MapsView that adopts the new map
        super().__init__(parent or view)
        self.view = view
        self.setWindowTitle("New coverage map")
        self.map: CoverageMap | None = None
        self.settings: MapSettings | None = None
        cur = view.live_settings
        ny, nx = cur.shape
        rect = cur.rect or (-7.5, -5.0, 15.0, 10.0)
        self.fields = {
            "cell": _Field(f"{cur.cell_size:g}", "edge of a square cell, m (> 0; seed: 0.3)"),
            "ny": _Field(str(ny), f"rows along y (north), 1..{MAX_SIDE_CELLS}"),
            "nx": _Field(str(nx), f"columns along x (east), 1..{MAX_SIDE_CELLS}"),
            "x0": _Field(f"{cur.origin[0]:g}", "x of the map's south-west corner, m (odom frame)"),
            "y0": _Field(f"{cur.origin[1]:g}", "y of the map's south-west corner, m (odom frame)"),
            "rx": _Field(f"{rect[0]:g}", "x of the rectangle's south-west corner, m"),
            "ry": _Field(f"{rect[1]:g}", "y of the rectangle's south-west corner, m"),
            "rw": _Field(f"{rect[2]:g}", "rectangle width along x, m (> 0)"),
            "rh": _Field(f"{rect[3]:g}", "rectangle height along y, m (> 0)"),
        }
        self.fill_box = QComboBox()
        for key, text in FILLS.items():
            self.fill_box.addItem(text, key)
        self.fill_box.setCurrentIndex(list(FILLS).index(cur.fill))
        self.fill_box.currentIndexChanged.connect(self._fill_changed)
        self.fill_error = QLabel("")
        self.fill_error.setStyleSheet(ERROR_STYLE)
        self.fill_error.setWordWrap(True)
        self.fill_error.hide()

        form = QFormLayout(self)
        f = self.fields
        form.addRow("Cell size (m)", f["cell"])
        form.addRow("Rows ny (along y)", f["ny"])
        form.addRow("Columns nx (along x)", f["nx"])
        form.addRow("Origin x0 (m)", f["x0"])
        form.addRow("Origin y0 (m)", f["y0"])
        form.addRow("Contents", self.fill_box)
        form.addRow("Perimeter corner x (m)", f["rx"])
        form.addRow("Perimeter corner y (m)", f["ry"])
        form.addRow("Perimeter width (m)", f["rw"])
        form.addRow("Perimeter height (m)", f["rh"])
        form.addRow(self.fill_error)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Cancel)
        self.create_button = buttons.addButton("Create", QDialogButtonBox.ButtonRole.AcceptRole)
        buttons.accepted.connect(self.apply)
        buttons.rejected.connect(self.reject)
        form.addRow(buttons)
        # Enter = Create (a refusal keeps the dialog open); set once inside the dialog, and
        # Cancel never default (before, Enter with a bad field closed the dialog silently)
        buttons.button(QDialogButtonBox.StandardButton.Cancel).setAutoDefault(False)
        self.create_button.setDefault(True)
        self._fill_changed()

    def _fit_height(self) -> None:
        """Grow so that every wrapped refusal shows whole."""
        self.layout().activate()
        need = self.layout().totalHeightForWidth(self.width())
        if need > self.height():
            self.resize(self.width(), need)

    @property
    def fill(self) -> str:
        return self.fill_box.currentData()

    def set_fill(self, fill: str) -> None:
        self.fill_box.setCurrentIndex(list(FILLS).index(fill))

    def _fill_changed(self, *_args) -> None:
        for key in ("rx", "ry", "rw", "rh"):
            self.fields[key].setEnabled(self.fill == "rectangle")

    def _read(self) -> MapSettings | None:
        """The typed settings, or None with every field's message shown."""
        parsers = {
            "cell": (_parse_positive, "cell size (m)"),
            "ny": (_parse_cells, "rows ny"),
            "nx": (_parse_cells, "columns nx"),
            "x0": (parse_number, "origin x0 (m)"),
            "y0": (parse_number, "origin y0 (m)"),
        }
        if self.fill == "rectangle":
            parsers |= {
                "rx": (parse_number, "corner x (m)"),
                "ry": (parse_number, "corner y (m)"),
                "rw": (_parse_positive, "width (m)"),
                "rh": (_parse_positive, "height (m)"),
            }
        values: dict[str, float] = {}
        for key, field in self.fields.items():
            field.set_error("")
            if key in parsers:
                parse, what = parsers[key]
                try:
                    values[key] = parse(field.edit.text(), what)
                except ValueError as e:
                    field.set_error(str(e))
        if len(values) < len(parsers):
            return None
        ny, nx = int(values["ny"]), int(values["nx"])
        if ny * nx > MAX_CELLS:
            self.fields["nx"].set_error(
                f"ny x nx = {ny * nx} cells; at most {MAX_CELLS} (use larger cells)"
            )
            return None
        rect = None
        if self.fill == "rectangle":
            rect = (values["rx"], values["ry"], values["rw"], values["rh"])
        return MapSettings(values["cell"], (ny, nx), (values["x0"], values["y0"]), self.fill, rect)

    def apply(self) -> bool:
        """Validate and create the map; False (messages shown, view unchanged) on bad input."""
        self.fill_error.hide()
        settings = self._read()
        if settings is None:
            self._fit_height()
            return False
        try:
            cmap = make_map(settings)
        except ValueError as e:
            self.fill_error.setText(f"map not created: {e}")
            self.fill_error.show()
            self._fit_height()
            return False
        self.map, self.settings = cmap, settings
        self.view.set_live_map(cmap, settings)
        self.accept()
        return True
