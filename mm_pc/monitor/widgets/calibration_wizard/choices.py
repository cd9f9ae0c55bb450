"""The wizard's page ids and the choices its pages offer (no widgets)."""

from __future__ import annotations

OK_STYLE = "color: #1b7a1b"
#: the kind of file dialog (``settings.last_folder``) the Save page's Browse remembers
FOLDER_KIND = "calibration"
PAGE_INTRO, PAGE_DRIVE, PAGE_DISTANCE, PAGE_RESULTS, PAGE_SAVE = range(5)
USE_FIT, USE_STRAIGHT_RUN = "whole-mount fit", "straight-run formula (seed)"
#: The distance page's scale references without a measured length (text, fit_mounts' name).
SCALE_CHOICES = (
    ("the sensors' CPI", "sensors"),
    ("the spins and the configured mounts", "mounts"),
)
