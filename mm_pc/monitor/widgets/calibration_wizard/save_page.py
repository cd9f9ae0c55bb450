"""Page 5: save the calibration to its YAML file and apply it; then offer to restart the
path from the calibrated pose."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWizardPage,
)

from mm_pc.monitor.settings import last_folder, remember_folder
from mm_pc.monitor.widgets.calibration_wizard.choices import (
    FOLDER_KIND,
    OK_STYLE,
)
from mm_pc.monitor.widgets.calibration_wizard.table_helpers import (
    error_label,
)

if TYPE_CHECKING:
    from mm_pc.monitor.widgets.calibration_wizard.wizard import CalibrationWizard


class SavePage(QWizardPage):
    """Path + Browse + Save (writes and applies); Finish applies without writing."""

    def __init__(self, wizard: CalibrationWizard) -> None:
        super().__init__(wizard)
        self._wizard = wizard
        self.setTitle("Save")
        self.setSubTitle("Save writes the file the monitor loads at start and puts the "
                         "calibration in force. Finish without saving uses it for this "
                         "session only.")
        self.path_edit = QLineEdit(str(wizard.ctx.config.calibration_file))
        self.path_edit.setToolTip("the monitor loads this file at start (default "
                                  "~/.config/mouse-monitor/calibration.yaml)")
        browse = QPushButton("Browse…")
        browse.clicked.connect(self._browse)
        self.save_button = QPushButton("Save")
        self.save_button.setToolTip("write the file and put the calibration in force")
        self.save_button.clicked.connect(lambda: self._wizard.save(self.path_edit.text()))
        row = QHBoxLayout()
        row.addWidget(self.path_edit, 1)
        row.addWidget(browse)
        row.addWidget(self.save_button)
        self.error = error_label()
        self.status = QLabel("")
        self.status.setStyleSheet(OK_STYLE)
        self.status.setWordWrap(True)
        self.restart_label = QLabel(
            "The map's path so far was drawn with the old calibration. Restart it here to "
            "draw the robot with the new one from the origin."
        )
        self.restart_label.setWordWrap(True)
        self.restart_button = QPushButton("Restart the path here")
        self.restart_button.setToolTip("clear the path and values; the pose starts again at "
                                       "the origin, with the new calibration")
        self.restart_button.clicked.connect(self.restart_path)
        self.restart_label.hide()
        self.restart_button.hide()
        lay = QVBoxLayout(self)
        lay.addWidget(QLabel("Calibration file (YAML)"))
        lay.addLayout(row)
        lay.addWidget(self.error)
        lay.addWidget(self.status)
        lay.addWidget(self.restart_label)
        lay.addWidget(self.restart_button, 0, Qt.AlignLeft)
        lay.addStretch(1)

    def offer_restart(self) -> None:
        """After the calibration is in force: offer to restart the path from here."""
        self.restart_label.show()
        self.restart_button.show()
        self.restart_button.setEnabled(True)

    def restart_path(self) -> None:
        """Restart the path and values (``MonitorContext.reset``): the pose from the origin
        with the new calibration."""
        self._wizard.ctx.reset()
        self.restart_button.setEnabled(False)
        self.restart_label.setText("path restarted: the robot is drawn with the new "
                                   "calibration from the origin")
        self._wizard.ctx.status_message.emit("path restarted with the new calibration")

    def _browse(self) -> None:
        """A save dialog in the folder the last calibration went to (never the repository)."""
        start = Path(last_folder(FOLDER_KIND)) / Path(self.path_edit.text()).name
        path, _ = QFileDialog.getSaveFileName(
            self, "Save calibration", str(start), "YAML (*.yaml *.yml)"
        )
        if path:
            self.path_edit.setText(path)
            remember_folder(FOLDER_KIND, path)
