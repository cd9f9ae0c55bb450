"""mm-beagle's own odometry hands the polls' lift flags to the pose math.

Two sensors driven straight ahead at 10 counts per poll, sensor 0 lifted for ten
polls (it reads nothing): ``two-sensor`` drops it for those polls and stays straight,
``exact`` takes sensor 1's split for them.
"""

from __future__ import annotations

import pytest

from mm_beagle.node.onboard_odometry import OnboardOdometry
from mm_beagle.node.params import OdometrySettings
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.channel import Channel
from pln2033 import INCH_M, Motion

MOUNTS = [(0.049, -0.0395, 0.0), (0.049, 0.0395, 0.0)]


def channel(state: ss.SharedState, i: int) -> Channel:
    ch = Channel(i, f"/dev/spidev1.{i}", state, state.ring_size)
    ch.set_cpi_cache(1600, 1600)
    return ch


def motion(dy: int, lifted: bool = False) -> Motion:
    return Motion(0, dy, 0x80 if dy else 0, lifted, bool(dy), False)


def settings(method: str) -> OdometrySettings:
    return OdometrySettings(20.0, method, 0, MOUNTS, "", "odom", "base_link")


def drive(method: str, lift: bool) -> OnboardOdometry:
    state = ss.SharedState(bytearray(ss.SharedState.size(2, 256)), 2, 256)
    chans = [channel(state, 0), channel(state, 1)]
    odo = OnboardOdometry(settings(method), ["/dev/spidev1.0", "/dev/spidev1.1"], state)
    for k in range(100):
        lifted = lift and 40 <= k < 50
        chans[0].record(1_000_000 * (k + 1), motion(0 if lifted else 10, lifted=lifted))
        chans[1].record(1_000_000 * (k + 1), motion(10))
    assert odo.step() is not None
    return odo


@pytest.mark.parametrize("lift", [False, True])
def test_two_sensor_drops_the_lifted_sensor_for_its_polls(lift):
    odo = drive("two-sensor", lift)
    p = odo.odometry.pose
    assert p.yaw == pytest.approx(0.0, abs=1e-12)
    assert p.x == pytest.approx(1000 * INCH_M / 1600, rel=1e-12)
    assert odo.odometry.lifted_samples == (10 if lift else 0)


def test_exact_switches_to_the_other_sensor_while_its_own_is_lifted():
    """(Before issue 28 it integrated its own sensor's nothing: x of 900 counts.)"""
    odo = drive("exact", lift=True).odometry
    p = odo.pose
    assert p.x == pytest.approx(1000 * INCH_M / 1600, rel=1e-12)  # no count lost
    assert p.yaw == 0.0
    assert odo.switched_samples == 10 and odo.lifted_samples == 10
