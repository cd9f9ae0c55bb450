"""A CPI change inside a request interval (issue 28 item 2): each poll scaled by its own
CPI (GetSamples' ``poll_cpi``), integrated exactly and no gap; an old node's reply
without ``poll_cpi`` still makes such an interval a gap step from the totals."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from cpi_ring import CpiRing

from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.core.polls import PollBatch, PollSteps, PollTracker
from mm_pc.sim import robot

N = 6000  # polls: 6 s of S-curves
CHANGES = {1234: 800, 3773: 3200}  # 1600 -> 800 -> 3200, inside request intervals


@pytest.fixture(scope="module", params=["poll", "command"])
def ring(request):
    """The drain read before each change as the poller records it today (a poll of that
    sensor alone) or as a command read (flag 16)."""
    v, w = robot.trajectory("s_curves")
    return CpiRing(v[:N], w[:N], 1600, CHANGES, drain=request.param)


def _run(ring, poll_ends, per_poll_cpi=True, batched=False):
    """Requests after the given poll counts; (steps, tracker)."""
    tr = PollTracker(2)
    tr.baseline(ring.totals(0))
    cursor = [t.seq for t in ring.totals(0)]
    items = []
    for p in poll_ends:
        tot = ring.totals(p)
        batches = [PollBatch.from_reply(ring.samples(i, cursor[i], tot[i].seq, per_poll_cpi))
                   for i in range(2)]  # fmt: skip
        cursor = [t.seq for t in tot]
        items.append((tot, batches))
    if batched:
        steps, _ = tr.step_many(items)
        return steps, tr
    return PollSteps.concat([tr.step(t, b) for t, b in items], 2), tr


def _pose(dt, d, method):
    odo = Odometry(DEFAULT_MOUNTS, method)
    odo.integrate(dt, d)
    return odo.pose.as_array()


@pytest.mark.parametrize("hz", [15.0, 100.0, 0.5])
@pytest.mark.parametrize("batched", [False, True])
def test_a_cpi_change_inside_an_interval_is_integrated_exactly_and_is_no_gap(ring, hz, batched):
    ends = [int(e) for e in robot.request_boundaries(N, hz)]
    # the changes (sensor 0's at c, sensor 1's at c + 3) fall inside intervals
    assert not any(c <= e <= c + 4 for c in CHANGES for e in ends)
    steps, tr = _run(ring, ends, batched=batched)
    assert tr.gaps == 0 and not steps.gap.any() and tr.gap_reasons == []
    assert len(steps) == N  # one step per poller tick (the drain read joins its tick)
    # every poll at its own CPI: the per-poll truth, to float rounding
    np.testing.assert_allclose(steps.d, ring.true_m, rtol=0, atol=1e-15)
    np.testing.assert_allclose(steps.d.sum(axis=0), ring.final_m, rtol=0, atol=1e-12)
    for method in ("exact", "two-sensor"):
        truth = _pose(steps.dt, ring.true_m, method)
        assert np.abs(_pose(steps.dt, steps.d, method) - truth).max() < 1e-12


def test_the_pose_across_cpi_changes_is_as_close_to_the_path_as_without(ring):
    """The path driven, not only the polls: 1600 -> 800 -> 3200 ends as near the true pose
    as 1600 throughout (what remains is each CPI's count quantisation)."""
    v, w = robot.trajectory("s_curves")
    truth = robot.integrate_pose(v[:N], w[:N], robot.DT)[-1]
    ends = [int(e) for e in robot.request_boundaries(N, 15.0)]
    steady = CpiRing(v[:N], w[:N], 1600, {})
    err = {}
    for name, r in (("changes", ring), ("steady", steady)):
        steps, tr = _run(r, ends)
        assert tr.gaps == 0
        p = _pose(steps.dt, steps.d, "exact")
        err[name] = float(np.hypot(*(p[:2] - truth[:2])))
    assert err["changes"] < 1e-3 and err["steady"] < 1e-3
    assert err["changes"] < 2 * err["steady"] + 2e-4


def test_an_old_nodes_reply_without_poll_cpi_makes_the_interval_a_gap_as_before(ring):
    ends = [int(e) for e in robot.request_boundaries(N, 15.0)]
    steps, tr = _run(ring, ends, per_poll_cpi=False)
    # each change (and its drain read) inside an interval: one gap step each, as before
    assert tr.gaps == len(CHANGES) == int(steps.gap.sum())
    assert all("the CPI changed within the interval" in r for r in tr.gap_reasons)
    # nothing lost: the gap steps carry the totals' displacement
    np.testing.assert_allclose(steps.d.sum(axis=0), ring.final_m, rtol=0, atol=1e-9)
    # the intervals without a change are per poll, as with poll_cpi
    new, _ = _run(ring, ends)
    keep = ~steps.gap
    assert keep.sum() == N - sum(
        int(np.diff(ends)[np.searchsorted(ends, c, side="right") - 1]) for c in CHANGES
    )
    on = np.isin(new.stamp_ns, steps.stamp_ns[keep])
    np.testing.assert_array_equal(steps.d[keep], new.d[on])


def test_a_cpi_change_at_a_request_boundary_was_and_is_no_gap():
    v, w = robot.trajectory("s_curves")
    r = CpiRing(v[:3000], w[:3000], 1600, {1000: 400}, drain=None, lag=0)
    for per_poll in (True, False):
        steps, tr = _run(r, [500, 1000, 2000, 3000], per_poll_cpi=per_poll)
        assert tr.gaps == 0
        np.testing.assert_allclose(steps.d, r.true_m, rtol=0, atol=1e-15)


def test_poll_cpi_joined_across_replies_and_old_replies():
    def res(first, cpis, cpi, per_poll=True):
        n = len(cpis)
        return SimpleNamespace(first_seq=first, next_seq=first + n, dropped=0, cpi=cpi,
                               stamp_ns=np.arange(first, first + n) + 1, dx=np.ones(n),
                               dy=np.ones(n), flags=np.zeros(n),
                               poll_cpi=cpis if per_poll else ())  # fmt: skip

    a = PollBatch.from_reply(res(0, [1600, 800], 800))
    b = PollBatch.from_reply(res(2, [800, 800], 800, per_poll=False))
    assert not a.one_cpi and b.one_cpi and b.poll_cpi is None
    j = PollBatch.join([a, b])
    assert list(j.cpis) == [1600, 800, 800, 800] and j.cpi == 800 and not j.one_cpi
    old = PollBatch.join([b, PollBatch.from_reply(res(4, [400], 400, per_poll=False))])
    assert old.poll_cpi is None and list(old.cpis) == [400, 400, 400]


@pytest.mark.parametrize(
    ("poll_cpi", "message"),
    [
        ([1600], "with 2 polls but 1 poll_cpi: one per poll or none"),
        ([1600, 0], "with a poll at cpi 0"),
        (["x", 1], "not a get_samples reply: poll_cpi"),
    ],
)
def test_a_bad_poll_cpi_is_refused_with_the_reason_and_changes_nothing(poll_cpi, message):
    """A peer's reply with poll_cpi of the wrong length or a zero CPI: a clear ValueError
    (the node and the monitor then treat the fetch as failed: a gap from the totals, no
    count lost), and the tracker is not touched."""
    res = SimpleNamespace(first_seq=0, next_seq=2, dropped=0, cpi=1600, stamp_ns=[1, 2],
                          dx=[1, 1], dy=[0, 0], flags=[0, 0], poll_cpi=poll_cpi)  # fmt: skip
    with pytest.raises(ValueError, match=r"poll_cpi|cpi 0") as e:
        PollBatch.from_reply(res)
    assert message in str(e.value) and "\n" not in str(e.value)
