"""The lift fill follows time, not polls (pln2033.lift_fill with the polls' intervals).

A sensor speeding up linearly (15 000 + 60 000 t counts/s: 0.24 m/s rising at 1 m/s²
at 1600 CPI) polled every 1 ms, except one poll inside a 10-poll lift that stalled
30 ms. Floored cumulative counts, lifted polls count nothing, as the chip does. With
a linear speed the rule's straight line is exact, so what is left is the windows'
rounding: the fill must hit the true distance within the rule's sigma. The per-poll
rule gave the stalled poll one poll's worth (about 30 ms of motion lost); with regular
stamps the rule per unit of time is the per-poll rule, to the bit.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from mm_beagle.poller.lift_gap import LiftGapEstimator
from mm_pc.core.fill_variance import FillVariance
from mm_pc.core.filters import fill_lift_gaps
from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.core.polls import PollBatch, PollTracker, SensorTotals
from pln2033 import INCH_M
from pln2033.lift_fill import fill_gap, fill_sequence

CPI = 1600
SCALE = INCH_M / CPI
N = 200
GAP = (100, 110)  # lifted polls
STALL = 105  # this lifted poll took 30 ms
T0_NS = 1_700_000_000_000_000_000


def run(stall_s: float = 0.030):
    """(dt s, counts (N, 2) int, lifted (N,), true counts (N, 2) float) of the timed run."""
    dt = np.full(N, 1e-3)
    dt[STALL] += stall_s - 1e-3 if stall_s else 0.0
    t = np.concatenate([[0.0], np.cumsum(dt)])
    cum = np.stack([15_000 * t + 30_000 * t * t, 0.5 * (15_000 * t + 30_000 * t * t)], -1)
    true = np.diff(cum, axis=0)
    lifted = np.zeros(N, bool)
    lifted[GAP[0] : GAP[1]] = True
    inc = np.where(lifted[:, None], 0.0, true)
    counts = np.diff(np.floor(np.concatenate([[[0.0, 0.0]], np.cumsum(inc, 0)])), axis=0)
    return dt, counts.astype(np.int64), lifted, true


def test_a_stalled_lifted_poll_is_filled_with_its_own_time():
    dt, counts, lifted, true = run()
    truth = true[GAP[0] : GAP[1]].sum(0)
    for j in (0, 1):
        filled, gaps = fill_sequence(counts[:, j].tolist(), lifted.tolist(), dt=dt.tolist())
        (start, fill), = gaps  # fmt: skip
        err = math.fsum(filled[GAP[0] : GAP[1]]) - truth[j]
        assert start == GAP[0] and fill.total == pytest.approx(sum(filled[GAP[0] : GAP[1]]))
        assert abs(err) <= fill.sigma and abs(err) < 2.0  # a linear speed: rounding only
        # the stalled poll got 30 ms of motion: about 30 of its neighbours' counts
        assert filled[STALL] == pytest.approx(true[STALL, j], abs=1.0)
        # the per-poll rule gave it one poll's worth: off by far more than its own sigma
        old = fill_sequence(counts[:, j].tolist(), lifted.tolist())[0]
        old_err = math.fsum(old[GAP[0] : GAP[1]]) - truth[j]
        assert abs(old_err) > 0.7 * true[STALL, j] and abs(old_err) > 10 * fill.sigma


def test_regular_stamps_fill_exactly_as_the_per_poll_rule():
    dt, counts, lifted, _ = run(stall_s=0.0)
    assert (dt == 1e-3).all()
    for j in (0, 1):
        new = fill_sequence(counts[:, j].tolist(), lifted.tolist(), dt=dt.tolist())
        old = fill_sequence(counts[:, j].tolist(), lifted.tolist())
        assert new == old  # values and GapFill (total, sigma), bit for bit
    f = fill_gap(30.0, 3, 4, 80.0, 4, unit=0.5, t_before=0.006, t_gap=[0.002] * 4, t_after=0.008)
    assert f == fill_gap(30.0, 3, 4, 80.0, 4, unit=0.5)


def test_the_time_rule_is_the_per_poll_rule_scaled_when_every_interval_is_alike():
    """Intervals alike but for one ulp: the time arithmetic, the same figures to 1e-9."""
    dt, counts, lifted, _ = run(stall_s=0.0)
    dt[GAP[0]] = np.nextafter(dt[GAP[0]], 1.0)
    new, (gn,) = fill_sequence(counts[:, 0].tolist(), lifted.tolist(), dt=dt.tolist())
    old, (go,) = fill_sequence(counts[:, 0].tolist(), lifted.tolist())
    assert new == pytest.approx(old, rel=1e-9)
    assert gn[1].sigma == pytest.approx(go[1].sigma, rel=1e-9)
    assert gn[1].values is not None and go[1].values is None  # really the other arithmetic


def test_one_sided_gap_holds_the_rate_per_second():
    f = fill_gap(30.0, 3, 3, 0.0, 0, t_before=0.003, t_gap=[0.001, 0.030, 0.001])
    assert f.per_poll() == pytest.approx([10.0, 300.0, 10.0])
    assert f.total == pytest.approx(320.0)
    assert f.sigma == pytest.approx(math.sqrt((32 / 3) ** 2 / 6 + 320.0**2 / 12))


def test_bad_intervals_are_refused_or_fall_back_to_per_poll():
    with pytest.raises(ValueError, match="3 values but 2 intervals"):
        fill_sequence([1.0, 0.0, 1.0], [False, True, False], dt=[1.0, 1.0])
    with pytest.raises(ValueError, match="2 lifted polls but 1 intervals"):
        fill_gap(1.0, 1, 2, 1.0, 1, t_before=1.0, t_gap=[1.0], t_after=1.0)
    # a zero interval (stamps alike): no usable timing, the per-poll rule
    assert fill_gap(2.0, 1, 3, 10.0, 1, t_before=1.0, t_gap=[1.0, 0.0, 1.0], t_after=1.0) == (
        fill_gap(2.0, 1, 3, 10.0, 1)
    )


def tracker_steps(dt, counts, lifted, cuts=(N,)):
    """Both sensors alike (the same counts), through the PollTracker in requests."""
    stamps = T0_NS + np.round(np.cumsum(dt) * 1e9).astype(np.int64)
    cum = np.concatenate([[[0, 0]], np.cumsum(counts, 0)])

    def totals(k):
        s = int(stamps[k - 1]) if k else T0_NS
        x, y = int(cum[k, 0]), int(cum[k, 1])
        return [SensorTotals(k, s, x, y, x * SCALE, y * SCALE) for _ in range(2)]

    tr = PollTracker(2)
    tr.baseline(totals(0))
    out, k = [], 0
    for end in cuts:
        sl = slice(k, end)
        flags = np.where(lifted[sl], 1, 2)
        batch = PollBatch(k, end, 0, CPI, stamps[sl], counts[sl, 0], counts[sl, 1], flags)
        out.append(tr.step(totals(end), [batch, batch]))
        k = end
    return out


@pytest.mark.parametrize("cuts", [(N,), (60, 104, 107, 115, 130, N)])
def test_the_tracker_fills_a_stalled_lifted_poll_with_its_own_time(cuts):
    dt, counts, lifted, true = run()
    steps = tracker_steps(dt, counts, lifted, cuts)
    d = np.concatenate([s.d for s in steps])
    step_dt = np.concatenate([s.dt for s in steps])
    assert len(d) == N and step_dt == pytest.approx(dt, rel=1e-9)
    want, gaps = fill_lift_gaps(counts, lifted, dt=dt)  # the one rule, on the stamps' dt
    assert d[:, 0, :] == pytest.approx(want * SCALE, rel=1e-12, abs=1e-15)
    err = d[GAP[0] : GAP[1], 0, :].sum(0) / SCALE - true[GAP[0] : GAP[1]].sum(0)
    (_, _, sigma), = gaps  # fmt: skip
    assert (np.abs(err) <= sigma).all() and (np.abs(err) < 2.0).all()


def test_the_tracker_on_regular_stamps_fills_as_before():
    dt, counts, lifted, _ = run(stall_s=0.0)
    d = np.concatenate([s.d for s in tracker_steps(dt, counts, lifted, (70, 105, N))])
    old = fill_lift_gaps(counts, lifted)[0] * SCALE  # the per-poll rule, no intervals
    assert np.array_equal(d[:, 0, :], old) and np.array_equal(d[:, 1, :], old)


@pytest.mark.parametrize("method", ["exact", "two-sensor"])
def test_the_fill_variance_is_the_time_rules_sigma(method):
    """Both sensors lifted: the method integrates the fill of the sensors its body_map
    uses, so it adds the rule's sigma^2 (per unit of time, with the stall) of each."""
    dt, counts, lifted, _ = run()
    fv = FillVariance(2)
    odo = Odometry(DEFAULT_MOUNTS, method)
    var = sum(
        fv.of_steps(s, odo.body_map, [SCALE, SCALE])
        for s in tracker_steps(dt, counts, lifted, (60, 130, N))
    )
    (_, _, sigma), = fill_lift_gaps(counts, lifted, dt=dt)[1]  # fmt: skip
    (_, _, old), = fill_lift_gaps(counts, lifted)[1]  # fmt: skip
    want = float(np.max(sigma)) ** 2 * SCALE**2
    m = odo.body_map((True, True))
    used = [bool(m[:, 2 * k : 2 * k + 2].any()) for k in (0, 1)]
    assert used[0] and var == pytest.approx([want * u for u in used], rel=1e-9)
    assert float(np.max(old)) ** 2 * SCALE**2 < 0.5 * want  # the per-poll sigma was too small


def test_the_boards_estimate_follows_the_stamps():
    """LiftGapEstimator fed every poll with its stamp: the gap's total is the rule's on
    the same intervals, within sigma of the truth; primed from the ring the same."""
    dt, counts, lifted, true = run()
    stamps = T0_NS + np.round(np.cumsum(dt) * 1e9).astype(np.int64)
    want = [fill_sequence(counts[:, j].tolist(), lifted.tolist(), dt=(np.diff(
        stamps, prepend=T0_NS) / 1e9).tolist())[1][0][1] for j in (0, 1)]  # fmt: skip
    fed, primed = LiftGapEstimator(), LiftGapEstimator()
    a = GAP[0] - 20
    primed.prime(
        [(int(counts[k, 0]), int(counts[k, 1]), (stamps[k] - stamps[k - 1]) / 1e9)
         for k in range(a, GAP[0])], int(stamps[GAP[0] - 1]),
    )  # fmt: skip
    got = {}
    for k in range(N):
        x, y = int(counts[k, 0]), int(counts[k, 1])
        for name, est in (("fed", fed), ("primed", primed)):
            if name == "primed" and k < GAP[0]:
                continue
            r = est.update(x, y, bool(lifted[k]), int(stamps[k]))
            if r is not None:
                got[name] = r
    truth = true[GAP[0] : GAP[1]].sum(0)
    for name in ("fed", "primed"):
        x, y, sx, sy = got[name]
        assert (x, y, sx, sy) == pytest.approx(
            (want[0].total, want[1].total, want[0].sigma, want[1].sigma), rel=1e-12
        )
        assert abs(x - truth[0]) <= sx and abs(y - truth[1]) <= sy
    # without stamps: one poll's worth for the stall, as before
    plain = LiftGapEstimator()
    r = [plain.update(int(c[0]), int(c[1]), bool(f)) for c, f in zip(counts, lifted, strict=True)]
    x_old = next(v for v in r if v is not None)[0]
    (_, per_poll), = fill_sequence(counts[:, 0].tolist(), lifted.tolist())[1]  # fmt: skip
    assert x_old == pytest.approx(per_poll.total)
    assert truth[0] - x_old > 0.7 * true[STALL, 0]


def _rig_class():
    """tests/beagle/test_poller.py's Rig (a Poller on emulated sensors and a fake clock)."""
    path = Path(__file__).resolve().parents[1] / "beagle" / "test_poller.py"
    spec = importlib.util.spec_from_file_location("_test_poller_rig", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_poller_estimates_a_stalled_lift_with_its_time():
    """The board's poller (emulated sensor at 0.3 m/s, 1600 CPI): a 10 ms lift whose
    middle poll is 30 ms late. The estimate is within its sigma of what the lift ate
    (the per-poll rule lost about 29 ms of it: ~550 counts)."""
    tp = _rig_class()
    from pln2033.motion import ConstantVelocity

    t_lift = tp.T0 + 0.5
    rig = tp.Rig(
        [{"motion": ConstantVelocity(0.0, 0.3), "lift_windows": [(t_lift, t_lift + 0.040)]}]
    )
    ch = rig.channels[0]
    t = tp.T0
    for _ in range(1000):
        t += 0.030 if abs(t - (t_lift + 0.005)) < 0.0005 else tp.PERIOD
        rig.clock.t = t
        rig.poller.poll(ch, round(t * 1e9), t)
    snap = rig.snap(0)
    lost = 0.3 * (t - rig.t_init) * CPI / INCH_M - snap.y_total
    assert lost > 0.035 * 0.3 * CPI / INCH_M  # the stall is inside the lift: > 35 ms eaten
    sigma = snap.y_est_var_counts**0.5
    assert abs(snap.y_est_counts - lost) <= sigma + 2  # + the totals' own rounding
    assert not ch.gap.busy
