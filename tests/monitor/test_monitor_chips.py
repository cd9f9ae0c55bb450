"""Which chip each sensor is, in the monitor (issue 15): the Data tab's titles, the Health
view's quality plot with the chip's threshold, the Registers view of any chip's dump, the
resolution panel's per-chip range and its disabled field for a fixed-resolution chip.

Fed by hand-built replies (the simulator's, with the chip fields set as a node of issue 15
fills them) and a fake bridge: no ROS.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from mm_pc.core.sensor_data import Reply
from mm_pc.monitor.context import MonitorContext
from mm_pc.monitor.model.chips import chip_title, cpi_range, quality_figure
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES, sim_replies
from mm_pc.monitor.widgets.data_list import DataListView
from mm_pc.monitor.widgets.health_view import DIAG_COLUMNS, HealthView
from mm_pc.monitor.widgets.registers_view import FIELDS, RegistersView
from mm_pc.monitor.widgets.resolution_panel import ResolutionPanel, validate_cpi


def quality_at(k: int) -> int:
    """The SQUAL the fake node reports at reply k: 80, with a dip to 5 at replies 100..119."""
    return 5 if 100 <= k < 120 else 80


def chip_replies(chips, seconds=3.0, cpi=(1600, 1600)):
    """Simulated replies as a node naming ``chips`` (one per device) would send them."""
    out = []
    for k, r in enumerate(sim_replies("figure_eight", 100.0, seconds)):
        readings = tuple(
            replace(x, chip=c, cpi=cpi[i] if c else x.cpi,
                    # the PMW3360 dips, the PMW3389 sees a good floor all along (a steady 60):
                    # the screenshot's curves differ (alike, the second hid the first)
                    quality={"pmw3360": quality_at(k), "pmw3389": 60}.get(c, -1),
                    low_quality_events=10 if quality_at(k) < 16 and c == "pmw3360" else 0)
            for i, (x, c) in enumerate(zip(r.readings, chips, strict=True))
        )
        out.append(Reply(readings, r.received_s, r.rtt_s))
    return out


def make_ctx(chips, bridge=None, cpi=(1600, 1600)):
    ctx = MonitorContext(MonitorSession(), bridge=bridge)
    for r in chip_replies(chips, cpi=cpi):
        ctx.on_reply(r)
    return ctx


def test_chip_facts_from_the_registry_and_an_old_node():
    assert chip_title("") == "Philips PLN2033" and chip_title("pmw3360") == "PixArt PMW3360"
    assert chip_title("future9000") == "future9000"  # unknown here: its name
    assert math.isnan(quality_figure("", 0))  # an old node's zero-filled 0 is no SQUAL 0
    assert math.isnan(quality_figure("pln2033", 0))  # the PLN2033 has no figure
    assert math.isnan(quality_figure("pmw3360", -1))
    assert quality_figure("pmw3360", 0) == 0.0
    assert cpi_range("pmw3901").fixed and cpi_range("pmw3360").describe() == (
        "100..12000 in steps of 100")
    settings = SimpleNamespace(cpi_min=200, cpi_max=8000, cpi_step=200)
    assert cpi_range("pmw3360", settings).describe() == "200..8000 in steps of 200"


def test_health_plots_quality_with_the_chips_threshold(qtbot, fake_bridge):
    bridge = fake_bridge
    ctx = make_ctx(("pmw3360", "pmw3389"), bridge)
    view = HealthView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    hist = ctx.session.history
    want = hist.column("s0_quality")
    assert set(np.unique(want)) == {5.0, 80.0}
    t, y = view.quality_data(0)
    assert np.array_equal(y, want) and np.array_equal(t, hist.column("t"))  # 300 rows: all
    assert {k: line.value() for k, line in view.threshold_lines.items()} == {0: 16.0, 1: 16.0}
    assert "SQUAL threshold 16" in view.threshold_lines[0].label.toPlainText()
    assert view.quality_plot.isVisible() or not view.isVisible()
    assert f"{DEFAULT_DEVICES[0]} (PMW3360)" in view.quality_plot.titleLabel.text
    assert view.quality_plot.getAxis("left").labelText == "SQUAL"
    assert view.quality_note.text() == ""
    # the Health table's low-quality row, from the node's /diagnostics
    row = [key for _t, key, _tip in DIAG_COLUMNS].index("low_quality_events")
    assert "treated like a lift" in DIAG_COLUMNS[row][2]
    bridge.diagnostics_received.emit({DEFAULT_DEVICES[0]: {"level": 0, "low_quality_events":
                                                           "37"}})
    assert view.table.item(row, 0).text() == "37"
    assert view.table.verticalHeaderItem(row).text() == "Low-quality polls"
    assert hist.column("s0_lowq").sum() == 20 * 10


def test_health_says_when_a_chip_has_no_quality_figure(qtbot):
    ctx = make_ctx(("", "pln2033"))  # an old node (no chip field) and a PLN2033 naming itself
    view = HealthView(ctx)
    qtbot.addWidget(view)
    view.show()
    view.refresh()
    note = view.quality_note.text()
    assert f"{DEFAULT_DEVICES[0]}: no quality figure (chip Philips PLN2033)" in note
    assert f"{DEFAULT_DEVICES[1]}: no quality figure (chip Philips PLN2033)" in note
    assert not view.quality_plot.isVisible()  # no empty plot
    assert view.threshold_lines == {}
    assert np.isnan(ctx.session.history.column("s0_quality")).all()


def test_mixed_chips_one_with_a_figure_one_without(qtbot):
    ctx = make_ctx(("pmw3360", ""))
    view = HealthView(ctx)
    qtbot.addWidget(view)
    view.show()
    view.refresh()
    assert view.quality_plot.isVisible() and list(view.threshold_lines) == [0]
    assert "no quality figure (chip Philips PLN2033)" in view.quality_note.text()
    assert len(view.quality_data(1)[1]) == 0


def test_data_tabs_name_each_sensors_chip(qtbot):
    ctx = make_ctx(("pmw3360", "paa5100"), cpi=(1600, 232))
    view = DataListView(ctx)
    qtbot.addWidget(view)
    view.refresh()
    assert [view.tabs.tabText(i) for i in range(2)] == [
        f"{DEFAULT_DEVICES[0]} (PixArt PMW3360)", f"{DEFAULT_DEVICES[1]} (PixArt PAA5100JE-Q)"]


def test_resolution_panel_uses_the_chips_own_range_and_disables_a_fixed_one(qtbot, fake_bridge):
    bridge = fake_bridge
    ctx = make_ctx(("pmw3360", "pmw3901"), bridge, cpi=(1600, 104))
    panel = ResolutionPanel(ctx)
    qtbot.addWidget(panel)
    panel.refresh()
    a, b = (panel.rows[d] for d in DEFAULT_DEVICES)
    assert a.name.text() == f"{DEFAULT_DEVICES[0]} (PixArt PMW3360)"
    assert a.edit.isEnabled() and a.edit.placeholderText() == "100..12000"
    a.edit.setText("11000")  # beyond the PLN2033's 6400, inside the PMW3360's range
    assert panel.apply(DEFAULT_DEVICES[0]) and bridge.calls == [
        ("resolution", DEFAULT_DEVICES[0], 11000)]
    a.edit.setText("12050")
    assert not panel.apply(DEFAULT_DEVICES[0])
    assert re.search(r"CPI 12050 is out of range \(PixArt PMW3360 allows 100\.\.12000",
                     a.error.text()), a.error.text()
    # the optical-flow chip: field and Set disabled, the tooltip says why and what to do
    assert not b.edit.isEnabled() and not b.set_button.isEnabled()
    assert "fixed resolution (104 CPI now)" in b.edit.toolTip()
    assert "calibrate the sensor's scale" in b.edit.toolTip()
    assert not panel.apply(DEFAULT_DEVICES[1]) and len(bridge.calls) == 1
    # the node's SensorSettings range wins over the registry's
    bridge.settings_received.emit(DEFAULT_DEVICES[0], SimpleNamespace(
        chip="pmw3360", cpi_min=100, cpi_max=3200, cpi_step=100))
    a.edit.setText("4000")
    assert not panel.apply(DEFAULT_DEVICES[0]) and "allows 100..3200" in a.error.text()
    from mm_pc.monitor.widgets.resolution_panel import fixed_tip

    otos = fixed_tip("otos", 1000)
    assert "fixed resolution (1000 CPI now)" in otos and "height" not in otos
    with pytest.raises(ValueError, match=r"PixArt PMW3389 allows 50\.\.16000 in steps of 50"):
        validate_cpi("75", cpi_range("pmw3389"), "pmw3389")


def _settings(device, chip, names=(), values=(), **kw):
    base = {name: 0 for name in FIELDS}
    base.update(spi_device=device, chip=chip, register_names=list(names),
                register_values=list(values), cpi=kw.get("cpi", 1600), x_cpi=1600, y_cpi=1600,
                lifted=False, motion=True, cpi_min=100, cpi_max=12000, cpi_step=100)
    return SimpleNamespace(**base)


def real_dump(chip: str):
    """The register dump the real driver reads from its register-level emulator."""
    from fakes import FakeClock

    from pln2033.chips import chip_info, make_driver, make_emulator
    from pln2033.motion import ConstantVelocity

    clock = FakeClock()

    emu = make_emulator(chip, motion=ConstantVelocity(0.0, 0.1), clock=clock, seed=1)
    drv = make_driver(chip, emu, name=DEFAULT_DEVICES[0], sleep=clock.sleep)
    drv.initialise(chip_info(chip).cpi_default)
    clock.t += 0.01
    _motion, regs = drv.read_all_registers()
    return tuple(regs), tuple(regs.values())


def test_registers_view_shows_any_chips_dump_beside_a_pln2033(qtbot, fake_bridge):
    bridge = fake_bridge
    ctx = MonitorContext(MonitorSession(devices=DEFAULT_DEVICES), bridge=bridge)
    view = RegistersView(ctx)
    qtbot.addWidget(view)
    names = ("Product_ID", "Revision_ID", "SQUAL", "Config1")
    bridge.settings_received.emit(DEFAULT_DEVICES[0], _settings(
        DEFAULT_DEVICES[0], "pmw3360", names, (0x42, 0x01, 0x33, 0x0F)))
    assert view.rows == list(names)
    assert [view.table.item(r, 0).text() for r in range(4)] == ["0x42", "0x01", "0x33", "0x0F"]
    assert view.table.horizontalHeaderItem(0).text() == f"{DEFAULT_DEVICES[0]}\nPixArt PMW3360"
    text = view.status_labels[DEFAULT_DEVICES[0]].text()
    assert "chip: PixArt PMW3360" in text and "4 registers" in text
    # an old node (no chip): the 13 PLN2033 rows as before, after the other chip's
    old = _settings(DEFAULT_DEVICES[1], "")
    old.status_register = 0x0090
    bridge.settings_received.emit(DEFAULT_DEVICES[1], old)
    assert view.rows == [*names, *FIELDS]
    assert view.table.item(4, 1).text() == "0x0090" and view.table.item(4, 0) is None
    assert view.table.item(0, 1) is None
    assert "bits set: motion, lift" in view.status_labels[DEFAULT_DEVICES[1]].text()


@pytest.mark.screenshot
def test_quality_and_chip_screenshots(qtbot, screenshot, fake_bridge):
    """docs/images/health-quality.png: a PMW3360 and a PMW3389 with a SQUAL dip below the
    threshold; registers-pmw3360.png: a PMW3360's dump beside an old node's PLN2033."""
    bridge = fake_bridge
    ctx = make_ctx(("pmw3360", "pmw3389"), bridge)
    view = HealthView(ctx)
    qtbot.addWidget(view)
    view.resize(1000, 900)
    view.show()
    bridge.diagnostics_received.emit({d: {"level": 0, "low_quality_events": str(200 - 200 * k),
                                          "lift_events": "0"}
                                      for k, d in enumerate(DEFAULT_DEVICES)})
    view.refresh()
    img = screenshot(view, "health-quality.png")
    assert img.width() >= 1000 and view.quality_plot.isVisible()
    # the two curves differ (the PMW3360 dips, the PMW3389 does not)
    assert min(view.quality_data(0)[1]) == 5 and set(view.quality_data(1)[1]) == {60}
    regs = RegistersView(MonitorContext(MonitorSession(devices=DEFAULT_DEVICES), bridge=bridge))
    qtbot.addWidget(regs)
    regs.resize(900, 600)
    regs.show()
    names, values = real_dump("pmw3360")
    bridge.settings_received.emit(DEFAULT_DEVICES[0], _settings(DEFAULT_DEVICES[0], "pmw3360",
                                                                names, values))
    old = _settings(DEFAULT_DEVICES[1], "")
    old.status_register = 0x0080
    bridge.settings_received.emit(DEFAULT_DEVICES[1], old)
    screenshot(regs, "registers-pmw3360.png")
    assert regs.rows[: len(names)] == list(names) and len(regs.rows) == len(names) + len(FIELDS)


def test_the_status_bar_names_the_chips(qtbot, tmp_path):
    from mm_pc.monitor.context import MonitorConfig
    from mm_pc.monitor.main_window import MainWindow

    config = MonitorConfig(rate_hz=100.0, calibration_file=tmp_path / "cal.yaml")
    ctx = MonitorContext(MonitorSession(), None, config)
    window = MainWindow(ctx)
    qtbot.addWidget(window)
    for r in chip_replies(("pmw3360", ""), seconds=0.2):
        ctx.on_reply(r)
    window.frame()
    assert window.chips_label.text() == "PMW3360 + PLN2033"
    tip = window.chips_label.toolTip()
    assert f"{DEFAULT_DEVICES[0]}: PixArt PMW3360" in tip
    assert f"{DEFAULT_DEVICES[1]}: Philips PLN2033 (the node names none)" in tip
