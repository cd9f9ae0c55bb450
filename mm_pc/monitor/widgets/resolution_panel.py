"""Resolution (CPI) of each sensor: set it on the node and show what the node read back.

The typed value is checked here first, by the chip's range (for a PLN2033 the registry's,
:func:`pln2033.chips.chip_info`: 100..6400 in steps of 100, the range the seed names;
a node with its own register map may allow less and says so); a refused value is
explained next to its field and never sent. An accepted value goes to the node's
``set_resolution``; its answer (the CPI read back from the sensor, or the node's reason
for refusing) appears next to the field when the bridge reports it. The CPI in force is
also shown from the newest reply.

Other chips (issue 15): each sensor's chip comes with every reply (``SensorData.chip``);
its own range is checked instead (``SensorSettings`` cpi_min/max/step once the Registers
view has read them, until then the registry's :func:`pln2033.chips.chip_info`). A chip
whose resolution cannot be set (the PMW3901/PAA5100 optical-flow sensors: it follows
their height above the floor) gets its field and Set button disabled, the tooltip
saying why and what to do instead (calibrate the scale, docs/pose-math.md).
"""

from __future__ import annotations

import time

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import (
    QGridLayout,
    QGroupBox,
    QLabel,
    QLineEdit,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
)

from mm_pc.monitor.model.chips import chip_key, chip_title, cpi_range
from mm_pc.monitor.widgets.style import ERROR_STYLE
from pln2033.chips import DEFAULT_CHIP, chip_info
from pln2033.sensor import CpiRange

__all__ = ["CPI_MAX", "CPI_MIN", "CPI_STEP", "ResolutionPanel", "validate_cpi"]

#: how often (ms) the panel looks for a new CPI in the history
REFRESH_MS = 200
#: a refusal stays beside its field this long (s), or until the next change succeeds
ERROR_SHOW_S = 15.0

_DEFAULT_CPI = chip_info(DEFAULT_CHIP).cpi  # an old node names no chip: a PLN2033
CPI_MIN, CPI_MAX, CPI_STEP = _DEFAULT_CPI.min, _DEFAULT_CPI.max, _DEFAULT_CPI.step
ALLOWED = f"allowed: {CPI_MIN}..{CPI_MAX} in steps of {CPI_STEP}"
RED = ERROR_STYLE
#: chips whose resolution follows their height (the optical-flow sensors)
OPTICAL_FLOW = ("pmw3901", "paa5100")


def fixed_tip(chip: str, cpi: int | None = None) -> str:
    """Why a fixed-resolution chip's field is disabled, and what to do instead."""
    now = f" ({cpi} CPI now)" if cpi else ""
    if chip_key(chip) in OPTICAL_FLOW:
        return (
            f"the {chip_title(chip)} has a fixed resolution{now}: it follows the sensor's "
            "height above the floor, not a register. Set the height in the node's options "
            "and calibrate the sensor's scale (docs/pose-math.md, optical-flow sensors)."
        )
    return (
        f"the {chip_title(chip)} has a fixed resolution{now}: its driver reports motion at "
        "that rate and there is nothing to set. Calibrate the sensor's scale instead "
        "(docs/pose-math.md; the OTOS: docs/sensors.md)."
    )


def validate_cpi(value, allowed: CpiRange | None = None, chip: str = "") -> int:
    """The CPI in ``value`` (text or number); ValueError saying what is allowed otherwise.

    ``allowed``: the chip's range (default: the registry's range of ``chip``; '' = an old
    node: a PLN2033; a chip not known here has none, and only the node checks the range);
    ``chip``: its name, for the message."""
    text = str(value).strip()
    if allowed is None:
        allowed = cpi_range(chip)
    title = chip_title(chip)
    what = f"{title} allows {allowed.describe()}" if allowed else "the node checks the range"
    if not text:
        raise ValueError(f"the CPI field is empty: type a whole number ({what})")
    try:
        cpi = int(text)
    except ValueError:
        raise ValueError(f"CPI must be a whole number, got {text!r} ({what})") from None
    problem = allowed.problem(cpi, title) if allowed is not None else None
    if problem:
        raise ValueError(problem)
    return cpi


class _SensorRow:
    """The widgets of one sensor: field, Set, CPI in force, read-back and error labels."""

    def __init__(self, device: str) -> None:
        self.device = device
        self.edit = QLineEdit()
        self._placeholder(f"{CPI_MIN}..{CPI_MAX}")
        self.edit.setToolTip(f"counts per inch of both axes, {ALLOWED} (Enter sets)")
        self.set_button = QPushButton("Set")
        self.set_button.setMaximumWidth(48)  # the dock is narrow (1024 px screens)
        self.set_button.setToolTip("ask the node to set this CPI; it reads the register back")
        self.current = QLabel("now: –")
        # never narrower than its text ("now: 12000 CPI"): the field gives way first
        self.current.setSizePolicy(QSizePolicy.Minimum, QSizePolicy.Preferred)
        self.current.setToolTip("the CPI in force, from the newest reply")
        self.read_back = QLabel("")
        self.read_back.setWordWrap(True)
        self.error = QLabel("")
        self.error_at: float | None = None  # time.monotonic() the error was shown
        self.error.setStyleSheet(RED)
        self.error.setWordWrap(True)
        self.name = QLabel(device)
        self.name.setToolTip(device)
        #: the chip named by the newest reply ('' = not known / an old node: PLN2033)
        self.chip = ""
        #: its range from the node's SensorSettings (None: not read yet)
        self.settings_range: CpiRange | None = None
        self.online = True

    def _placeholder(self, text: str) -> None:
        """Show ``text`` in the empty field, never cut: the field is at least that wide."""
        self.edit.setPlaceholderText(text)
        # the frame and text margins of the style: about 8 px a side
        self.edit.setMinimumWidth(self.edit.fontMetrics().horizontalAdvance(text) + 18)

    def allowed(self) -> CpiRange | None:
        """The range to check against: the node's word, else the registry's (None: a chip not
        known here)."""
        return self.settings_range or cpi_range(self.chip)

    def fixed(self) -> bool:
        allowed = self.allowed()
        return allowed is not None and allowed.fixed

    def show_chip(self, cpi: int | None = None) -> None:
        """Name, placeholder, tooltips and enabled state for the chip now known."""
        title = chip_title(self.chip) if self.chip else ""
        self.name.setText(f"{self.device} ({title})" if title else self.device)
        allowed = self.allowed()
        if allowed is not None and allowed.fixed:
            tip = fixed_tip(self.chip, cpi)
            self._placeholder(f"fixed {cpi or allowed.min}")
            self.edit.setToolTip(tip)
            self.set_button.setToolTip(tip)
            self.edit.setEnabled(False)
            self.set_button.setEnabled(False)
            return
        if allowed is not None:
            self._placeholder(f"{allowed.min}..{allowed.max}")
            self.edit.setToolTip(f"counts per inch of both axes, {chip_title(self.chip)} allows "
                                 f"{allowed.describe()} (Enter sets)")
        self.edit.setEnabled(self.online)
        self.set_button.setEnabled(self.online)


class ResolutionPanel(QGroupBox):
    """Per sensor: a CPI field, Set, the value read back from the node and errors."""

    def __init__(self, ctx, parent=None) -> None:
        super().__init__("Resolution (CPI)", parent)
        self.ctx = ctx
        self.rows: dict[str, _SensorRow] = {}
        self._version = -1
        self.grid = QGridLayout()
        self.grid.setColumnStretch(2, 1)
        self.note = QLabel("")
        self.note.setWordWrap(True)
        lay = QVBoxLayout(self)
        lay.addLayout(self.grid)
        lay.addWidget(self.note)
        if ctx.bridge is not None:
            ctx.bridge.resolution_done.connect(self.on_resolution_done)
            if hasattr(ctx.bridge, "settings_received"):
                ctx.bridge.settings_received.connect(self.on_settings)
        ctx.devices_known.connect(self._build)
        # the CPI in force changes rarely: a look five times a second, not a slot per reply
        # (at 500 Hz that is 500 queued calls a second for nothing; docs/benchmarks.md, gui)
        self._timer = QTimer(self)
        self._timer.setInterval(REFRESH_MS)
        self._timer.timeout.connect(self.refresh)
        self._timer.start()
        self._build(ctx.session.devices)

    def _build(self, devices) -> None:
        for dev in devices:
            if dev in self.rows:
                continue
            row = _SensorRow(dev)
            row.set_button.clicked.connect(lambda _=False, d=dev: self.apply(d))
            row.edit.returnPressed.connect(lambda d=dev: self.apply(d))
            row.online = self.ctx.bridge is not None
            row.edit.setEnabled(row.online)
            row.set_button.setEnabled(row.online)
            # name; field, Set; now; read back; error (one column fits a 255 px dock)
            base = 5 * len(self.rows)
            self.grid.addWidget(row.name, base, 0, 1, 3)
            self.grid.addWidget(row.edit, base + 1, 0)
            self.grid.addWidget(row.set_button, base + 1, 1)
            self.grid.setColumnStretch(0, 1)
            self.grid.addWidget(row.current, base + 2, 0, 1, 3)
            self.grid.addWidget(row.read_back, base + 3, 0, 1, 3)
            self.grid.addWidget(row.error, base + 4, 0, 1, 3)
            self.rows[dev] = row
        if self.ctx.bridge is None:
            self.note.setText("offline: no node to set the resolution on")
        elif not self.rows:
            self.note.setText("no sensor known yet (waiting for the first reply)")
        else:
            self.note.setText("")
        self.refresh()

    # -- user intent --------------------------------------------------------------------

    def apply(self, device: str) -> bool:
        """Validate the typed CPI of ``device`` and ask the node to set it.

        False (nothing sent, the reason shown next to the field) when the
        value is refused or there is no node.
        """
        row = self.rows[device]
        if row.fixed():
            self._set_error(row, fixed_tip(row.chip))
            return False
        try:
            cpi = validate_cpi(row.edit.text(), row.allowed(), row.chip)
        except ValueError as e:
            self._set_error(row, str(e))
            self._restore_field(device)
            return False
        if self.ctx.bridge is None:
            self._set_error(row, "offline: no node to set the resolution on")
            self._restore_field(device)
            return False
        self._set_error(row, "")
        row.read_back.setStyleSheet("")
        row.read_back.setText(f"asking the node for {cpi} CPI…")
        self.ctx.bridge.set_resolution(device, cpi)
        return True

    # -- answers ------------------------------------------------------------------------

    def on_settings(self, device: str, msg) -> None:
        """A ``SensorSettings``: the chip's own range (cpi_min/max/step) from the node."""
        row = self.rows.get(device)
        if row is None:
            return
        row.chip = str(getattr(msg, "chip", "") or row.chip)
        row.settings_range = cpi_range(row.chip, msg) if getattr(msg, "cpi_max", 0) else None
        row.show_chip(self.cpi_in_force(device))

    def on_resolution_done(self, device: str, ok: bool, message: str, cpi: int) -> None:
        """The node's answer: the CPI read back, or its message in red."""
        row = self.rows.get(device)
        if row is None:
            return
        if ok:
            self._set_error(row, "")
            row.read_back.setText(f"read back: {cpi} CPI")
        else:
            self._set_error(row, message or "the node refused the resolution")
            row.read_back.setText(f"read back: {cpi} CPI" if cpi else "")
            self._restore_field(device, cpi)

    def cpi_in_force(self, device: str) -> int | None:
        """The CPI of ``device`` in the newest reply (None before the first)."""
        hist = self.ctx.session.history
        devices = self.ctx.session.devices
        if hist is None or not len(hist) or device not in devices:
            return None
        value = hist.last(f"s{devices.index(device)}_cpi")
        return int(value) if value == value else None

    def _restore_field(self, device: str, cpi: int = 0) -> None:
        """After a refusal the field shows the value in force again (empty if unknown)."""
        known = cpi or self.cpi_in_force(device)
        self.rows[device].edit.setText(str(known) if known else "")

    @staticmethod
    def _set_error(row: _SensorRow, text: str) -> None:
        """Show (or clear, with "") a row's error; it goes after ERROR_SHOW_S by itself."""
        row.error.setText(text)
        row.error_at = time.monotonic() if text else None

    def _expire_errors(self) -> None:
        now = time.monotonic()
        for row in self.rows.values():
            if row.error_at is not None and now - row.error_at > ERROR_SHOW_S:
                self._set_error(row, "")

    def refresh(self) -> None:
        """Show the CPI of the newest history row (cheap: only when it changed); an error
        older than ERROR_SHOW_S goes."""
        self._expire_errors()
        hist = self.ctx.session.history
        if hist is None or hist.version == self._version or not len(hist):
            return
        self._version = hist.version
        for k, dev in enumerate(self.ctx.session.devices):
            row = self.rows.get(dev)
            if row is None:
                continue
            text = f"now: {hist.last(f's{k}_cpi'):.0f} CPI"
            if row.current.text() != text:
                row.current.setText(text)
            chip = self.ctx.session.chip(dev)
            if chip != row.chip:
                row.chip = chip
                row.show_chip(self.cpi_in_force(dev))
