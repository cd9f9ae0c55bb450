"""/diagnostics levels from one period's polls (mm_beagle.node.health), no ROS."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mm_beagle.node import health
from mm_beagle.poller.shared_state import STATE_STARTING, STATE_UP, Totals
from pln2033 import INCH_M


def _polls(n, period_ns=1_000_000, start=10**18, counts=10):
    t = start + np.arange(n, dtype=np.int64) * period_ns
    return t, np.full(n, counts), np.full(n, counts)


def test_a_steady_period_is_ok():
    t, dx, dy = _polls(500)
    gap = health.longest_gap(t, dx, dy, int(t[0]) - 1_000_000, int(t[-1]) + 500_000)
    assert math.isclose(gap.seconds, 0.001)
    assert math.isclose(gap.speed_y, 10_000, rel_tol=0.01)  # 10 counts per 1 ms poll
    assert health.assess(1000.0, 1000.0, 0, gap, 1600)[:2] == ("OK", "up")


def test_low_rate_overruns_and_a_stall_each_warn():
    t, dx, dy = _polls(500)
    ok = health.longest_gap(t, dx, dy, 0, int(t[-1]) + 1)
    level, text, _ = health.assess(949.0, 1000.0, 0, ok, 1600)
    assert level == "WARN" and "949 Hz" in text
    assert health.assess(990.0, 1000.0, 3, ok, 1600)[:2] == ("WARN", "3 overruns")
    stalled = np.concatenate([t[:250], t[250:] + 60_000_000])  # 60 ms without a poll
    gap = health.longest_gap(stalled, dx, dy, 0, int(stalled[-1]) + 1)
    assert math.isclose(gap.seconds, 0.061)
    level, text, values = health.assess(1000.0, 1000.0, 0, gap, 1600)
    assert level == "WARN" and "stall" in text and values["longest_poll_gap_ms"] == "61.0"
    # 49 ms is not a stall; a first period (rate nan) is not judged on rate
    short = np.concatenate([t[:250], t[250:] + 48_000_000])
    gap = health.longest_gap(short, dx, dy, 0, int(short[-1]) + 1)
    assert health.assess(float("nan"), 1000.0, 0, gap, 1600)[0] == "OK"


def test_a_gap_that_wraps_the_counter_is_an_error_with_the_estimated_loss():
    """The issue's case: 4 s without a poll at ~16 000 counts/s (0.25 m/s at 1600 CPI)."""
    t, dx, dy = _polls(500, counts=16)
    # the poll after the gap read a wrapped (garbage) value: it must not set the speed
    t2 = np.concatenate([t, [int(t[-1]) + 4_000_000_000]])
    dx2, dy2 = np.append(dx, -30_000), np.append(dy, 31_000)
    gap = health.longest_gap(t2, dx2, dy2, 0, int(t2[-1]) + 1)
    assert math.isclose(gap.seconds, 4.0)
    assert math.isclose(gap.speed_y, 16_000, rel_tol=0.01)
    level, text, values = health.assess(200.0, 1000.0, 0, gap, 1600)
    assert level == "ERROR" and "wrapped" in text
    assert values["est_wrap_loss_counts"] == 65_536  # 64 000 counts in the gap: one wrap
    assert values["est_wrap_loss_m"] == f"{65_536 * INCH_M / 1600:.3f}"  # 1.040 m
    # the same gap while standing still is only a stall
    still = health.longest_gap(t2, dx2 * 0, dy2 * 0, 0, int(t2[-1]) + 1)
    assert health.assess(200.0, 1000.0, 0, still, 1600)[0] == "WARN"


def test_a_stall_going_on_now_counts():
    t, dx, dy = _polls(100)
    gap = health.longest_gap(t, dx, dy, 0, int(t[-1]) + 300_000_000)
    assert math.isclose(gap.seconds, 0.3)
    assert health.longest_gap([], [], [], 5, 5 + 200_000_000).seconds == 0.2


def _round(**kw) -> health.PollerRound:
    values = dict(
        period_p50_us=1000.2, period_p99_us=1180.7, late_polls=3, overruns=1,
        cpu_percent=12.34, restarts=0, link={},
    )  # fmt: skip
    return health.PollerRound(**{**values, **kw})


def _up(**kw) -> Totals:
    base = dict(state=STATE_UP, seq=5000, cpi_y=1600, x_total=120, y_total=-40, spi_errors=2)
    return dataclasses.replace(Totals.zero(7), **{**base, **kw})


OK = ("OK", "up", {"longest_poll_gap_ms": "1.0", "gap_est_counts": "0"})


def test_a_sensor_status_carries_the_snapshot_and_the_round():
    level, text, values = health.sensor_status(
        _round(link={"link_age_ms": "4.0"}), "pmw3360", _up(quality=37), 999.94, "", OK,
        "down?", (2, 0),
    )  # fmt: skip
    assert (level, text) == ("OK", "up")
    assert values["chip"] == "pmw3360" and values["state"] == "up"
    assert values["polls"] == 5000 and values["achieved_rate_hz"] == "999.9"
    assert (values["period_p50_us"], values["period_p99_us"]) == ("1000", "1181")
    assert (values["late_polls"], values["overruns"], values["spi_errors"]) == (3, 1, 2)
    assert (values["x_total_counts"], values["y_total_counts"], values["cpi"]) == (120, -40, 1600)
    assert values["quality"] == 37 and values["poller_cpu_percent"] == "12.3"
    assert values["link_age_ms"] == "4.0" and values["longest_poll_gap_ms"] == "1.0"
    assert "sim_generated_x_counts" not in values  # not the sim backend, no ground truth
    _, _, sim = health.sensor_status(_round(sim=True), "pln2033", _up(gen_x=9), 1000.0, "",
                                     OK, "", (2, 0))  # fmt: skip
    assert sim["sim_generated_x_counts"] == 9 and sim["sim_lift_lost_y_counts"] == 0


def test_the_status_level_goes_by_the_worst_of_its_causes():
    warn = ("WARN", "3 overruns", {})
    error = ("ERROR", "counter may have wrapped", {})

    def status(r=None, t=None, assessed=OK, errors_before=(2, 0)):
        level, text, _ = health.sensor_status(
            r or _round(), "pln2033", t or _up(), 1000.0, "gone", assessed,
            "sensor /dev/a is down (gone)", errors_before,
        )  # fmt: skip
        return level, text

    assert status(assessed=warn) == ("WARN", "3 overruns")
    assert status(errors_before=(1, 0)) == (
        "WARN", "SPI errors or counter overflows since last report",
    )  # fmt: skip
    assert status(errors_before=(1, 0), assessed=warn)[1].endswith("; 3 overruns")
    assert status(assessed=error, errors_before=(1, 0)) == ("ERROR", "counter may have wrapped")
    down = _up(state=STATE_STARTING)
    assert status(t=down, assessed=error) == ("ERROR", "sensor /dev/a is down (gone)")
    assert status(_round(unavailable="agent unreachable"), down) == ("ERROR", "agent unreachable")
    stuck = _round(stuck="poller stuck", unavailable="agent unreachable")
    assert status(stuck, down) == ("ERROR", "poller stuck")
