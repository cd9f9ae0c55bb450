"""Page 3: the straights' measured length, each spin's angle, and without a length the
scale reference (the sensors' CPI or the spins against the configured mounts)."""

from __future__ import annotations

import math

from PySide6.QtWidgets import (
    QComboBox,
    QFormLayout,
    QLineEdit,
    QWidget,
    QWizardPage,
)

from mm_pc.monitor.widgets.calibration_wizard.choices import (
    SCALE_CHOICES,
)
from mm_pc.monitor.widgets.calibration_wizard.entries import parse_spin_angle, parse_true_distance
from mm_pc.monitor.widgets.calibration_wizard.table_helpers import (
    error_label,
)


class DistancePage(QWizardPage):
    """The straights' true length (cm, optional: gives the scales) and each spin's angle."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setTitle("Distance and spin angle")
        self.setSubTitle("If you measured how far each straight went, enter it: the scales "
                         "become true / measured (empty: the sensors' mean Y scale stays 1). "
                         "Each spin turned this far (empty: 360 deg, one full turn).")
        self.edit = QLineEdit()
        self.edit.setPlaceholderText("empty = scale from the sensors")
        self.edit.setToolTip("the measured length of each straight in cm (e.g. 100); empty "
                             "keeps the sensors' mean Y scale at 1")
        self.spin_edit = QLineEdit()
        self.spin_edit.setPlaceholderText("empty = 360")
        self.spin_edit.setToolTip("how far each spin turned, in degrees (360 = one full turn)")
        self.scale_box = QComboBox()
        for text, ref in SCALE_CHOICES:
            self.scale_box.addItem(text, ref)
        self.scale_box.setToolTip(
            "<p>Without a measured length the straights and spins fix only scale times "
            "position. <b>The sensors' CPI</b>: distances as the sensors count them (often a "
            "few % off). <b>The spins and the configured mounts</b>: a spin of the entered "
            "angle moves each sensor by angle x its distance from the axle centre, so with "
            "the mount positions you entered (geometry) the spins give the scale: as good "
            "as your measurement of the mounts (1 mm: about 1 %).</p>")
        self.error = error_label()
        self.true_distance: float | None = None
        self.spin_angle = 2 * math.pi
        self.scale_reference = "sensors"
        form = QFormLayout(self)
        form.addRow("True distance of each straight (cm)", self.edit)
        form.addRow("Angle of each spin (deg)", self.spin_edit)
        form.addRow("Without a distance, scale from", self.scale_box)
        form.addRow(self.error)

    def validatePage(self) -> bool:  # noqa: N802 - Qt API
        try:
            self.true_distance = parse_true_distance(self.edit.text())
            self.spin_angle = parse_spin_angle(self.spin_edit.text())
            self.scale_reference = str(self.scale_box.currentData())
        except ValueError as e:
            self.error.setText(str(e))
            self.error.show()
            return False
        self.error.hide()
        return True
