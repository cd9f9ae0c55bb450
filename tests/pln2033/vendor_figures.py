"""The vendor-agreement figures of docs/sensors.md (issue 26), printed, not asserted (the
vendor tests assert them). Not collected by the suite (no test_ prefix). From the repository:

    install/venv/bin/python -m pytest -q -s -p no:cacheprovider tests/pln2033/vendor_figures.py

Reuses the vendor tests' fakes."""

import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from fakes import FakeClock
from test_pmw33xx_timing import BLOB, arduino_sketch_init, qmk_style_init
from test_vendor_otos import T0, ConstantYawRate, Ramp, bench, regs, started  # noqa: F401
from test_vendor_pmw3901 import CHIPS, Bench, counts_per_metre, run_both

from pln2033.chips import make_driver, make_emulator
from pln2033.motion import ConstantVelocity


def test_otos_figures(bench):  # noqa: F811
    ft, emu, _k, otos = started(bench)
    t0 = ft.t
    ramp = Ramp(t0, a=0.6, v=0.3)
    emu.motion = ramp
    for dt in (0.4, 2.0):
        ft.t = t0 + dt
        p = otos.getPosition()
        tu = emu.t_update
        v, a = otos.getVelocity(), otos.getAcceleration()
        print(f"OTOS ramp t={dt:.1f}s: y {p.y:.5f} m truth {ramp.y(tu):.5f} "
              f"(diff {1000 * (p.y - ramp.y(tu)):+.2f} mm), x {p.x:+.5f}; "
              f"v {v.y:.4f} truth {ramp.speed(tu):.4f} m/s; a {a.y:.4f} m/s^2")
    for config in (0x0F, 0x0B):
        ft, emu, _k, otos = started(bench)
        otos.setSignalProcessConfig(config)
        t0 = ft.t
        emu.motion = Ramp(t0, a=1e9, v=0.3)
        emu.heading_source = ConstantYawRate(1.0, t_start=t0)
        ft.t = t0 + 1.0
        p = otos.getPosition()
        tu = emu.t_update - t0
        truth = ((0.3 * (math.cos(tu) - 1.0), 0.3 * math.sin(tu)) if config & regs.SP_ROT
                 else (0.0, 0.3 * tu))
        print(f"OTOS 0x{config:02X} 1 rad/s 0.3 m/s 1 s: ({p.x:+.4f}, {p.y:.4f}) m truth "
              f"({truth[0]:+.4f}, {truth[1]:.4f}); heading {p.h:.4f} truth {tu:.4f} rad "
              f"(diff {p.h - tu:+.1e})")
    for speed in (0.3, 1.0):
        ft, emu, _k, otos = started(bench, lift_windows=[(T0 + 1.0, T0 + 1.5)])
        t0 = ft.t
        emu.motion = Ramp(t0, a=1e9, v=speed)
        ft.t = t0 + 1.3
        print(f"OTOS lifted at {speed} m/s: status {otos.getStatus()}")


def test_pmw3901_figures(monkeypatch):
    for p in CHIPS:
        vendor_cls, emu_cls, drv_cls = p.values
        for read in ("get_motion", "get_motion_slow"):
            b = Bench(monkeypatch)
            vs, ours, emu, dt = run_both(b, vendor_cls, emu_cls, drv_cls, read, 0.12, 0.25, 200)
            cpm = counts_per_metre(emu)
            print(f"{p.id} {read}: pimoroni {vs}, ours {ours}, emulator "
                  f"[{emu.stats.counted_x}, {emu.stats.counted_y}], truth "
                  f"[{0.12 * dt * cpm:.2f}, {0.25 * dt * cpm:.2f}]")


def test_pmw33xx_figures():
    for chip in ("pmw3360", "pmw3389"):
        clock = FakeClock(1.0)
        emu = make_emulator(chip, clock=clock, srom=BLOB)
        sid = qmk_style_init(chip, emu, clock)
        print(f"{chip} QMK-timed bring-up: SROM_ID {sid[0]:#04x}, errors "
              f"{emu.stats.protocol_errors} {dict(emu.timing_errors)}")
        clock = FakeClock()
        emu = make_emulator(chip, clock=clock, srom=BLOB)
        drv = make_driver(chip, emu, name="/dev/spidev1.0", sleep=clock.sleep)
        drv.initialise(1600, firmware=list(BLOB))
        for _ in range(200):
            clock.t += 0.001
            drv.read_motion()
        print(f"{chip} our driver (bring-up + SROM + 200 bursts): errors "
              f"{emu.stats.protocol_errors}")
    clock = FakeClock(1.0)
    emu = make_emulator("pmw3360", motion=ConstantVelocity(0.0, 0.1), clock=clock, srom=BLOB)
    bursts = []
    banner = arduino_sketch_init(emu, clock, bursts)
    print(f"pmw3360 Arduino-sketch bring-up: banner {[hex(v) for v in banner]}, SROM intact "
          f"{emu.srom_intact}, errors {emu.stats.protocol_errors} {dict(emu.timing_errors)}")


def test_otos_filter_lag_left_out(bench):  # noqa: F811
    """How far the firmware's own Kalman filters (run alongside in EmulatedOTOS) would put
    position and velocity from the truth: the lag the emulator does not model."""
    for a, v in ((0.6, 0.3), (1e9, 0.5)):
        ft, emu, _k, otos = started(bench)
        t0 = ft.t
        ramp = Ramp(t0, a=a, v=v)
        emu.motion = ramp
        for dt in (0.05, 0.2, 0.4, 1.0, 2.0):
            ft.t = t0 + dt
            otos.getPosition()
            tu = emu.t_update
            print(f"a={a:g} v={v}: t={dt:.2f}s truth y {ramp.y(tu):.4f} v {ramp.speed(tu):.3f}; "
                  f"emulator (lag-free) y {emu.sy:.4f} v {emu.vy:.3f}; firmware filter y "
                  f"{emu.kf_y.x[0]:.4f} v {emu.kf_y.x[1]:.3f} "
                  f"(pos lag {1000 * (ramp.y(tu) - emu.kf_y.x[0]):.1f} mm)")
