"""The 13 PLN2033 registers of every sensor, read from the node on demand.

"Refresh" asks the node (``get_sensor_settings``) once per sensor; the
answers arrive as bridge signals and fill one column per sensor (hex), and
below the table the decoded status of each sensor: lift and motion as the
node decoded them, the status register's bits 15..0, the names of the bits
that are set (by the chip registry's status bits: the PLN2033's are the
default register map's, an assumption documented in docs/pln2033.md), the
resolution and the time of the read. Errors of a read are shown in red under
the button.

Other chips (issue 15): a ``SensorSettings`` that names its chip and carries its own
register dump (``register_names`` / ``register_values``) is shown by those names; the
table's rows are the names of every sensor read so far, in order (the 13 PLN2033 rows for a
PLN2033, or for an old node that names no chip), so mixed chips sit side by side.
"""

from __future__ import annotations

import time

from PySide6.QtGui import QFont
from PySide6.QtWidgets import (
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from mm_pc.monitor.model.chips import chip_key, chip_title, info_of
from mm_pc.monitor.widgets.style import ERROR_STYLE
from pln2033.chips import DEFAULT_CHIP, chip_info

__all__ = ["FIELDS", "RegistersView", "decode_status", "register_dump", "status_bits"]

#: SensorSettings field names, in the seed's order
FIELDS: tuple[str, ...] = tuple(f"{name}_register" for name in chip_info(DEFAULT_CHIP).registers)
NO_LOSS_TIP = (
    "Reading the registers does not lose counts: the node folds the displacement it reads "
    "with the status register into its sums before replying."
)


def status_bits(value: int) -> str:
    """Bits 15..0 of a 16-bit register, in groups of four (e.g. '0000 0000 1001 0000')."""
    bits = f"{value & 0xFFFF:016b}"
    return " ".join(bits[i : i + 4] for i in range(0, 16, 4))


def decode_status(value: int, chip: str = "") -> list[str]:
    """Names of the status bits set in ``value``, by the registry's ``ChipInfo.status_bits``
    of ``chip`` ('' = the PLN2033; none for a chip not known here)."""
    info = info_of(chip)
    named = info.status_bits if info is not None else ()
    return [name for name, mask in named if value & mask]


def register_dump(msg) -> tuple[str, tuple[tuple[str, int], ...]]:
    """(chip, ((register name, value), ...)) of a ``SensorSettings``: the chip's own dump
    when it carries one, else the 13 PLN2033 fields (a PLN2033, or an old node)."""
    chip = chip_key(str(getattr(msg, "chip", "") or ""))
    names = list(getattr(msg, "register_names", ()) or ())
    values = list(getattr(msg, "register_values", ()) or ())
    if chip != DEFAULT_CHIP and names:
        return chip, tuple(zip(names, (int(v) for v in values), strict=False))
    return chip, tuple((name, int(getattr(msg, name))) for name in FIELDS)


class RegistersView(QWidget):
    """Register table (rows: registers, columns: sensors) with the decoded status below."""

    def __init__(self, ctx, parent=None) -> None:
        super().__init__(parent)
        self.ctx = ctx
        self.devices: list[str] = []
        #: device -> (SensorSettings, local time of the answer)
        self.settings: dict[str, tuple[object, float]] = {}
        #: device -> (chip, its register dump) of the newest answer
        self.dumps: dict[str, tuple[str, tuple[tuple[str, int], ...]]] = {}
        self.rows: list[str] = list(FIELDS)
        self.errors: dict[str, str] = {}

        self.refresh_button = QPushButton("Refresh")
        self.refresh_button.setToolTip(NO_LOSS_TIP)
        self.refresh_button.clicked.connect(lambda: self.request_registers())
        self.note = QLabel("")
        self.note.setWordWrap(True)
        self.error = QLabel("")
        self.error.setStyleSheet(ERROR_STYLE)
        self.error.setWordWrap(True)
        bar = QHBoxLayout()
        bar.addWidget(self.refresh_button)
        bar.addWidget(self.note, 1)

        self.table = QTableWidget(len(FIELDS), 0)
        self.table.setVerticalHeaderLabels(list(FIELDS))
        self.table.setEditTriggers(QTableWidget.NoEditTriggers)
        # the sensors share the width alike, each as wide as its head at least (a narrow
        # window scrolls; with the last column stretched alone the columns were unequal)
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.Stretch)
        self.table.setToolTip(NO_LOSS_TIP)
        mono = QFont("monospace")
        mono.setStyleHint(QFont.Monospace)
        self._mono = mono

        self.status_box = QGroupBox("Status (decoded)")
        self.status_layout = QHBoxLayout(self.status_box)
        self.status_labels: dict[str, QLabel] = {}

        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.error)
        lay.addWidget(self.table, 1)
        lay.addWidget(self.status_box)

        if ctx.bridge is not None:
            ctx.bridge.settings_received.connect(self.on_settings)
            ctx.bridge.settings_failed.connect(self.on_failed)
        ctx.devices_known.connect(self._set_devices)
        self._set_devices(ctx.session.devices)
        self._update_note()

    # -- columns -----------------------------------------------------------------------

    def _set_devices(self, devices) -> None:
        for dev in devices:
            self._column(dev)
        self._update_note()

    def _column(self, device: str) -> int:
        if device not in self.devices:
            self.devices.append(device)
            col = len(self.devices) - 1
            self.table.setColumnCount(len(self.devices))
            self.table.setHorizontalHeaderItem(col, QTableWidgetItem(device))
            label = QLabel("not read yet")
            label.setFont(self._mono)
            label.setWordWrap(True)
            self._least_column_width()
            box = QGroupBox(device)
            QVBoxLayout(box).addWidget(label)
            self.status_layout.addWidget(box)
            self.status_labels[device] = label
        return self.devices.index(device)

    def _update_note(self) -> None:
        if self.ctx.bridge is None:
            self.refresh_button.setEnabled(False)
            self.note.setText("offline: no node to read the registers from")
        elif not self.ctx.session.devices:
            self.note.setText("no sensor known yet (waiting for the first reply)")
        else:
            self.note.setText("values read on demand; reading loses no counts")

    # -- requests and answers -----------------------------------------------------------

    def request_registers(self, devices=None) -> int:
        """Ask the node for the registers of ``devices`` (default: every known sensor).

        Returns the number of requests sent (0 offline). Never waits: the
        answers arrive through the bridge's signals.
        """
        bridge = self.ctx.bridge
        devices = list(self.ctx.session.devices if devices is None else devices)
        if bridge is None or not devices:
            self._update_note()
            return 0
        self.errors.clear()
        self.error.setText("")
        for dev in devices:
            bridge.request_settings(dev)
        self.note.setText(f"asked the node for {len(devices)} sensor(s)…")
        return len(devices)

    def on_settings(self, device: str, msg) -> None:
        """Fill one sensor's column and status from a SensorSettings message."""
        self._column(device)
        self.dumps[device] = register_dump(msg)
        self._fill_table()
        now = time.time()
        self.settings[device] = (msg, now)
        self.errors.pop(device, None)
        self._show_errors()
        self.status_labels[device].setText(self.status_text(msg, now))
        self.note.setText(f"read {time.strftime('%H:%M:%S', time.localtime(now))}")

    def _fill_table(self) -> None:
        """Rows: every register name of the sensors read so far, in order; one column each."""
        rows: list[str] = []
        for dev in self.devices:
            for name, _v in self.dumps.get(dev, ("", ()))[1]:
                if name not in rows:
                    rows.append(name)
        self.rows = rows or list(FIELDS)
        self.table.setRowCount(len(self.rows))
        self.table.setVerticalHeaderLabels(self.rows)
        for col, dev in enumerate(self.devices):
            chip, dump = self.dumps.get(dev, ("", ()))
            values = dict(dump)
            wide = chip == DEFAULT_CHIP or any(v > 0xFF for v in values.values())
            for r, name in enumerate(self.rows):
                if name not in values:
                    self.table.setItem(r, col, None)
                    continue
                v = values[name]
                item = QTableWidgetItem(f"0x{v:04X}" if wide else f"0x{v:02X}")
                item.setFont(self._mono)
                item.setToolTip(f"{dev} ({chip_title(chip)}): {name} = {v}")
                self.table.setItem(r, col, item)
            head = self.table.horizontalHeaderItem(col)
            if head is not None and dev in self.dumps:
                head.setText(f"{dev}\n{chip_title(chip)}")
        self._least_column_width()

    def _least_column_width(self) -> None:
        """No column narrower than its widest head line or value (plus the margins)."""
        header = self.table.horizontalHeader()
        fm = header.fontMetrics()
        widest = max((fm.horizontalAdvance(line) for c in range(self.table.columnCount())
                      if (item := self.table.horizontalHeaderItem(c)) is not None
                      for line in item.text().split("\n")), default=0)
        values = self.table.fontMetrics().horizontalAdvance("0x0000") if self.dumps else 0
        header.setMinimumSectionSize(max(widest, values) + 16)

    def status_text(self, msg, stamp: float) -> str:
        chip = chip_key(str(getattr(msg, "chip", "") or ""))
        if chip != DEFAULT_CHIP:
            yes = {True: "yes", False: "no"}
            n = len(self.dumps.get(str(getattr(msg, "spi_device", "")), ("", ()))[1]) or len(
                getattr(msg, "register_names", ()) or ())
            return "\n".join((
                f"chip: {chip_title(chip)}",
                f"lifted: {yes[bool(msg.lifted)]}    motion: {yes[bool(msg.motion)]}",
                f"{n} registers, by the chip's own names (docs/sensors.md)",
                f"cpi {int(msg.cpi)}  (x_cpi {int(msg.x_cpi)}, y_cpi {int(msg.y_cpi)})",
                f"read at {time.strftime('%H:%M:%S', time.localtime(stamp))}",
            ))  # fmt: skip
        status = int(msg.status_register)
        names = ", ".join(decode_status(status, chip)) or "none"
        yes = {True: "yes", False: "no"}
        return "\n".join(
            (
                f"lifted: {yes[bool(msg.lifted)]}    motion: {yes[bool(msg.motion)]}",
                f"status 0x{status:04X}  bits 15..0: {status_bits(status)}",
                f"bits set: {names}",
                f"cpi {int(msg.cpi)}  (x_cpi {int(msg.x_cpi)}, y_cpi {int(msg.y_cpi)})",
                f"read at {time.strftime('%H:%M:%S', time.localtime(stamp))}",
            )
        )

    def on_failed(self, device: str, message: str) -> None:
        self.errors[device] = message
        self._show_errors()

    def _show_errors(self) -> None:
        self.error.setText("\n".join(f"{d}: {m}" for d, m in self.errors.items()))

    def refresh(self) -> None:
        """Nothing to redraw per frame: the registers are read on demand."""
