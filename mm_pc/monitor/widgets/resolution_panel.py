"""Resolution (CPI) of each sensor: set it on the node and show what the node read back.

The typed value is checked here first, by the default register map
(:meth:`pln2033.RegisterMap.cpi_problem`: 100..6400 in steps of 100, the range the
seed names; a node with its own map may allow less and says so); a refused value is
explained next to its field and never sent. An accepted value goes to the node's
``set_resolution``; its answer (the CPI read back from the sensor, or the node's reason
for refusing) appears next to the field when the bridge reports it. The CPI in force is
also shown from the newest reply.
"""

from __future__ import annotations

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import (
    QGridLayout,
    QGroupBox,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
)

from mm_pc.monitor.widgets.style import ERROR_STYLE
from pln2033 import RegisterMap

__all__ = ["CPI_MAX", "CPI_MIN", "CPI_STEP", "ResolutionPanel", "validate_cpi"]

#: how often (ms) the panel looks for a new CPI in the history
REFRESH_MS = 200

_REGMAP = RegisterMap.default()
_ALLOWED_CPI = _REGMAP.allowed_cpi
CPI_MIN, CPI_MAX, CPI_STEP = _ALLOWED_CPI.start, _ALLOWED_CPI.stop - 1, _ALLOWED_CPI.step
ALLOWED = f"allowed: {CPI_MIN}..{CPI_MAX} in steps of {CPI_STEP}"
RED = ERROR_STYLE


def validate_cpi(value) -> int:
    """The CPI in ``value`` (text or number); ValueError saying what is allowed otherwise."""
    text = str(value).strip()
    try:
        cpi = int(text)
    except ValueError:
        raise ValueError(f"CPI must be a whole number, got {text!r} ({ALLOWED})") from None
    problem = _REGMAP.cpi_problem(cpi)
    if problem:
        raise ValueError(problem)
    return cpi


class _SensorRow:
    """The widgets of one sensor: field, Set, CPI in force, read-back and error labels."""

    def __init__(self, device: str) -> None:
        self.device = device
        self.edit = QLineEdit()
        self.edit.setPlaceholderText(f"{CPI_MIN}..{CPI_MAX}")
        self.edit.setMinimumWidth(60)
        self.edit.setToolTip(f"counts per inch of both axes, {ALLOWED} (Enter sets)")
        self.set_button = QPushButton("Set")
        self.set_button.setMaximumWidth(48)  # the dock is narrow (1024 px screens)
        self.set_button.setToolTip("ask the node to set this CPI; it reads the register back")
        self.current = QLabel("now: –")
        self.current.setToolTip("the CPI in force, from the newest reply")
        self.read_back = QLabel("")
        self.read_back.setWordWrap(True)
        self.error = QLabel("")
        self.error.setStyleSheet(RED)
        self.error.setWordWrap(True)


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
            online = self.ctx.bridge is not None
            row.edit.setEnabled(online)
            row.set_button.setEnabled(online)
            base = 4 * len(self.rows)  # name; field, Set, now; read back; error
            name = QLabel(dev)
            name.setToolTip(dev)
            self.grid.addWidget(name, base, 0, 1, 3)
            self.grid.addWidget(row.edit, base + 1, 0)
            self.grid.addWidget(row.set_button, base + 1, 1)
            self.grid.addWidget(row.current, base + 1, 2)
            self.grid.addWidget(row.read_back, base + 2, 0, 1, 3)
            self.grid.addWidget(row.error, base + 3, 0, 1, 3)
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
        try:
            cpi = validate_cpi(row.edit.text())
        except ValueError as e:
            row.error.setText(str(e))
            self._restore_field(device)
            return False
        if self.ctx.bridge is None:
            row.error.setText("offline: no node to set the resolution on")
            self._restore_field(device)
            return False
        row.error.setText("")
        row.read_back.setStyleSheet("")
        row.read_back.setText(f"asking the node for {cpi} CPI…")
        self.ctx.bridge.set_resolution(device, cpi)
        return True

    # -- answers ------------------------------------------------------------------------

    def on_resolution_done(self, device: str, ok: bool, message: str, cpi: int) -> None:
        """The node's answer: the CPI read back, or its message in red."""
        row = self.rows.get(device)
        if row is None:
            return
        if ok:
            row.error.setText("")
            row.read_back.setText(f"read back: {cpi} CPI")
        else:
            row.error.setText(message or "the node refused the resolution")
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

        # the CPI in force changes rarely: a look five times a second, not a slot per reply
        # (at 500 Hz that is 500 queued calls a second for nothing; docs/benchmarks.md, gui)
        self._timer = QTimer(self)
        self._timer.setInterval(REFRESH_MS)
        self._timer.timeout.connect(self.refresh)
        self._timer.start()
    def refresh(self) -> None:
        """Show the CPI of the newest history row (cheap: only when it changed)."""
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
