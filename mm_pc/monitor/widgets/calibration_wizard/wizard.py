"""The calibration wizard itself: its pages in order, the fit, the choice, save and apply
(the pages: the other modules of this package)."""

from __future__ import annotations

from contextlib import suppress
from pathlib import Path

from PySide6.QtWidgets import (
    QWidget,
    QWizard,
)

from mm_pc.core.calibration import Calibration
from mm_pc.core.calibration_fit import MountFit
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.settings import remember_folder
from mm_pc.monitor.widgets.calibration_wizard.choices import (
    FOLDER_KIND,
    PAGE_DISTANCE,
    PAGE_DRIVE,
    PAGE_INTRO,
    PAGE_RESULTS,
    PAGE_SAVE,
    USE_STRAIGHT_RUN,
)
from mm_pc.monitor.widgets.calibration_wizard.distance_page import DistancePage
from mm_pc.monitor.widgets.calibration_wizard.drive_page import DrivePage
from mm_pc.monitor.widgets.calibration_wizard.intro_page import IntroPage
from mm_pc.monitor.widgets.calibration_wizard.results_page import ResultsPage
from mm_pc.monitor.widgets.calibration_wizard.save_page import SavePage


class CalibrationWizard(QWizard):
    """The calibration wizard (a QDialog).

    ``fit``: the :class:`MountFit` of the run, or None; ``calibration``: the
    one chosen on the results page (the fit, or the seed's straight-run
    formula), or None.
    """

    def __init__(self, ctx: MonitorContext, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.setWindowTitle("Calibration wizard")
        self.setOption(QWizard.NoBackButtonOnStartPage, True)
        self.calibration: Calibration | None = None
        self.fit: MountFit | None = None
        self.compute_error = ""
        self.applied = False
        self._done = False
        self.intro_page = IntroPage(self)
        self.drive_page = DrivePage(ctx, self)
        self.distance_page = DistancePage(self)
        self.results_page = ResultsPage(self)
        self.save_page = SavePage(self)
        for pid, page in (
            (PAGE_INTRO, self.intro_page),
            (PAGE_DRIVE, self.drive_page),
            (PAGE_DISTANCE, self.distance_page),
            (PAGE_RESULTS, self.results_page),
            (PAGE_SAVE, self.save_page),
        ):
            self.setPage(pid, page)
        self.setStartId(PAGE_INTRO)
        self.resize(820, 560)

    def compute(self) -> Calibration | None:
        """Fit from the recorded steps (distance and spin angle of the pages); None on a
        refused run (``compute_error`` says why and what to do; nothing changes)."""
        try:
            page = self.distance_page
            self.fit = self.ctx.session.compute_calibration(
                page.true_distance, page.spin_angle, scale_reference=page.scale_reference
            )
            self.compute_error = ""
        except ValueError as e:
            self.fit = None
            self.calibration = None
            self.compute_error = str(e)
            return None
        return self.choose()

    def choose(self) -> Calibration | None:
        """The calibration of the method picked on the results page."""
        if self.fit is None:
            self.calibration = None
        elif self.results_page.use_box.currentText() == USE_STRAIGHT_RUN:
            self.calibration = self.fit.straight_run
        else:
            self.calibration = self.fit.calibration()
        return self.calibration

    def save(self, path: str | Path) -> bool:
        """Write the computed calibration to ``path`` and apply it; False (nothing applied,
        message on the page) if it cannot be written."""
        page = self.save_page
        cal = self.calibration
        if cal is None:
            page.error.setText("nothing to save: no calibration was computed")
            page.error.show()
            return False
        path = Path(str(path).strip()).expanduser()
        try:
            if not str(path) or path.is_dir():
                raise OSError(f"{str(path)!r} is not a file name")
            path.parent.mkdir(parents=True, exist_ok=True)
            cal.save(path)
        except OSError as e:
            page.error.setText(f"not saved and not applied: {e}")
            page.error.show()
            page.status.setText("")
            return False
        page.error.hide()
        remember_folder(FOLDER_KIND, path)
        self._apply(cal, str(path))
        page.status.setText(f"saved to {path} and applied")
        page.offer_restart()
        return True

    def _apply(self, cal: Calibration, source: str = "") -> None:
        self.ctx.session.finish_calibration(cal)
        self.ctx.set_calibration(cal, source or "calibration wizard (not saved)")
        self.applied = True
        self.ctx.status_message.emit("new calibration in force")

    def done(self, result: int) -> None:
        """Finish applies the result; Cancel/close ends the run with the old calibration."""
        if result == QWizard.Accepted and not self.validateCurrentPage():
            return
        if not self._done:
            self._done = True
            if result == QWizard.Accepted and self.calibration is not None:
                if not self.applied:
                    self._apply(self.calibration)
            elif self.ctx.session.calibrating:
                self.ctx.session.finish_calibration(None)
                self.ctx.status_message.emit("calibration cancelled; the old one stays")
            # a closed wizard stays a child of the window: stop listening to every reply
            for signal in (self.ctx.reply_processed, self.ctx.devices_known):
                with suppress(RuntimeError, TypeError):
                    signal.disconnect(self.drive_page.update_sums)
        super().done(result)
