"""Calibration wizard: the whole mount of every sensor from a guided run.

Pages: (1) instructions; (2) record -- explicit steps, each between Start
(straight or spin) and Stop: the session keeps the raw (unfiltered,
uncalibrated) displacements of every interval of the step, nothing after
Stop; the map keeps drawing the robot meanwhile (calibration in force). Live
residuals (distance, how far the path left a line, the spin angle) and a
pass/fail per step: a step whose motion does not fit its kind (a spin that
moved, a straight that turned) is stopped at once with the reason, and no
step starts until the failed one is discarded. With ``mm-monitor --sim
calibration_run`` the page drives the run itself (:class:`AutoDrive`, which
presses Start/Stop per recorded interval). Next once a straight and a spin
passed, every step passed and nothing records; (3) the straights' measured length (optional)
and the angle of each spin; (4) results per sensor with their standard
errors and the predicted heading drift per metre (the whole-mount fit,
``MonitorSession.compute_calibration``), the seed's straight-run angle next
to it, the sim's true mounts when known, and which of the two to use; a
refused run is shown with what to do and changes nothing; (5) save: the YAML
file (``Calibration.save``) and the calibration in force
(``MonitorContext.set_calibration``), then an offer to restart the path.

Cancel (or closing the window) at any time ends the run with the old
calibration still in force (``finish_calibration(None)``); Finish applies the
computed calibration (Save also writes it to the file). The math:
:mod:`mm_pc.core.calibration_fit`; units shown are cm, mm and degrees, kept
in metres and radians.

One module per page (intro_page, drive_page, distance_page, results_page,
save_page), the wizard that strings them together (wizard), what they share
(choices: page ids and choices; entries: the distance page's parsing;
table_helpers). Import from the package: the names below.
"""

from mm_pc.monitor.widgets.calibration_wizard.choices import (
    FOLDER_KIND,
    PAGE_DISTANCE,
    PAGE_DRIVE,
    PAGE_INTRO,
    PAGE_RESULTS,
    PAGE_SAVE,
    SCALE_CHOICES,
    USE_FIT,
    USE_STRAIGHT_RUN,
)
from mm_pc.monitor.widgets.calibration_wizard.entries import parse_spin_angle, parse_true_distance
from mm_pc.monitor.widgets.calibration_wizard.wizard import CalibrationWizard

__all__ = [
    "FOLDER_KIND",
    "PAGE_DISTANCE",
    "PAGE_DRIVE",
    "PAGE_INTRO",
    "PAGE_RESULTS",
    "PAGE_SAVE",
    "SCALE_CHOICES",
    "USE_FIT",
    "USE_STRAIGHT_RUN",
    "CalibrationWizard",
    "parse_spin_angle",
    "parse_true_distance",
]
