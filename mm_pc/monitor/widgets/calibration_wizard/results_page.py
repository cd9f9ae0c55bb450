"""Page 4: the fitted mount per sensor (± one standard error), the predicted drift, what to
add for a better fit, the sim's true mounts when known, and which calibration to use."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QVBoxLayout,
    QWizardPage,
)

from mm_pc.core.calibration_fit import MountFit, fit_advice
from mm_pc.monitor.widgets.calibration_wizard.choices import (
    USE_FIT,
    USE_STRAIGHT_RUN,
)
from mm_pc.monitor.widgets.calibration_wizard.table_helpers import (
    error_label,
    make_table,
    plus_minus,
    set_row,
)

if TYPE_CHECKING:
    from mm_pc.monitor.widgets.calibration_wizard.wizard import CalibrationWizard


class ResultsPage(QWizardPage):
    """The fitted mount per sensor with standard errors, the drift, the seed's angle."""

    COLUMNS = ("Sensor", "Yaw (deg)", "Scale X", "Scale Y", "x (cm)", "y (cm)",
               "Straight-run angle (deg)", "Previous angle (deg)")
    TRUTH_COLUMNS = ("Sensor", "Yaw fitted (deg)", "Yaw true (deg)", "x fitted (cm)",
                     "x true (cm)", "y fitted (cm)", "y true (cm)")

    def __init__(self, wizard: CalibrationWizard) -> None:
        super().__init__(wizard)
        self._wizard = wizard
        self.setTitle("Results")
        self.setSubTitle("The fitted correction for each sensor (± one standard error; not "
                         "applied yet) and the seed's straight-run angle on the same straights.")
        self.table = make_table(list(self.COLUMNS))
        self.drift = QLabel("")
        self.drift.setWordWrap(True)
        self.advice = QLabel("")
        self.advice.setWordWrap(True)
        self.use_box = QComboBox()
        self.use_box.addItems([USE_FIT, USE_STRAIGHT_RUN])
        self.use_box.setToolTip("<p>whole-mount fit: angle, scales and position of every sensor "
                                "(recommended); straight-run formula: the original's angle "
                                "only, to compare</p>")
        self.use_box.currentTextChanged.connect(lambda _t: self._wizard.choose())
        self.error = error_label()
        row = QHBoxLayout()
        row.addWidget(QLabel("Use"))
        row.addWidget(self.use_box)
        row.addStretch(1)
        lay = QVBoxLayout(self)
        self.truth_label = QLabel("The sim's sensors are mounted with a known error: the "
                                  "fit next to the truth")
        self.truth_table = make_table(list(self.TRUTH_COLUMNS))
        lay.addWidget(self.table)
        lay.addWidget(self.truth_label)
        lay.addWidget(self.truth_table)
        lay.addWidget(self.drift)
        lay.addWidget(self.advice)
        lay.addLayout(row)
        lay.addWidget(self.error)
        self._show_truth(None)

    def initializePage(self) -> None:  # noqa: N802 - Qt API
        self._wizard.compute()
        fit = self._wizard.fit
        old = self._wizard.ctx.session.calibration
        if fit is None:
            self.table.setRowCount(0)
            self.drift.setText("")
            self.advice.setText("")
            self.error.setText(f"cannot calibrate: {self._wizard.compute_error}")
            self.error.show()
        else:
            self.error.hide()
            self.table.setRowCount(len(fit.devices))
            for k, (dev, c) in enumerate(zip(fit.devices, fit.sensors, strict=True)):
                se = c.angle_offset_se
                set_row(self.table, k, [
                    dev,
                    plus_minus(c.angle_offset_deg, None if se is None else math.degrees(se), ".3f"),
                    plus_minus(c.scale_x, c.scale_x_se, ".4f"),
                    plus_minus(c.scale_y, c.scale_y_se, ".4f"),
                    plus_minus(c.x * 100, None if c.x_se is None else c.x_se * 100, ".2f"),
                    plus_minus(c.y * 100, None if c.y_se is None else c.y_se * 100, ".2f"),
                    f"{fit.straight_run[dev].angle_offset_deg:.3f}",
                    f"{old.get(dev).angle_offset_deg:.3f}",
                ])
            parts = [f"{m}: {math.degrees(v):.3f} deg per metre"
                     for m, v in fit.drift_per_m.items()]
            self.drift.setText(
                "Predicted heading drift driving straight (1 sigma, from the fit's "
                "uncertainty): " + "; ".join(parts)
                + f". Method in use: {self._wizard.ctx.session.method}."
            )
            self.advice.setText(fit_advice(fit, self._wizard.ctx.session.method))
        self._show_truth(fit)
        self.completeChanged.emit()

    def _show_truth(self, fit: MountFit | None) -> None:
        """The fit next to the sim's true mounts (``MonitorConfig.sim_mounts``), if known:
        angle offset = true yaw - the geometry's yaw; positions in base_link."""
        ctx = self._wizard.ctx
        truth = ctx.config.sim_mounts
        shown = fit is not None and bool(truth) and len(truth) >= len(fit.devices)
        self.truth_label.setVisible(shown)
        self.truth_table.setVisible(shown)
        if not shown:
            return
        nominal = ctx.session.odometry_mounts
        cal = fit.calibration()
        self.truth_table.setRowCount(len(fit.devices))
        for k, dev in enumerate(fit.devices):
            c, t = cal[dev], truth[k]
            yaw_true = math.degrees(t.yaw - (nominal[k].yaw if k < len(nominal) else 0.0))
            x = c.x if c.position is not None else math.nan
            y = c.y if c.position is not None else math.nan
            set_row(self.truth_table, k, [
                dev,
                f"{c.angle_offset_deg:.3f}", f"{yaw_true:.3f}",
                f"{x * 100:.2f}", f"{t.x * 100:.2f}",
                f"{y * 100:.2f}", f"{t.y * 100:.2f}",
            ])
        # as tall as its rows: the page keeps its room for the drift and the choice
        table = self.truth_table
        table.resizeRowsToContents()
        rows = sum(table.rowHeight(r) for r in range(table.rowCount()))
        table.setMaximumHeight(table.horizontalHeader().sizeHint().height() + rows
                               + 2 * table.frameWidth() + table.horizontalScrollBar().sizeHint()
                               .height())

    def cleanupPage(self) -> None:  # noqa: N802 - Qt API
        self._wizard.calibration = None
        self._wizard.fit = None

    def isComplete(self) -> bool:  # noqa: N802 - Qt API
        return self._wizard.calibration is not None
