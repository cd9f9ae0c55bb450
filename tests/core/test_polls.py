"""Per-poll steps from get_samples replies (mm_pc.core.polls) against a simulated ring."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from fakes import FakeRing

from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.core.polls import PollBatch, PollSteps, PollTracker, SensorTotals
from mm_pc.sim import robot
from pln2033 import INCH_M


def _run(ring: FakeRing, boundaries, fetch=None, n_sensors=2):
    """Feed the tracker one request per boundary (polls done); (steps, tracker)."""
    tr = PollTracker(n_sensors)
    tr.baseline(ring.totals(0))
    parts = []
    for k in boundaries:
        batches = []
        for i in range(n_sensors):
            res = (fetch or ring.samples)(i, tr.cursor(i), k - tr.cursor(i), k)
            batches.append(None if res is None else PollBatch.from_reply(res))
        parts.append(tr.step(ring.totals(k), batches))
    return PollSteps.concat(parts, n_sensors), tr


def _pose(steps: PollSteps, method="exact"):
    odo = Odometry(DEFAULT_MOUNTS, method)
    odo.integrate(steps.dt, steps.d)
    return odo.pose.as_array()


@pytest.fixture(scope="module")
def s_curve_ring():
    v, w = robot.trajectory("s_curves")
    n = 20_000  # 20 s: enough turns and speed changes
    return FakeRing(v[:n], w[:n])


@pytest.mark.parametrize("hz", [1000.0, 15.0, 2.0, 0.2])
def test_pose_does_not_depend_on_the_request_rate(s_curve_ring, hz):
    ring = s_curve_ring
    ends = robot.request_boundaries(ring.n_polls, hz)
    steps, tr = _run(ring, ends)
    assert len(steps) == ring.n_polls and not steps.gap.any() and tr.gaps == 0
    # the per-poll counts add up to the totals' delta exactly
    assert np.array_equal(steps.counts.sum(axis=0), ring.cum[-1] - ring.cum[0])
    assert np.allclose(steps.dt, 0.001)
    one, _ = _run(ring, [ring.n_polls])
    for method in ("exact", "two-sensor"):
        assert np.allclose(_pose(steps, method), _pose(one, method), atol=1e-12, rtol=0)
    truth = robot.integrate_pose(ring.v, ring.w, robot.DT)[-1]
    # what is left is the 1600 CPI quantisation (floor: yaw lags by up to one count / 4.9 cm)
    assert np.hypot(*(_pose(steps)[:2] - truth[:2])) < 1e-3


def test_per_poll_is_exact_where_per_request_is_not(s_curve_ring):
    # a resolution so fine that quantisation does not hide the integration error
    ring = FakeRing(s_curve_ring.v, s_curve_ring.w, cpi=10**7)
    steps, _ = _run(ring, robot.request_boundaries(ring.n_polls, 15.0))
    truth = robot.integrate_pose(ring.v, ring.w, robot.DT)[-1]
    per_poll = np.hypot(*(_pose(steps)[:2] - truth[:2]))
    # the same counts summed per request and integrated as one twist each
    ends = robot.request_boundaries(ring.n_polls, 15.0)
    starts = np.concatenate([[0], ends[:-1]])
    d = (ring.cum[ends] - ring.cum[starts]) * ring.scale
    odo = Odometry(DEFAULT_MOUNTS)
    odo.integrate((ends - starts) * 1e-3, d)
    per_request = np.hypot(*(odo.pose.as_array()[:2] - truth[:2]))
    assert per_poll < 1e-6 and per_request > 1e-4  # 10 m of s_curves: ~9e-8 vs ~6 mm


def test_dropped_polls_make_one_marked_gap_with_the_totals_displacement(s_curve_ring):
    ring = s_curve_ring
    ring_small = FakeRing(ring.v[:8000], ring.w[:8000], ring_size=2000)
    ends = [1000, 2000, 7000, 8000]  # 5 s between the 2nd and 3rd request: the ring overran
    steps, tr = _run(ring_small, ends)
    assert tr.gaps == 1 and "left the node's ring buffer" in tr.gap_reasons[0]
    assert steps.gap.sum() == 1
    gi = int(np.flatnonzero(steps.gap)[0])
    assert steps.dt[gi] == pytest.approx(5.0)
    # the gap step carries exactly the totals' displacement of its interval
    assert np.allclose(steps.d[gi], (ring_small.cum[7000] - ring_small.cum[2000]) * ring.scale)
    # metres are conserved: the steps sum to the totals' delta
    assert np.allclose(steps.d.sum(axis=0), (ring_small.cum[-1] - ring_small.cum[0]) * ring.scale)
    # per-poll again after the gap
    assert len(steps) == 2000 + 1 + 1000


def test_a_failed_fetch_falls_back_to_the_totals(s_curve_ring):
    ring = FakeRing(s_curve_ring.v[:3000], s_curve_ring.w[:3000])
    calls = []

    def fetch(i, since, n, now):
        calls.append(now)
        return None if now == 2000 and i == 1 else ring.samples(i, since, n, now)

    steps, tr = _run(ring, [1000, 2000, 3000], fetch)
    assert tr.gaps == 1 and "no polls" in tr.gap_reasons[0]
    assert np.allclose(steps.d.sum(axis=0), ring.cum[-1] * ring.scale)
    # the per-poll steps before the gap are kept (no step lost, none doubled)
    assert len(steps) == 1000 + 1 + 1000


def test_polls_that_disagree_with_the_totals_are_not_used(s_curve_ring):
    ring = FakeRing(s_curve_ring.v[:2000], s_curve_ring.w[:2000])

    def fetch(i, since, n, now):
        res = ring.samples(i, since, n, now)
        if now == 2000:
            res.dx = np.array(res.dx) + 1
        return res

    steps, tr = _run(ring, [1000, 2000], fetch)
    assert tr.gaps == 1 and "sum to" in tr.gap_reasons[0]
    assert np.allclose(steps.d.sum(axis=0), ring.cum[-1] * ring.scale)


def test_command_reads_fold_into_the_next_tick_and_a_down_sensor_marks_a_gap():
    ms = 1_000_000
    t = np.array([10, 20, 25, 30, 40, 50, 60]) * ms
    flags0 = np.array([2, 2, 16, 2, 2, 2, 2])
    b0 = PollBatch.from_reply(SimpleNamespace(
        first_seq=0, next_seq=7, dropped=0, cpi=1000, stamp_ns=t,
        dx=[1, 1, 5, 1, 1, 1, 1], dy=[0] * 7, flags=flags0))
    # sensor 1 missed the ticks at 30 and 40 (down)
    b1 = PollBatch.from_reply(SimpleNamespace(
        first_seq=0, next_seq=4, dropped=0, cpi=1000, stamp_ns=np.array([10, 20, 50, 60]) * ms,
        dx=[2, 2, 2, 2], dy=[0] * 4, flags=[2] * 4))
    tr = PollTracker(2)
    tr.baseline([SensorTotals(0, 0, 0, 0, 0.0, 0.0)] * 2)
    s = INCH_M / 1000
    tot = [SensorTotals(7, 60 * ms, 11, 0, 11 * s, 0.0), SensorTotals(4, 60 * ms, 8, 0, 8 * s, 0.0)]
    steps = tr.step(tot, [b0, b1])
    assert list(steps.stamp_ns // ms) == [10, 20, 50, 60]
    assert list(steps.counts[:, 0, 0]) == [1, 1, 5 + 1 + 1 + 1, 1]
    assert list(steps.gap) == [False, False, True, False]  # sensor 0 alone at 30, 40
    assert list(steps.dt) == pytest.approx([0.01, 0.01, 0.03, 0.01])


def test_lifted_polls_are_filled_the_same_whatever_the_request_boundaries(s_curve_ring):
    n = 6000
    lifted = np.zeros((n, 2), bool)
    lifted[1500:1530, 0] = True  # sensor 0 lifted for 30 ms
    lifted[3990:4010, 1] = True  # sensor 1 lifted across a request boundary
    ring = FakeRing(s_curve_ring.v[:n], s_curve_ring.w[:n], lifted=lifted)
    a, _ = _run(ring, robot.request_boundaries(n, 15.0))
    b, _ = _run(ring, [1510, 1600, 4000, 4005, n])  # requests inside the lifts
    one, _ = _run(ring, [n])
    assert len(a) == len(b) == len(one) == n
    for s in (a, b):
        assert np.array_equal(s.lifted, one.lifted)
        assert np.allclose(s.d, one.d, atol=1e-15)
    assert one.lifted[:, 0].sum() == 30 and one.lifted[:, 1].sum() == 20
    # the filled polls are not zero: the lost motion is estimated
    assert np.all(one.d[1500:1530, 0, 1] > 0)


def test_a_low_quality_stretch_gives_the_pose_of_a_lift_there(s_curve_ring):
    """Flag 32 (surface quality below the chip's threshold) is treated like a lift: the
    junk counts the chip reported there are replaced by the gap fill, in both methods."""
    n = 6000
    v, w = s_curve_ring.v[:n], s_curve_ring.w[:n]
    stretch = np.zeros((n, 2), bool)
    stretch[1500:1560, 0] = True  # sensor 0 on a poor surface for 60 ms
    stretch[3990:4040, 1] = True  # sensor 1 across a request boundary
    junk = np.random.default_rng(3).integers(-40, 41, size=(n, 2, 2))
    lift = FakeRing(v, w, lifted=stretch)
    poor = FakeRing(v, w, low_quality=stretch, junk=junk, quality_ok=120, quality_low=4)
    ends = robot.request_boundaries(n, 15.0)
    a, _ = _run(lift, ends)
    b, _ = _run(poor, ends)
    assert len(a) == len(b) == n and np.array_equal(a.lifted, b.lifted)
    assert b.lifted.sum() == 110
    # the measured counts differ (the junk), the filled displacements do not
    assert not np.array_equal(a.counts, b.counts)
    assert np.allclose(a.d, b.d, atol=1e-15)
    for method in ("exact", "two-sensor"):
        pa, pb = _pose(a, method), _pose(b, method)
        assert np.allclose(pa, pb, atol=1e-12, rtol=0)
    # the same junk without the flag moves the pose: the rule is what makes them equal
    blind = FakeRing(v, w, low_quality=stretch, junk=junk)
    blind.low_quality[:] = False
    c, _ = _run(blind, ends)
    assert np.hypot(*(_pose(c)[:2] - _pose(a)[:2])) > 1e-3


@pytest.mark.parametrize("chip", ["otos", ""])
def test_low_quality_polls_of_a_chip_that_carries_motion_keep_their_counts(s_curve_ring, chip):
    """The OTOS's warning polls (flag 32) hold motion its IMU carried (its ChipInfo's
    poor_polls_carry_motion): with the totals' chip "otos" they are neither filled nor held
    back, the steps are those without the flag; with no chip named (an old node or
    recording) they are filled like a lift, as before."""
    n = 6000
    v, w = s_curve_ring.v[:n], s_curve_ring.w[:n]
    stretch = np.zeros((n, 2), bool)
    stretch[1500:1530, :] = True  # 30 ms of warnings on both sensors
    plain = FakeRing(v, w)
    flagged = FakeRing(v, w)
    flagged.low_quality[:] = stretch  # flag 32, the counts stay the motion
    totals = flagged.totals
    flagged.totals = lambda k: [t._replace(chip=chip) for t in totals(k)]
    ends = robot.request_boundaries(n, 15.0)
    a, _ = _run(plain, ends)
    b, _ = _run(flagged, ends)
    assert len(b) == n and np.array_equal(a.counts, b.counts)
    if chip:
        assert not b.lifted.any()
        assert np.array_equal(a.d, b.d)
    else:
        assert b.lifted.sum() == 60
        assert not np.allclose(a.d[1500:1530], b.d[1500:1530], atol=1e-9, rtol=0)


def test_unseen_bits_follow_the_chips_fact():
    from mm_pc.core.polls import FLAG_LIFT, FLAG_UNSEEN, unseen_bits

    assert unseen_bits("otos") == FLAG_LIFT
    for chip in ("", "pln2033", "pmw3901", "no-such-chip"):
        assert unseen_bits(chip) == FLAG_UNSEEN, chip


def test_unseen_is_the_lift_or_the_low_quality_bit():
    from mm_pc.core.polls import FLAG_LIFT, FLAG_LOW_QUALITY, FLAG_UNSEEN, unseen

    assert (FLAG_LOW_QUALITY, FLAG_UNSEEN) == (32, FLAG_LIFT | 32)
    assert unseen([0, 1, 2, 32, 34, 16, 33, 8]).tolist() == [
        False, True, False, True, True, False, True, False]


def test_an_open_lift_holds_the_steps_back_until_it_closes():
    n = 3000
    v, w = robot.trajectory("s_curves")
    lifted = np.zeros((n, 2), bool)
    lifted[900:1200, 0] = True
    ring = FakeRing(v[:n], w[:n], lifted=lifted)
    tr = PollTracker(2)
    tr.baseline(ring.totals(0))
    got = []
    for k in (1000, 1220, 1300, n):
        batches = [PollBatch.from_reply(ring.samples(i, tr.cursor(i), k - tr.cursor(i), k))
                   for i in range(2)]
        got.append(len(tr.step(ring.totals(k), batches)))
    assert got[0] == 900  # up to the lift
    assert got[1] == 0  # closed, but fewer than LIFT_CONTEXT_POLLS good polls after it
    assert sum(got) == n


def test_bad_replies_and_a_restart_are_refused():
    with pytest.raises(ValueError, match="holds 2 polls"):
        PollBatch.from_reply(SimpleNamespace(first_seq=0, next_seq=3, dropped=0, cpi=1600,
                                             stamp_ns=[1, 2], dx=[0, 0], dy=[0, 0], flags=[0, 0]))
    with pytest.raises(ValueError, match="every poll needs"):
        PollBatch.from_reply(SimpleNamespace(first_seq=0, next_seq=2, dropped=0, cpi=1600,
                                             stamp_ns=[1, 2], dx=[0], dy=[0, 0], flags=[0, 0]))
    with pytest.raises(ValueError, match="not a get_samples reply"):
        PollBatch.from_reply(object())
    tr = PollTracker(1)
    with pytest.raises(ValueError, match="before baseline"):
        tr.step([SensorTotals(1, 1, 0, 0, 0.0, 0.0)], [None])
    tr.baseline([SensorTotals(10, 1, 0, 0, 0.0, 0.0)])
    with pytest.raises(ValueError, match="restarted"):
        tr.step([SensorTotals(5, 2, 0, 0, 0.0, 0.0)], [None])
    with pytest.raises(ValueError, match="1 sensor"):
        tr.step([SensorTotals(11, 2, 0, 0, 0.0, 0.0)] * 2, [None, None])


def test_a_new_node_identity_is_a_restart_whatever_seq_says():
    tr = PollTracker(1)
    tr.baseline([SensorTotals(10, 1, 0, 0, 0.0, 0.0, instance_id=7)])
    same = [SensorTotals(10, 2, 0, 0, 0.0, 0.0, instance_id=7)]
    assert tr.restart_in(same) == ""
    later = [SensorTotals(50_000, 2, 900, 900, 0.01, 0.01, instance_id=8)]  # ran longer
    assert "identity changed" in tr.restart_in(later)
    with pytest.raises(ValueError, match="restarted"):
        tr.step(later, [None])
    assert "seq went back" in tr.restart_in([SensorTotals(5, 2, 0, 0, 0.0, 0.0, instance_id=7)])
    tr.baseline(later)  # what mm-odometry does on a restart
    assert tr.restart_in(later) == "" and tr.cursor(0) == 50_000


def test_polls_from_another_node_run_than_the_totals_are_a_gap():
    tr = PollTracker(1)
    tr.baseline([SensorTotals(0, 0, 0, 0, 0.0, 0.0, instance_id=7)])
    res = SimpleNamespace(first_seq=0, next_seq=2, dropped=0, cpi=1600, stamp_ns=[1, 2],
                          dx=[0, 0], dy=[1, 1], flags=[0, 0], instance_id=9)
    b = PollBatch.from_reply(res)
    assert b.instance_id == 9
    tr.step([SensorTotals(2, 2, 0, 2, 0.0, 2 * INCH_M / 1600, instance_id=7)], [b])
    assert tr.gaps == 1


def test_flags_agree_with_the_node():
    """One definition: polls and the board's shared state use mm_pc.core.poll_flags'."""
    from mm_beagle.poller import shared_state as ss
    from mm_pc.core import poll_flags, polls

    for name, bit in poll_flags.FLAGS.items():
        assert getattr(polls, name) is bit and getattr(ss, name) is bit
    assert sorted(poll_flags.FLAGS.values()) == [1 << k for k in range(6)]
    assert not hasattr(ss, "FLAG_SETTINGS_READ") and not hasattr(polls, "FLAG_SETTINGS_READ")


def test_sensor_polls_msg_constants_are_the_python_flags():
    """SensorPolls.msg declares the flag bits as constants: the same names and values."""
    import re
    from pathlib import Path

    from mm_pc.core import poll_flags

    msg = Path(__file__).parents[2] / "mm_interfaces" / "msg" / "SensorPolls.msg"
    consts = {
        name: int(value)
        for name, value in re.findall(r"^uint8\s+(FLAG_\w+)\s*=\s*(\d+)", msg.read_text(), re.M)
    }
    assert consts == poll_flags.FLAGS


def test_generated_sensor_polls_has_the_flags():
    """The built message module (./compile setup) carries the constants too."""
    from mm_pc.core import poll_flags

    msgs = pytest.importorskip("mm_interfaces.msg")
    for name, bit in poll_flags.FLAGS.items():
        assert getattr(msgs.SensorPolls, name) == bit


def test_totals_of_one_reply_a_tick_apart_are_no_gap(s_curve_ring):
    """The node reads the sensors' totals one after the other: sensor 1 may be a poll ahead."""
    ring = FakeRing(s_curve_ring.v[:3000], s_curve_ring.w[:3000])
    tr = PollTracker(2)
    base = ring.totals(1000)
    base[1] = ring.totals(1001)[1]
    tr.baseline(base)
    parts = []
    for k in (2000, 3000):
        now = ring.totals(k)
        now[0] = ring.totals(k - 1)[0]  # and the other way round
        batches = [PollBatch.from_reply(ring.samples(i, tr.cursor(i), now[i].seq - tr.cursor(i),
                                                     now[i].seq)) for i in range(2)]
        parts.append(tr.step(now, batches))
    steps = PollSteps.concat(parts, 2)
    assert tr.gaps == 0 and not steps.gap.any()
    got = steps.counts[:, 0].sum(axis=0)
    assert got.tolist() == (ring.cum[2999, 0] - ring.cum[1000, 0]).tolist()


def test_integrate_steps_hands_the_lift_mask_to_an_integrator_that_takes_it():
    from mm_pc.core.polls import integrate_steps

    steps = PollSteps(np.array([1, 2]), np.array([1e-3, 1e-3]), np.zeros((2, 2, 2)),
                      np.zeros((2, 2, 2), np.int64), np.array([[False, True], [False, False]]),
                      np.zeros(2, bool))
    got = {}

    class WithMask:
        def integrate(self, dt, d, return_residual=False, *, lifted=None):
            got["lifted"] = lifted
            return np.zeros((len(dt), 3))

    integrate_steps(WithMask(), steps)
    assert got["lifted"] is steps.lifted
    odo = Odometry(DEFAULT_MOUNTS)  # without the keyword (or without a lift): the plain call
    assert integrate_steps(odo, steps).shape == (2, 3)


def test_the_per_poll_figures_of_the_docs():
    """python -m mm_pc.bench.per_poll: per poll is exact in exact metres, per request not."""
    from mm_pc.bench.per_poll import per_poll_errors

    r = per_poll_errors("s_curves", 15.0)
    assert r["per_poll_error_m_exact_m"] < 1e-9 < 5e-4 < r["per_request_error_m_exact_m"]
    assert r["per_poll_error_m_1600cpi"] < r["per_request_error_m_1600cpi"]
    assert r["length_m"] == pytest.approx(10.1, abs=0.05)


def test_the_same_ticks_fast_path_pairs_exactly_as_the_general_matching():
    """Sensors polled on the same ticks (the poller's common case) take a cheap path; it
    must give what the general stamp matching gives, and step aside for anything else."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from mm_pc.core.polls import FLAG_COMMAND_READ, _Pending

    @settings(max_examples=200, deadline=None)
    @given(st.integers(1, 12), st.integers(0, 2**31), st.data())
    def check(k, seed, data):
        rng = np.random.default_rng(seed)
        stamps = np.cumsum(rng.integers(1, 3_000_000, k)).astype(np.int64) + 10**12
        flags_choice = st.sampled_from([0, 1, 2, 32, 33])
        tr = PollTracker(2)
        tr._last_stamp = 0  # as after a baseline
        pend = []
        for _ in range(2):
            flags = np.array(data.draw(st.lists(flags_choice, min_size=k, max_size=k)), np.int64)
            dx, dy = (rng.integers(-300, 300, k).astype(np.int64) for _ in range(2))
            cpi = np.array(data.draw(st.lists(st.sampled_from([800, 1600, 3200]),
                                              min_size=k, max_size=k)), np.int64)
            pend.append(_Pending(stamps.copy(), dx, dy, flags, cpi))  # CPI per poll
        fast = tr._same_ticks(pend)
        slow = tr._match_ticks(pend)
        assert fast is not None
        for a, b in zip(fast, slow, strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))

    check()
    # a command read, different stamps or a repeated stamp: the general path
    tr = PollTracker(2)
    s = np.array([1, 2, 3], np.int64)
    z = np.zeros(3, np.int64)
    c = np.full(3, 1600, np.int64)
    assert tr._same_ticks([_Pending(s, z, z, z, c), _Pending(s + 1, z, z, z, c)]) is None
    cmd = np.array([0, FLAG_COMMAND_READ, 0], np.int64)
    assert tr._same_ticks([_Pending(s, z, z, cmd, c), _Pending(s, z, z, z, c)]) is None
    rep = np.array([1, 1, 2], np.int64)
    assert tr._same_ticks([_Pending(rep, z, z, z, c), _Pending(rep, z, z, z, c)]) is None
