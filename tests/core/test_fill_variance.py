"""The lift-fill variance mm-odometry adds to its covariance (mm_pc.core.fill_variance).

Polls of a FakeRing (1 kHz, 1600 CPI, an accelerating S-curve) through the PollTracker,
as mm-odometry gets them; the variance is the :mod:`pln2033.lift_fill` rule's sigma of
each gap whose filled counts the method really used.
"""

from __future__ import annotations

import numpy as np
import pytest
from fakes import FakeRing

from mm_pc.core.fill_variance import FillVariance
from mm_pc.core.filters import fill_lift_gaps
from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.core.polls import PollBatch, PollTracker
from pln2033 import INCH_M

N = 3000
UNIT = INCH_M / 1600


def ring_with(lift0=(), lift1=()) -> FakeRing:
    """v from 0.1 to 0.5 m/s, a turn; sensor 0 lifted in the ranges ``lift0``, 1 in ``lift1``."""
    t = np.arange(N) / 1000
    lifted = np.zeros((N, 2), bool)
    for i, ranges in enumerate((lift0, lift1)):
        for a, b in ranges:
            lifted[a:b, i] = True
    return FakeRing(0.1 + 0.4 * t / t[-1], 0.8 * np.sin(2 * np.pi * t / 3), lifted=lifted)


def steps_of(ring: FakeRing, cuts=(N,)):
    """The tracker's steps, one batch per request ending at each of ``cuts``."""
    tr = PollTracker(2)
    tr.baseline(ring.totals(0))
    out, k = [], 0
    for end in cuts:
        batches = [PollBatch.from_reply(ring.samples(i, k, end - k, end)) for i in (0, 1)]
        out.append(tr.step(ring.totals(end), batches))
        k = end
    return out


def variance(method: str, ring: FakeRing, cuts=(N,)) -> np.ndarray:
    fv = FillVariance(2)
    odo = Odometry(DEFAULT_MOUNTS, method)
    return sum(fv.of_steps(s, odo.body_map, [UNIT, UNIT]) for s in steps_of(ring, cuts))


def rule_var(ring: FakeRing, sensor: int, a: int, b: int) -> float:
    """The pln2033 rule's sigma^2 of the gap [a, b) of ``sensor``, m^2, the larger axis."""
    _, gaps = fill_lift_gaps(ring.counts[:, sensor, :], ring.lifted[:, sensor], unit=1.0)
    (sigma,) = [s for start, stop, s in gaps if (start, stop) == (a, b)]
    return float(np.max(sigma)) ** 2 * UNIT**2


@pytest.mark.parametrize("method", ["exact", "two-sensor"])
def test_one_sensor_lifted_adds_nothing_the_method_does_not_use_the_fill(method):
    assert not variance(method, ring_with(lift0=[(1000, 1400)])).any()
    assert not variance(method, ring_with(lift1=[(1000, 1400)])).any()


@pytest.mark.parametrize("method", ["exact", "two-sensor"])
def test_both_lifted_adds_the_rules_sigma_squared_of_the_used_sensors(method):
    ring = ring_with(lift0=[(1000, 1400)], lift1=[(1000, 1400)])
    var = variance(method, ring)
    want = [rule_var(ring, 0, 1000, 1400), rule_var(ring, 1, 1000, 1400)]
    assert want[0] > (1e-4) ** 2  # the speed changes within 0.4 s: a spread of ~mm
    if method == "exact":  # only its own sensor's fill is integrated
        assert var == pytest.approx([want[0], 0.0], rel=1e-12)
    else:
        assert var == pytest.approx(want, rel=1e-12)


def test_a_partly_used_gap_adds_its_share_squared():
    """Sensor 0 lifted 400 polls, sensor 1 for 100 of them: exact uses sensor 0's fill
    only there (switching to sensor 1 for the rest), so (100/400)^2 of its variance."""
    ring = ring_with(lift0=[(1000, 1400)], lift1=[(1200, 1300)])
    var = variance("exact", ring)
    assert var[0] == pytest.approx(rule_var(ring, 0, 1000, 1400) / 16, rel=1e-12)
    assert var[1] == 0.0


def test_the_figure_does_not_depend_on_where_requests_fell():
    ring = ring_with(lift0=[(1000, 1400), (2000, 2300)], lift1=[(1000, 1400), (2000, 2300)])
    one = variance("exact", ring)
    many = variance("exact", ring, cuts=(990, 1410, 1700, 1995, 2400, N))  # windows split
    assert many == pytest.approx(one, rel=1e-12) and one[0] > 0


def test_the_sigma_covers_the_fills_actual_error():
    """Honest, not decoration: the filled total's real error is within 2 sigma per axis."""
    ring = ring_with(lift0=[(1000, 1400)], lift1=[(1000, 1400)])
    filled, gaps = fill_lift_gaps(ring.counts[:, 0, :], ring.lifted[:, 0], unit=1.0)
    truth = FakeRing(ring.v, ring.w).counts[1000:1400, 0, :].sum(axis=0)
    (sigma,) = [s for start, _, s in gaps if start == 1000]
    assert np.all(np.abs(filled[1000:1400].sum(axis=0) - truth) <= 2 * sigma)


def test_a_gap_step_from_the_totals_starts_the_context_afresh():
    fv = FillVariance(2)
    odo = Odometry(DEFAULT_MOUNTS, "exact")
    ring = ring_with(lift0=[(1000, 1400)], lift1=[(1000, 1400)])
    (steps,) = steps_of(ring)
    fv.of_steps(steps, odo.body_map, [UNIT, UNIT])
    tr = PollTracker(2)
    tr.baseline(ring.totals(0))
    gap = tr.step(ring.totals(500), [None, None])  # no polls: one gap step
    assert len(gap) == 1 and gap.gap[0]
    assert not fv.of_steps(gap, odo.body_map, [UNIT, UNIT]).any()
    assert len(fv._ctx_counts) == 0
