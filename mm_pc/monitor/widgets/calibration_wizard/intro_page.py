"""Page 1: what the guided run is and how to record it."""

from __future__ import annotations

from PySide6.QtWidgets import (
    QLabel,
    QVBoxLayout,
    QWidget,
    QWizardPage,
)


class IntroPage(QWizardPage):
    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setTitle("Calibrate the sensors")
        text = QLabel(
            "<p>The wizard fits, for every sensor at once, its mounting angle, its X and Y "
            "scale and where it sits relative to the turning centre, from a guided run:</p>"
            "<ol><li>Mark a straight line (a ruler or a wall edge) and, if you can, its "
            "length (1&nbsp;m is good).</li>"
            "<li>Press <b>Start straight</b>, push the robot <b>straight forward</b> along "
            "the edge, stop it, press <b>Stop</b>. Then the same <b>back</b>. Twice is "
            "better than once.</li>"
            "<li>Press <b>Start spin</b>, turn the robot <b>on the spot one full turn</b> "
            "(back to where it pointed), press <b>Stop</b>. Once left, once right, twice "
            "each is better.</li></ol>"
            "<p>Each step shows its residuals and passes or fails; a step that cannot be "
            "what you pressed (a spin that moved, a straight that turned) stops at once "
            "with the reason. Discard the failed step and record it again. The map keeps "
            "drawing the robot with the old calibration. Cancel at any time keeps the old "
            "calibration.</p>"
            "<p>How long? One 0.5&nbsp;m straight forward and back with a turn each way "
            "leaves about 0.3&deg; of heading per metre driven (3&deg; after 10&nbsp;m); "
            "straights four times as long halve it. Without a measured length, distances "
            "keep the sensors' own scale (often a few % off). The results page says what "
            "to add.</p>"
            "<p>With <tt>mm-monitor --sim calibration_run</tt> the next page can drive "
            "the whole run for you.</p>"
        )
        text.setWordWrap(True)
        QVBoxLayout(self).addWidget(text)
