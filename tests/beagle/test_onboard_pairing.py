"""mm-beagle's onboard odometry pairs the sensors' polls by tick, as mm-odometry does.

Each sensor's CPI change adds a command read (the drain at the old CPI) to its ring, so
between the two sensors' changes one ring holds an entry more: paired by ring position
(before), every later poll of that sensor met the other's poll of the previous tick.
Here the counts change every tick, the sensors change CPI 50 ticks apart, and the onboard
pose must equal the per-tick integration (each drain summed into the next tick at its
own CPI), whatever the step boundaries, also a step taken between the two sensors' reads
of one tick.
"""

from __future__ import annotations

import numpy as np
import pytest

from mm_beagle.node.onboard_odometry import OnboardOdometry
from mm_beagle.node.params import OdometrySettings
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.channel import Channel
from mm_pc.core.geometry import SensorMount
from mm_pc.core.odometry import Odometry
from pln2033 import INCH_M, Motion

MOUNTS = [(0.049, -0.0395, 0.0), (0.049, 0.0395, 0.0)]
DEVICES = ["/dev/spidev1.0", "/dev/spidev1.1"]
TICKS = 200
CHANGE_AT = (100, 150)  # the tick after which sensor 0 / sensor 1 goes to 800 CPI


def counts(i: int, k: int) -> tuple[int, int]:
    """Sensor ``i``'s counts in tick ``k`` (1..TICKS): a turn that keeps changing."""
    return (k % 3) - 1 + i, 10 + (k * (3 + 2 * i)) % 7


def run(method: str, steps_after: set[int], delay_ns: int = 0):
    """The onboard odometry after the run, and each tick's true metres (TICKS, 2, 2).
    ``delay_ns``: sensor 1 read that long after sensor 0 in each tick."""
    state = ss.SharedState(bytearray(ss.SharedState.size(2, 1024)), 2, 1024)
    chans = [Channel(i, DEVICES[i], state, state.ring_size) for i in (0, 1)]
    for ch in chans:
        ch.set_cpi_cache(1600, 1600)
    odo = OnboardOdometry(
        OdometrySettings(20.0, method, 0, MOUNTS, "", "odom", "base_link"), DEVICES, state
    )
    want = np.zeros((TICKS, 2, 2))  # per tick, each read at its own CPI (m)
    cpi = [1600, 1600]
    for k in range(1, TICKS + 1):
        tick = 1_000_000 * k
        for i, ch in enumerate(chans):
            if k == CHANGE_AT[i] + 1:  # the drain read between two ticks, then 800
                drain = (1 + i, 4)
                ch.record(tick - 400_000, Motion(*drain, 0x80, False, True, False),
                          ss.FLAG_COMMAND_READ)  # fmt: skip
                want[k - 1, i] += np.array(drain) * INCH_M / cpi[i]
                cpi[i] = 800
                ch.set_cpi_cache(800, 800)
            c = counts(i, k)
            ch.record(tick + i * delay_ns, Motion(*c, 0x80, False, True, False))
            want[k - 1, i] += np.array(c) * INCH_M / cpi[i]
            if i == 0 and k == 130 and k in steps_after:
                odo.step()  # sensor 1 has not been read in this tick yet: it waits
        if k in steps_after:
            odo.step()
    return odo, want


@pytest.mark.parametrize("method", ["two-sensor", "exact"])
@pytest.mark.parametrize("steps_after", [{TICKS}, {37, 101, 130, 149, 151, TICKS}])
def test_polls_are_paired_by_tick_across_the_drain_reads(method, steps_after):
    odo, want = run(method, steps_after)
    assert odo.next_seq == [TICKS + 1, TICKS + 1]  # every poll and both drains used
    ref = Odometry([SensorMount(*m) for m in MOUNTS], method=method)
    ref.integrate(np.full(TICKS, 1e-3), want)
    got, exp = odo.odometry.pose, ref.pose
    assert (got.x, got.y, got.yaw) == pytest.approx((exp.x, exp.y, exp.yaw), abs=1e-12)


def test_a_later_read_of_the_same_tick_is_paired_with_it_and_deskewed():
    """Sensor 1 read 0.15 ms after sensor 0: the same ticks (deskew moves its reads back
    to the tick, holding back 0.15 of its newest read, up to 2.4 counts here)."""
    odo, want = run("two-sensor", {37, 101, 130, 149, 151, TICKS}, delay_ns=150_000)
    assert odo.next_seq == [TICKS + 1, TICKS + 1]
    ref = Odometry([SensorMount(*m) for m in MOUNTS], method="two-sensor")
    ref.integrate(np.full(TICKS, 1e-3), want)
    got, exp = odo.odometry.pose, ref.pose
    count = 3 * INCH_M / 800
    assert abs(got.x - exp.x) < count and abs(got.y - exp.y) < count
    assert abs(got.yaw - exp.yaw) < count / 0.079
