"""The poller with mixed chips (issue 15): the real drivers against their emulators.

Each test builds a real :class:`Poller` on a plain bytearray and polls it by hand on a
fake clock (as tests/beagle/test_poller.py does for the PLN2033); each device's emulator
comes from :func:`pln2033.chips.make_emulator`. Parametrised over every registered chip:
a chip whose family is not installed yet is skipped with a reason.
"""

from __future__ import annotations

from multiprocessing import Pipe

import pytest
from fakes import FakeClock

from mm_beagle.poller import chip_config
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import Poller, PollerConfig
from mm_beagle.poller.sim_backend import SimConfig
from mm_beagle.poller.sim_channel import truth_of
from pln2033 import INCH_M
from pln2033 import chips as registry
from pln2033.motion import ConstantVelocity

T0 = 100.0
PERIOD = 1e-3
OTHERS = [c for c in registry.chip_names() if c != registry.DEFAULT_CHIP]
#: chips whose low-quality polls lost their motion (the OTOS's carry it: its own test below)
LOSING = [
    c for c in OTHERS
    if not (chip_config.available(c) and registry.chip_info(c).poor_polls_carry_motion)
]


def need(chip: str) -> None:
    if not chip_config.available(chip):
        pytest.skip(f"the {chip} driver is not in this tree yet")


class Rig:
    """A Poller over one emulator per device (its chip's), on a fake clock."""

    def __init__(self, chips, emu_kw=None, cpi=1600, options=None, ring=65536):
        n = len(chips)
        self.clock = FakeClock(T0)
        self.state = ss.SharedState(bytearray(ss.SharedState.size(n, ring)), n, ring)
        self.cmd, cmd_child = Pipe()
        self.ev, ev_child = Pipe()
        self.cfg = PollerConfig(
            devices=[f"/dev/spidev1.{i}" for i in range(n)],
            backend="sim",
            cpi=cpi,
            chips=list(chips),
            chip_options=dict(options or {}),
            ring_size=ring,
            sim=SimConfig(trajectory="straight"),
        )
        self.poller = Poller(self.cfg, self.state, cmd_child, ev_child)
        self.poller.driver_extra = {"sleep": self.sleep}
        self.emus = []
        self.t_init = []  # when each channel's counting started (bring-up waits move the clock)
        for ch, kw in zip(self.poller.channels, emu_kw or [{}] * n, strict=True):
            emu = registry.make_emulator(ch.chip, clock=self.clock, **kw)
            ch.bus = emu
            self.emus.append(emu)
            self.poller.try_init(ch, self.clock.t)
            self.t_init.append(self.clock.t)
        self.k = 0
        self.t_start = self.clock.t

    def sleep(self, s: float) -> None:
        self.clock.t += s

    def run(self, polls: int) -> None:
        for _ in range(polls):
            self.k += 1
            self.clock.t = self.t_start + self.k * PERIOD
            for ch in self.poller.channels:
                self.poller.poll(ch, round(self.clock.t * 1e9), self.clock.t)

    def events(self):
        out = []
        while self.ev.poll():
            out.append(self.ev.recv())
        return out


@pytest.mark.parametrize("chip", OTHERS)
def test_mixed_chips_poll_every_count_with_quality(chip):
    """A PLN2033 and another chip on one poller: both up, every counted count measured,
    the quality ring -1 for the PLN2033 and the chip's figure for the other."""
    need(chip)
    motion = ConstantVelocity(0.05, 0.2)
    rig = Rig(["pln2033", chip], [{"motion": motion}, {"motion": motion}])
    ev = rig.events()
    assert [e[0] for e in ev] == ["up", "up"], ev
    rig.run(500)
    info = rig.poller.channels[1].info
    for i in range(2):
        t = rig.state.snapshot(i)
        assert t.state == ss.STATE_UP and t.seq == 500
        stats = rig.emus[i].stats
        assert stats.protocol_errors == 0
        # every count that entered the chip's counter is in the measured totals (the OTOS:
        # counts from its fused position, 0.305 mm per LSB = 12 counts: within that)
        slack = 12 if truth_of(rig.poller.channels[i]).ratio != 1.0 else 0
        assert abs(t.x_total - t.gen_x) <= slack and abs(t.y_total - t.gen_y) <= slack
        assert t.y_total > 100
        # metres: within 2 % of the true path (optical flow: its scale model, exactly)
        assert t.y_total_m == pytest.approx(0.2 * (rig.clock.t - rig.t_init[i]), rel=0.02)
        _f, _n, _d, arr = rig.state.samples(i, 0, 0)
        q = arr["quality"]
        if i == 0:
            assert (q == -1).all() and t.quality == -1
        else:
            assert info.quality_name, "every chip besides the PLN2033 reports a quality"
            assert (q >= info.quality_threshold).all() and t.quality == int(q[-1])
            assert not (arr["flags"] & ss.FLAG_LOW_QUALITY).any()
        assert t.low_quality_total == 0


@pytest.mark.parametrize("chip", LOSING)
def test_low_quality_window_is_treated_like_a_lift(chip):
    """A 30 ms poor-surface window: its polls carry FLAG_LOW_QUALITY and are counted;
    the lift-gap estimate fills the motion the chip did not count (the emulator's ground
    truth) within 15 %, and the measured totals still hold every counted count."""
    need(chip)
    info = registry.chip_info(chip)
    if info.quality_threshold <= 0:
        pytest.skip(f"the {chip} has no quality threshold")
    motion = ConstantVelocity(0.0, 0.3)
    start = T0 + 2.0  # after the slowest bring-up (the OTOS's IMU calibration: 0.6 s)
    rig = Rig([chip], [{"motion": motion, "low_quality_windows": [(start, start + 0.03)]}])
    assert rig.clock.t < start - 0.2
    rig.run(round((start + 0.3 - rig.clock.t) / PERIOD))
    t = rig.state.snapshot(0)
    _f, _n, _d, arr = rig.state.samples(0, 0, 0)
    poor = (arr["flags"] & ss.FLAG_LOW_QUALITY) != 0
    assert 28 <= poor.sum() <= 32, poor.sum()
    assert t.low_quality_total == int(poor.sum())
    assert (arr["quality"][poor] < info.quality_threshold).all()
    assert not (arr["flags"] & ss.FLAG_LIFT).any()  # a low quality is not a lift bit
    slack = 12 if truth_of(rig.poller.channels[0]).ratio != 1.0 else 0
    assert abs(t.x_total - t.gen_x) <= slack and abs(t.y_total - t.gen_y) <= slack
    lost = t.lift_lost_y  # counts the chip did not count in the window (ground truth)
    window_counts = 0.3 * 0.03 / (t.y_total_m / t.y_total)
    assert lost == pytest.approx(window_counts, rel=0.1)
    assert t.y_est_counts == pytest.approx(lost, rel=0.15)
    # measured + estimate = the true path within 1 %
    true_m = 0.3 * (rig.clock.t - rig.t_init[0])
    assert t.y_total_m + t.y_est_m == pytest.approx(true_m, rel=0.01)
    assert t.y_total_m < true_m - 0.3 * 0.03 * 0.8  # without the estimate: the window short


def test_otos_warning_polls_carry_motion_and_add_no_lift_estimate():
    """The OTOS over a 30 ms poor surface at 0.8 m/s: the firmware warns (its filters'
    velocity is above 0.5 m/s) and carries the pose on its IMU, so the warning polls'
    counts are motion. They are flagged FLAG_LOW_QUALITY but open no lift gap: no
    estimate is added on top (it added 0.025 m: the window twice), and the measured
    totals alone equal the true path within the chip's resolution."""
    need("otos")
    from pln2033.otos import regs

    info = registry.chip_info("otos")
    assert info.poor_polls_carry_motion and info.quality_threshold == 1
    speed, start = 0.8, T0 + 2.0  # after the IMU calibration; the filters have settled
    motion = ConstantVelocity(0.0, speed)
    rig = Rig(["otos"], [{"motion": motion, "low_quality_windows": [(start, start + 0.03)]}])
    rig.run(round((start + 0.3 - rig.clock.t) / PERIOD))
    t = rig.state.snapshot(0)
    _f, _n, _d, arr = rig.state.samples(0, 0, 0)
    poor = (arr["flags"] & ss.FLAG_LOW_QUALITY) != 0
    assert 28 <= poor.sum() <= 34, poor.sum()  # the warning, one firmware update late at most
    assert t.low_quality_total == int(poor.sum())
    assert not (arr["flags"] & ss.FLAG_LIFT).any()
    # the optical counts did stop (the emulator's ground truth) ...
    window_counts = speed * 0.03 / INCH_M * 1000  # at the driver's 1000 CPI
    assert t.lift_lost_y == pytest.approx(window_counts, rel=0.1)
    # ... but the IMU carried the pose: the warning polls hold the window's motion
    assert int(arr["dy"][poor].sum()) == pytest.approx(window_counts, rel=0.1)
    # so no lift estimate is added on top
    assert (t.x_est_counts, t.y_est_counts, t.x_est_m, t.y_est_m) == (0.0, 0.0, 0.0, 0.0)
    # and the totals are the truth within the chip's resolution (0.305 mm per LSB)
    true_m = speed * (rig.clock.t - rig.t_init[0])
    assert t.y_total_m == pytest.approx(true_m, abs=regs.POS_M_PER_LSB)
    assert abs(t.x_total_m) <= regs.POS_M_PER_LSB
    assert abs(t.y_total - (t.gen_y + t.lift_lost_y)) <= 12  # optical + carried counts


@pytest.mark.parametrize("chip", OTHERS)
def test_cpi_is_refused_outside_each_chips_own_range(chip):
    need(chip)
    rig = Rig(["pln2033", chip])
    info = rig.poller.channels[1].info
    serve = rig.poller.serve_command
    bad = info.cpi.max + info.cpi.step if not info.cpi.fixed else 1600
    status, text = serve(("set_cpi", 1, bad))
    assert status == "invalid"
    assert chip in text and str(bad) in text
    if info.cpi.fixed:
        assert "fixed" in text
        assert serve(("set_cpi", 1, info.cpi.min))[0] == "ok"
    else:
        good = info.cpi.max
        assert serve(("set_cpi", 1, good)) == ("ok", good)
        assert rig.state.snapshot(1).cpi_y == good
    # the PLN2033 next to it keeps its own rules
    status, text = serve(("set_cpi", 0, 16000))
    assert status == "invalid" and "pln2033" in text


@pytest.mark.parametrize("chip", ["pln2033", *OTHERS])
def test_settings_reply_names_the_chip_its_dump_and_range(chip):
    need(chip)
    rig = Rig([chip])
    status, reply = rig.poller.serve_command(("settings", 0))
    assert status == "ok"
    info = rig.poller.channels[0].info
    assert reply["chip"] == chip
    assert reply["cpi_range"] == [info.cpi.min, info.cpi.max, info.cpi.step]
    assert len(reply["registers"]) >= 5
    assert all(isinstance(v, int) for v in reply["registers"].values())


def test_fixed_chip_ignores_cpi_and_scales_by_its_rounded_cpi_like_every_client():
    need("pmw3901")
    rig = Rig(["pmw3901"], cpi=3200, options={"height_m": 0.08})
    ch = rig.poller.channels[0]
    assert ch.cpi_y == ch.driver.cpi  # the rounded effective CPI, not 3200
    # the messages carry the integer CPI and clients convert the polls by it: the totals too
    assert ch.scale_y == pytest.approx(0.0254 / ch.cpi_y, rel=1e-15)
    assert ch.scale_y == pytest.approx(ch.driver.metres_per_count, rel=0.005)
    assert any("fixed" in n for n in rig.poller.notes)


@pytest.mark.parametrize(
    ("chips", "options", "cpi", "needle"),
    [
        (["pmw9999"], {}, 1600, "allowed: pln2033"),
        (["pln2033", "pln2033", "pln2033"], {}, 1600, "give one per device"),
        (["pmw3360"], {"hieght_m": 0.1}, 1600, "no configured chip takes"),
        (["pmw3901"], {"height_m": 5.0}, 1600, "working range"),
        (["pmw3360"], {}, 16000, "PMW3360 allows 100..12000"),
        (["pln2033", "pmw3389"], {}, 12000, "PLN2033 allows"),
        (["pmw3360"], {"pmw3389.product_id": 0x42}, 1600, "no configured chip takes"),
    ],
)
def test_bad_chip_configuration_says_what_is_allowed(chips, options, cpi, needle):
    for chip in chips:
        if chip in registry.CHIPS:
            need(chip)
    with pytest.raises(ValueError, match=needle):
        chip_config.check_board_config(["/dev/spidev1.0", "/dev/spidev1.1"], chips, options, cpi)


def test_chip_options_parse_and_reach_only_the_chips_that_take_them():
    opts = chip_config.parse_chip_options(
        ["height_m=0.08", "pmw3389.product_id=0x42", "check_crc=false", ""]
    )
    assert opts == {"height_m": 0.08, "pmw3389.product_id": 0x42, "check_crc": False}
    need("pmw3389")
    assert chip_config.options_for("pmw3389", opts) == {"check_crc": False, "product_id": 0x42}
    assert chip_config.options_for("pln2033", opts) == {}
    for bad in ("height_m", "=3", "pmw9.x=1"):
        with pytest.raises(ValueError, match=r"key=value|allowed"):
            chip_config.parse_chip_options([bad])


def test_otos_on_chip_pose_reaches_the_shared_state_in_base_link_terms():
    """The OTOS's fused pose (its frame: x right, y forward) is stored as base_link
    (x forward, y left): 0.2 m/s forward and 0.05 m/s right -> x grows, y falls."""
    need("otos")
    motion = ConstantVelocity(0.05, 0.2)
    rig = Rig(["otos"], [{"motion": motion}])
    rig.run(100)
    t0, c0 = rig.state.snapshot(0), rig.clock.t
    rig.run(500)
    t = rig.state.snapshot(0)
    moved = rig.clock.t - c0  # (the chip's pose also ran during its bring-up)
    assert t.chip_pose_ns == round(rig.clock.t * 1e9)
    assert t.chip_x - t0.chip_x == pytest.approx(0.2 * moved, abs=0.002)  # 0.305 mm LSB
    assert t.chip_y - t0.chip_y == pytest.approx(-0.05 * moved, abs=0.002)
    assert abs(t.chip_yaw) < 1e-3
    assert t.chip_vx == pytest.approx(0.2, abs=0.02)
    assert t.chip_vy == pytest.approx(-0.05, abs=0.02)
    # the PLN2033 next to it has none
    rig2 = Rig(["pln2033"])
    rig2.run(10)
    assert rig2.state.snapshot(0).chip_pose_ns == 0


def test_otos_settings_from_the_calibration_file_are_written_at_every_start(tmp_path):
    """calibration_file -> each OTOS's linear scalar and offset (issue 15 part 5c), written
    by the driver at bring-up and again after the chip lost them (a re-initialisation)."""
    need("otos")
    from mm_beagle.node.otos_calibration import otos_options
    from mm_pc.core.calibration import Calibration, SensorCalibration

    dev = "/dev/spidev1.0"
    cal = Calibration({dev: SensorCalibration(scale_x=1.04, scale_y=1.04, x=0.05, y=0.02)})
    path = tmp_path / "cal.yaml"
    cal.save(path)
    opts = otos_options([dev], ["otos"], str(path), [0.049, -0.0395, 0.0])
    assert opts[dev]["linear_scalar"] == pytest.approx(1.04)
    assert opts[dev]["offset"] == pytest.approx((-0.02, 0.05, 0.0))  # OTOS frame: -y, x
    assert otos_options([dev], ["pln2033"], str(path), [0, 0, 0]) == {}
    rig = Rig(["otos"])
    rig.poller.cfg.device_options = opts
    ch, emu = rig.poller.channels[0], rig.emus[0]
    rig.poller.try_init(ch, rig.clock.t)
    assert ch.driver.linear_scalar == pytest.approx(1.04)
    assert emu.linear_scalar == pytest.approx(1.04, abs=0.001)  # the chip's register
    emu.power_cycle()  # the chip forgets
    assert emu.linear_scalar == 1.0
    rig.poller.try_init(ch, rig.clock.t)
    assert emu.linear_scalar == pytest.approx(1.04, abs=0.001)
    bad = Calibration({dev: SensorCalibration(scale_x=1.3, scale_y=1.3)})
    bad.save(path)
    with pytest.raises(ValueError, match="calibration_file"):
        otos_options([dev], ["otos"], str(path), [0.049, -0.0395, 0.0])


def test_srom_file_goes_to_srom_chips_and_is_ignored_by_the_others(tmp_path):
    """srom_file (in patch_dir) is uploaded and verified at bring-up of a PMW3360; the
    PLN2033 next to it takes the patch_file rule, and a PMW3901 ignores both, said once."""
    need("pmw3360")
    need("pmw3901")
    from mm_beagle.poller.poller import poller_config
    from pln2033.pmw33xx import regs as R  # noqa: N812

    blob = bytes((i * 7 + 3) & 0xFF for i in range(R.SROM_LENGTH))
    (tmp_path / "srom.bin").write_bytes(blob)
    values = {
        "devices": ["/dev/spidev1.0", "/dev/spidev1.1"], "backend": "sim", "cpi": 1600,
        "poll_rate": 1000.0, "spi_speed_hz": 3_000_000, "register_map": "", "patch_file": "",
        "patch_dir": str(tmp_path), "srom_file": "srom.bin", "realtime_priority": 0,
        "retry_interval": 1.0, "chips": ["pmw3360", "pmw3901"], "chip_options": {},
    }  # fmt: skip
    cfg = poller_config(values, 4096, SimConfig())
    assert cfg.srom_file == str((tmp_path / "srom.bin").resolve())
    rig = Rig(["pmw3360", "pmw3901"], [{"srom": blob}, {}])
    rig.poller.cfg.srom_file = cfg.srom_file
    rig.poller.firmware["pmw3360"] = list(blob)
    ch = rig.poller.channels[0]
    rig.poller.try_init(ch, rig.clock.t)
    assert ch.driver is not None and ch.driver.srom_version == 0x04
    assert rig.emus[0].srom_running and rig.emus[0].srom_intact
    # the firmware kinds as the poller reads them from the config
    pol = Poller(cfg, rig.state, Pipe()[1], Pipe()[1])
    assert pol.firmware["pmw3360"] == list(blob) and pol.firmware["pmw3901"] is None
    assert any("takes no firmware: srom_file ignored" in n for n in pol.notes)
    with pytest.raises(ValueError, match="outside patch_dir"):
        poller_config({**values, "srom_file": "/etc/hostname"}, 4096, SimConfig())
