"""The monitor's processing pipeline (no Qt, no ROS): totals, restarts, calibration, history."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mm_pc.core.calibration import Calibration, SensorCalibration
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.monitor.model.history import History
from mm_pc.monitor.model.session import MonitorSession
from mm_pc.monitor.model.sim_feed import DEFAULT_DEVICES, sim_replies
from mm_pc.sim.robot import guided_calibration_steps, integrate_pose, trajectory, with_mount_yaw

A, B = DEFAULT_DEVICES


def reply(seq: int, totals: dict[str, tuple[float, float]], lift=None, node=0) -> Reply:
    lift = lift or {}
    return Reply(
        tuple(
            Reading(
                id=d,
                stamp_ns=seq * 1_000_000,
                seq=seq,
                x_total=x,
                y_total=y,
                x_lift_total=lift.get(d, (0.0, 0.0))[0],
                y_lift_total=lift.get(d, (0.0, 0.0))[1],
                cpi=1600,
                instance_id=node,
            )
            for d, (x, y) in totals.items()
        )
    )


def test_first_reply_is_the_baseline_then_deltas_come_from_the_totals():
    s = MonitorSession()
    assert not s.process(reply(100, {A: (0.5, 1.0), B: (0.5, 1.0)}))  # node ran before us
    assert s.devices == (A, B)
    assert s.process(reply(110, {A: (0.5, 1.01), B: (0.5, 1.01)}))
    h = s.history
    assert len(h) == 1
    assert h.last("s0_raw_dy") == pytest.approx(0.01)
    assert h.last("dt") == pytest.approx(0.010)
    assert h.last("s0_vy") == pytest.approx(1.0)
    assert s.pose.x == pytest.approx(0.01)


def test_a_slow_reply_covers_the_gap_exactly_no_double_count():
    """Totals make the sum of deltas independent of how the replies were spaced."""
    fast, slow = MonitorSession(), MonitorSession()
    ys = np.linspace(0, 0.3, 31)
    for k, y in enumerate(ys):
        fast.process(reply(10 * k, {A: (0.0, y), B: (0.0, y)}))
        if k % 7 == 0 or k == len(ys) - 1:  # replies that came late, some lost
            slow.process(reply(10 * k, {A: (0.0, y), B: (0.0, y)}))
    assert fast.history.column("s0_raw_dy").sum() == pytest.approx(0.3)
    assert slow.history.column("s0_raw_dy").sum() == pytest.approx(0.3)
    assert slow.pose.x == pytest.approx(fast.pose.x)


def test_lift_estimates_are_added_only_when_enabled():
    on, off = MonitorSession(), MonitorSession(use_lift_estimates=False)
    for s in (on, off):
        s.process(reply(0, {A: (0, 0), B: (0, 0)}))
        s.process(reply(10, {A: (0, 0.1), B: (0, 0.1)}, lift={A: (0, 0.02), B: (0, 0.02)}))
    assert on.history.last("s0_raw_dy") == pytest.approx(0.12)
    assert off.history.last("s0_raw_dy") == pytest.approx(0.1)


def test_node_restart_rebaselines_without_a_jump():
    s = MonitorSession()
    s.process(reply(0, {A: (0, 0), B: (0, 0)}))
    s.process(reply(500, {A: (0, 0.1), B: (0, 0.1)}))
    x_before = s.pose.x
    assert not s.process(reply(20, {A: (0, 0.001), B: (0, 0.001)}))  # seq went back
    assert s.stats.restarts == 1
    assert s.pose.x == x_before
    assert s.process(reply(30, {A: (0, 0.011), B: (0, 0.011)}))
    assert s.pose.x == pytest.approx(x_before + 0.01)
    assert any(kind == "restart" for kind, _ in s.stats.events)


def test_a_restart_of_a_node_that_ran_longer_is_seen_by_its_identity():
    """The issue's case: the new node's seq is past the old one's, its totals unrelated."""
    s = MonitorSession()
    s.process(reply(0, {A: (0, 0), B: (0, 0)}, node=111))
    s.process(reply(500, {A: (0, 0.1), B: (0, 0.1)}, node=111))
    x_before = s.pose.x
    # a new node, 9000 polls in, 3 m driven (0 m then 3 m as seen by the counters)
    assert not s.process(reply(9000, {A: (0, 3.0), B: (0, 3.0)}, node=222))
    assert s.stats.restarts == 1
    assert s.pose.x == x_before  # no jump of 2.9 m
    assert s.process(reply(9010, {A: (0, 3.01), B: (0, 3.01)}, node=222))
    assert s.pose.x == pytest.approx(x_before + 0.01)
    assert [k for k, _ in s.stats.events].count("restart") == 1


def test_without_an_identity_the_longer_run_restart_was_a_jump():
    """What the identity fixes (and proof the test above can fail): same ids, a jump."""
    s = MonitorSession()
    s.process(reply(0, {A: (0, 0), B: (0, 0)}, node=111))
    s.process(reply(500, {A: (0, 0.1), B: (0, 0.1)}, node=111))
    assert s.process(reply(9000, {A: (0, 3.0), B: (0, 3.0)}, node=111))
    assert s.stats.restarts == 0 and s.pose.x == pytest.approx(3.0)


def test_a_reply_missing_a_sensor_is_kept_for_later_no_count_lost():
    s = MonitorSession()
    s.process(reply(0, {A: (0, 0), B: (0, 0)}))
    assert not s.process(reply(10, {A: (0, 0.05)}))
    assert s.stats.incomplete == 1
    assert s.process(reply(20, {A: (0, 0.1), B: (0, 0.1)}))
    assert s.history.column("s1_raw_dy").sum() == pytest.approx(0.1)
    assert s.history.column("s0_raw_dy").sum() == pytest.approx(0.1)


def test_non_finite_totals_are_rejected_and_change_nothing():
    s = MonitorSession()
    s.process(reply(0, {A: (0, 0), B: (0, 0)}))
    before = (s.pose, len(s.history), dict(s._prev))
    assert not s.process(reply(10, {A: (math.nan, 0.1), B: (0, 0.1)}))
    assert s.stats.rejected == 1
    assert (s.pose, len(s.history), dict(s._prev)) == before


def test_sim_figure_eight_matches_ground_truth():
    s = MonitorSession()
    for r in sim_replies("figure_eight", 50):
        s.process(r)
    v, w = trajectory("figure_eight")
    truth = integrate_pose(v, w, 0.001)[-1]
    assert s.pose.x == pytest.approx(truth[0], abs=2e-3)
    assert s.pose.y == pytest.approx(truth[1], abs=2e-3)


def test_calibration_run_keeps_the_pose_integrating_and_fits_the_mount():
    mounts = with_mount_yaw(DEFAULT_MOUNTS, math.radians(5))
    s = MonitorSession()
    replies = list(sim_replies("calibration_run", 50, mounts=mounts))
    s.process(replies[0])
    s.start_calibration()
    i = 1
    for kind, a, b in guided_calibration_steps():
        while replies[i].readings[0].seq < a - 200:
            s.process(replies[i])
            i += 1
        s.start_calibration_step(kind)
        with pytest.raises(ValueError, match=f"a {kind} step is recording; stop it first"):
            s.start_calibration_step("spin")
        while replies[i].readings[0].seq < b + 200:
            s.process(replies[i])
            i += 1
        assert s.calibration_step_check().ok
        assert s.stop_calibration_step().ok
    for r in replies[i:]:
        s.process(r)  # standing after Stop: nothing recorded
    assert s.calibrating and s.recording_step is None
    # the pose kept integrating (issue 29: a frozen pose resumed where the robot was not):
    # 0.5 m forward and back, then the spins, back where it started
    assert s.history.column("x").max() > 0.4
    assert s.pose.x == pytest.approx(0.0, abs=1e-3) and s.pose.y == pytest.approx(0.0, abs=1e-3)
    assert s.history.column("calibrating").min() == 1.0
    fit = s.compute_calibration(true_distance=0.5)
    cal = fit.calibration()
    for dev, m in zip(DEFAULT_DEVICES, DEFAULT_MOUNTS, strict=True):
        assert cal[dev].angle_offset_deg == pytest.approx(5.0, abs=0.05)
        assert fit.straight_run[dev].angle_offset_deg == pytest.approx(5.0, abs=0.05)
        assert cal[dev].scale_y == pytest.approx(1.0, abs=1e-3)
        assert cal[dev].x == pytest.approx(m.x, abs=3e-4)
        assert cal[dev].y == pytest.approx(m.y, abs=3e-4)
    s.finish_calibration(cal)
    assert not s.calibrating
    assert s.calibration == cal
    assert s.odometry.mounts == cal.mounts(DEFAULT_DEVICES, DEFAULT_MOUNTS)


def test_calibration_errors_say_what_to_do_and_apply_nothing():
    s = MonitorSession()
    s.process(reply(0, {A: (0, 0), B: (0, 0)}))
    with pytest.raises(ValueError, match="no calibration run in progress"):
        s.compute_calibration()
    with pytest.raises(ValueError, match="no calibration run in progress"):
        s.start_calibration_step("straight")
    s.start_calibration()
    with pytest.raises(ValueError, match="step kind must be one of"):
        s.start_calibration_step("wiggle")
    with pytest.raises(ValueError, match="no calibration step is recording"):
        s.stop_calibration_step()
    with pytest.raises(ValueError, match="no recorded calibration step to discard"):
        s.discard_calibration_step()
    s.start_calibration_step("straight")
    s.process(reply(10, {A: (0, 0.01), B: (0, 0.01)}))
    with pytest.raises(ValueError, match="still recording; press Stop first"):
        s.compute_calibration()
    check = s.stop_calibration_step()
    assert not check.ok and check.message.startswith("straight too short: 1.0 cm")
    with pytest.raises(ValueError, match=r"step 1 \(straight\): straight too short"):
        s.compute_calibration()
    s.finish_calibration(None)
    assert s.calibration == Calibration()


def test_calibration_is_applied_before_the_pose_math():
    cal = Calibration({A: SensorCalibration(math.radians(90), 1.0, 2.0)})
    s = MonitorSession(calibration=cal)
    s.process(reply(0, {A: (0, 0), B: (0, 0)}))
    s.process(reply(10, {A: (-0.01, 0), B: (0, 0.01)}))  # turned by 90 deg: X becomes Y
    assert s.history.last("s0_dy") == pytest.approx(-0.02)
    assert s.history.last("s0_dx") == pytest.approx(0.0, abs=1e-12)


def test_configure_odometry_validates_and_keeps_the_pose():
    s = MonitorSession()
    for r in sim_replies("straight", 20, seconds=1.0):
        s.process(r)
    pose = s.pose
    with pytest.raises(ValueError, match="unknown pose method"):
        s.configure_odometry(method="magic")
    with pytest.raises(ValueError, match="one mount per sensor"):
        s.configure_odometry(mounts=DEFAULT_MOUNTS[:1])
    with pytest.raises(ValueError):
        s.configure_odometry(mounts=(SensorMount(0.0, -0.04), SensorMount(0.0, 0.04)))
    assert (s.method, s.mounts, s.pose) == ("exact", DEFAULT_MOUNTS, pose)
    s.configure_odometry(method="two-sensor")
    assert s.method == "two-sensor"
    assert s.pose == pose


def test_filters_validate_and_clear():
    s = MonitorSession(devices=DEFAULT_DEVICES)
    with pytest.raises(ValueError, match="unknown sensor"):
        s.set_filter("/dev/nope", 5, True, False)
    with pytest.raises(ValueError):
        s.set_filter(A, 0, True, False)
    assert s.filters[A].window == 5 and not s.filters[A].filter_x
    s.set_filter(A, 7, True, False)
    assert (s.filters[A].window, s.filters[A].filter_x, s.filters[A].filter_y) == (7, True, False)
    s.clear_filters()
    assert not s.filters[A].filter_x


def test_reset_clears_history_and_pose_but_counting_continues():
    s = MonitorSession()
    feed = list(sim_replies("straight", 20, seconds=1.0))
    for r in feed[:10]:
        s.process(r)
    s.reset()
    assert len(s.history) == 0 and s.pose.x == 0.0
    for r in feed[10:]:
        s.process(r)
    assert s.pose.x == pytest.approx(
        feed[-1].readings[0].y_total - feed[9].readings[0].y_total, abs=1e-9
    )


def test_history_is_bounded_and_reports_dropped_rows():
    h = History(["a", "b"], max_rows=100, initial=8)
    for i in range(250):
        h.append((i, -i))
    assert len(h) <= 100
    assert h.last("a") == 249
    assert h.dropped_rows == 250 - len(h)
    col = h.column("a")
    assert np.all(np.diff(col) == 1)
    with pytest.raises(ValueError):
        col[0] = 5  # views are read-only
    h.extend(np.arange(40.0).reshape(20, 2))
    assert h.last("b") == 39
    with pytest.raises(ValueError, match="expected shape"):
        h.extend(np.zeros((3, 3)))
    with pytest.raises(KeyError, match="no column 'c'"):
        h.column("c")


def test_reading_from_msg_reads_every_field():
    @dataclasses.dataclass
    class Stamp:
        sec: int = 2
        nanosec: int = 5

    msg = type("Msg", (), {})()
    values = dict(
        id="/dev/x", stamp=Stamp(), seq=7, x_total_disp=0.1, y_total_disp=0.2,
        x_lift_est_total_disp=0.01, y_lift_est_total_disp=0.02, x_speed=1.0, y_speed=2.0,
        x_counts=3, y_counts=4, cpi=800, samples=10, lift_events=1, lift_events_total=2,
        interval=0.01, x_disp=0.001, y_disp=0.002, x_total_counts=6, y_total_counts=12,
        x_lift_est_counts=0.5, y_lift_est_counts=1.5, x_lift_est_disp=1e-5, y_lift_est_disp=2e-5,
    )  # fmt: skip
    for k, v in values.items():
        setattr(msg, k, v)
    r = Reading.from_msg(msg)
    assert r.stamp_ns == 2_000_000_005
    assert (r.x_total, r.y_lift_total, r.cpi, r.lift_events_total) == (0.1, 0.02, 800, 2)
    assert (r.x_disp, r.y_total_counts, r.y_lift_est_counts, r.y_lift_est_disp) == (
        0.001, 12, 1.5, 2e-5,
    )


# -- pose from the single polls (Reply.polls) ---------------------------------------------

DEVS = ("/dev/spidev1.0", "/dev/spidev1.1")


def _poll_replies(ring, ends, skip=()):
    """Replies at the given poll counts, each with the polls since the previous one (as the
    bridge fetches them); ``skip``: poll counts whose fetch of sensor 1 failed."""
    from fakes import FakeRing  # noqa: F401 - the ring's type

    from mm_pc.core.sensor_data import Reading, Reply

    out, cursor = [], None
    for k in ends:
        tot = ring.totals(k)
        readings = tuple(
            Reading(id=d, stamp_ns=t.stamp_ns, seq=t.seq, x_total=t.x_m, y_total=t.y_m,
                    x_total_counts=t.x_counts, y_total_counts=t.y_counts, cpi=ring.cpi)
            for d, t in zip(DEVS, tot, strict=True)
        )
        since = k if cursor is None else cursor
        polls = {d: (None if (k in skip and i == 1) else ring.samples(i, since, k - since, k))
                 for i, d in enumerate(DEVS)}
        out.append(Reply(readings, polls=polls))
        cursor = k
    return out


def test_pose_from_polls_is_the_same_with_a_five_second_pause():
    from fakes import FakeRing

    from mm_pc.sim.robot import request_boundaries

    v, w = trajectory("s_curves")
    ring = FakeRing(v[:15000], w[:15000])
    ends = [int(e) for e in request_boundaries(ring.n_polls, 15.0)]
    paused = [e for e in ends if not 4000 < e < 9000]  # no request for 5 s mid-turn
    poses, sessions = [], []
    for e in (ends, paused):
        s = MonitorSession(devices=DEVS)
        for r in _poll_replies(ring, [0, *e]):
            s.process(r)
        poses.append(s.pose.as_array())
        sessions.append(s)
    assert np.allclose(poses[0], poses[1], atol=1e-9)
    truth = integrate_pose(ring.v, ring.w, 0.001)[-1]
    assert np.hypot(*(poses[0][:2] - truth[:2])) < 5e-4  # 1600 CPI quantisation only
    for s in sessions:
        assert s.stats.polls == ring.n_polls and s.stats.gaps == 0 and s.stats.per_reply == 0
    # Graphs and Data keep the per-request values: one row per reply, the served sums
    h = sessions[1].history
    assert len(h) == len(paused)
    assert np.sum(h.column("s0_raw_dy")) == pytest.approx(ring.cum[-1, 0, 1] * ring.scale)
    big = np.argmax(h.column("dt"))
    assert h.column("dt")[big] == pytest.approx(5.0, abs=0.07)
    # the same replies without their polls: per-request integration, off by millimetres
    s = MonitorSession(devices=DEVS)
    for r in _poll_replies(ring, [0, *paused]):
        s.process(type(r)(r.readings))
    assert s.stats.per_reply == len(paused) and s.stats.polls == 0
    assert np.hypot(*(s.pose.as_array()[:2] - truth[:2])) > 3e-3


def test_the_map_follows_the_path_through_a_pause_not_its_chord():
    """The map's rows (map_history) of the reply that covers a 5 s pause are its per-poll
    poses: they lie on the true path, and the paused session's map matches the unpaused one."""
    from fakes import FakeRing

    from mm_pc.monitor.model.session import MAP_SPACING_M
    from mm_pc.sim.robot import request_boundaries

    v, w = trajectory("s_curves")
    ring = FakeRing(v[:15000], w[:15000])
    ends = [int(e) for e in request_boundaries(ring.n_polls, 15.0)]
    paused = [e for e in ends if not 4000 < e < 9000]
    s = MonitorSession(devices=DEVS)
    for r in _poll_replies(ring, [0, *paused]):
        s.process(r)
    m = s.map_history
    t, x, y = m.column("t"), m.column("x"), m.column("y")
    inside = (t > 4.1) & (t < 8.9)  # drawn inside the pause: only per-poll poses can be there
    travelled = float(np.sum(np.abs(v[4000:9000])) * 0.001)
    assert inside.sum() > 0.8 * travelled / MAP_SPACING_M
    truth = integrate_pose(ring.v, ring.w, 0.001)
    k = np.clip(np.round(t * 1000).astype(int) - 1, 0, len(truth) - 1)  # poll k ends at (k+1) ms
    off = np.hypot(x - truth[k, 0], y - truth[k, 1])
    assert off.max() < 1e-3  # on the path (1600 CPI quantisation), not on a 5 s chord
    assert (m.column("x")[-1], m.column("y")[-1]) == (s.pose.x, s.pose.y)
    # without the polls the map has one row per reply: the pause is one straight segment
    s2 = MonitorSession(devices=DEVS)
    for r in _poll_replies(ring, [0, *paused]):
        s2.process(type(r)(r.readings))
    assert len(s2.map_history) == len(s2.history) and not (
        (s2.map_history.column("t") > 4.1) & (s2.map_history.column("t") < 8.9)
    ).any()


def test_a_failed_poll_fetch_is_a_marked_gap_from_the_totals():
    from fakes import FakeRing

    v, w = trajectory("s_curves")
    ring = FakeRing(v[:3000], w[:3000])
    s = MonitorSession(devices=DEVS)
    for r in _poll_replies(ring, [0, 1000, 2000, 3000], skip=(2000,)):
        s.process(r)
    assert s.stats.gaps == 1 and len(s.gaps) == 1
    g = s.gaps[0]
    assert "no polls" in g.reason and g.t == pytest.approx(2.0)
    assert math.hypot(g.x1 - g.x0, g.y1 - g.y0) > 0.1  # the drawn stretch of the gap
    assert any(kind == "gap" for kind, _ in s.stats.events)
    assert s.stats.polls == 2000
    truth = integrate_pose(ring.v, ring.w, 0.001)[-1]
    assert np.hypot(*(s.pose.as_array()[:2] - truth[:2])) < 0.01  # the totals kept it close


def _map_keep_by_definition(poses: np.ndarray) -> list[int]:
    """The rule of ``_map_keep`` written out pose by pose: keep pose j (j >= 1) when the
    distance or the turn travelled since pose 0 enters a new multiple of the spacing;
    never pose 0 of a reply (unless it is the only one); always the last."""
    from mm_pc.monitor.model.session import MAP_SPACING_M, MAP_SPACING_RAD

    keep, dist, turn, bins = [], 0.0, 0.0, (0.0, 0.0)
    for j in range(1, len(poses)):
        dist += float(np.hypot(poses[j, 0] - poses[j - 1, 0], poses[j, 1] - poses[j - 1, 1]))
        turn += abs(poses[j, 2] - poses[j - 1, 2])
        now = (math.floor(dist / MAP_SPACING_M), math.floor(turn / MAP_SPACING_RAD))
        if now != bins or j == len(poses) - 1:
            keep.append(j)
        bins = now
    return keep if len(poses) > 1 else list(range(len(poses)))


def test_map_keep_keeps_the_poses_its_rule_names():
    from hypothesis import given, settings
    from hypothesis import strategies as st
    from hypothesis.extra.numpy import arrays

    from mm_pc.monitor.model.session import _map_keep

    steps = st.floats(-0.004, 0.004, allow_nan=False, allow_subnormal=False)

    @settings(max_examples=300, deadline=None)
    @given(arrays(float, st.tuples(st.integers(0, 12), st.just(3)), elements=steps))
    def check(deltas):
        poses = np.cumsum(deltas, axis=0)
        assert list(_map_keep(poses)) == _map_keep_by_definition(poses)

    check()


# -- replies delivered together (process_batch) ---------------------------------------------


def _batched(replies, n):
    return [replies[i : i + n] for i in range(0, len(replies), n)]


def _sessions_one_by_one_and_batched(replies, n=8):
    one, many = MonitorSession(devices=DEVS), MonitorSession(devices=DEVS)
    made = sum(one.process(r) for r in replies)
    assert sum(many.process_batch(b) for b in _batched(replies, n)) == made
    return one, many


def _assert_same_session(one: MonitorSession, many: MonitorSession) -> None:
    """Every history column bit for bit, the pose, the gaps and the counters."""
    assert len(one.history) == len(many.history)
    for c in one.history.columns:
        assert np.array_equal(one.history.column(c), many.history.column(c), equal_nan=True), c
    assert one.pose == many.pose
    assert list(one.gaps) == list(many.gaps)
    for f in ("replies", "used", "incomplete", "polls", "gaps", "baselines"):
        assert getattr(one.stats, f) == getattr(many.stats, f), f


def test_a_batch_gives_the_rows_and_pose_of_its_replies_one_by_one():
    """500 Hz replies in batches of 8 (a 60 Hz frame's worth): the same rows, values and
    per-poll pose as one reply at a time, bit for bit; fewer map rows (one forced per
    batch), ending at the pose."""
    from fakes import FakeRing

    from mm_pc.sim.robot import request_boundaries

    v, w = trajectory("s_curves")
    ring = FakeRing(v[:6000], w[:6000])
    ends = [int(e) for e in request_boundaries(ring.n_polls, 500.0)]
    one, many = _sessions_one_by_one_and_batched(_poll_replies(ring, [0, *ends]))
    assert len(one.history) == len(ends)
    _assert_same_session(one, many)
    for s in (one, many):
        assert s.stats.polls == ring.n_polls and s.stats.gaps == 0 and s.stats.used == len(ends)
    assert len(many.map_history) < len(one.map_history)
    assert (many.map_history.column("x")[-1], many.map_history.column("y")[-1]) == (
        many.pose.x, many.pose.y)  # fmt: skip


def test_a_lift_held_back_in_a_batch_is_in_the_row_of_the_reply_that_released_it():
    """A lift holds steps back until it has closed; a row's pose is the pose after the
    steps its own reply released, in a batch as one by one (it was the pose at the row's
    stamp: steps a later reply of the batch released were in the earlier rows)."""
    from fakes import FakeRing

    from mm_pc.sim.robot import request_boundaries

    v, w = trajectory("s_curves")
    lifted = np.zeros(4000, bool)
    lifted[1500:1540] = True
    ring = FakeRing(v[:4000], w[:4000], lifted=lifted)
    ends = [int(e) for e in request_boundaries(ring.n_polls, 500.0)]
    one, many = _sessions_one_by_one_and_batched(_poll_replies(ring, [0, *ends]))
    _assert_same_session(one, many)
    x, t = one.history.column("x"), one.history.column("t")
    held = np.flatnonzero(np.diff(x) == 0)  # rows whose reply released no step
    assert len(held) and t[held].min() >= 1.5 and t[held].max() < 1.7  # only at the lift


def test_a_failed_fetch_in_a_batch_is_a_gap_of_its_own_reply_only():
    """The polls of the other replies of the batch are integrated: the gap covers the
    failed reply's interval (2 ms at 500 Hz), as one by one."""
    from fakes import FakeRing

    from mm_pc.sim.robot import request_boundaries

    v, w = trajectory("s_curves")
    ring = FakeRing(v[:3000], w[:3000])
    ends = [int(e) for e in request_boundaries(ring.n_polls, 500.0)]
    bad = ends[len(ends) // 2]
    one, s = _sessions_one_by_one_and_batched(_poll_replies(ring, [0, *ends], skip=(bad,)))
    _assert_same_session(one, s)
    assert s.stats.gaps == 1 and len(s.gaps) == 1 and "no polls" in s.gaps[0].reason
    assert len(s.history) == len(ends)
    gap_polls = bad - ends[ends.index(bad) - 1]
    assert s.stats.polls == ring.n_polls - gap_polls
    truth = integrate_pose(ring.v, ring.w, 0.001)[-1]
    assert np.hypot(*(s.pose.as_array()[:2] - truth[:2])) < 1e-3


_GROUPING_CASE: dict = {}


def _grouping_case():
    """One run's replies (100 Hz, s_curves) with everything that used to depend on the
    grouping: lifts of one and of both sensors, a low-quality stretch, a failed fetch of
    sensor 1's polls, a reply missing sensor 1, replies a tick apart between the sensors
    are not made here (FakeRing stamps both alike); and the session one reply at a time."""
    if not _GROUPING_CASE:
        from fakes import FakeRing

        from mm_pc.sim.robot import request_boundaries

        v, w = trajectory("s_curves")
        n = 3000
        lifted = np.zeros((n, 2), bool)
        lifted[700:760, 0] = True  # one sensor
        lifted[1500:1530] = True  # both
        lowq = np.zeros((n, 2), bool)
        lowq[2200:2215, 1] = True
        ring = FakeRing(v[:n], w[:n], lifted=lifted, low_quality=lowq)
        ends = [int(e) for e in request_boundaries(ring.n_polls, 100.0)]
        replies = _poll_replies(ring, [0, *ends], skip=(ends[40],))
        j = 120  # sensor 1 missing from this reply: its polls wait for the next one
        replies[j] = Reply(replies[j].readings[:1], polls=replies[j].polls)
        one = MonitorSession(devices=DEVS)
        for r in replies:
            one.process(r)
        assert one.stats.gaps >= 1 and one.stats.incomplete == 1
        _GROUPING_CASE.update(replies=replies, one=one)
    return _GROUPING_CASE["replies"], _GROUPING_CASE["one"]


def test_the_history_does_not_depend_on_how_replies_were_grouped():
    """The bridge hands replies over in batches whose size depends on the load; a replay
    feeds them one by one. Any grouping gives the same history, pose and gaps (a live
    session under load differed from its replay at max speed: a lift released by a later
    reply of the batch was in an earlier row, a failed fetch made the whole batch a gap)."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    replies, one = _grouping_case()

    @settings(max_examples=40, deadline=None)
    @given(st.lists(st.integers(1, 40), min_size=1, max_size=len(replies)))
    def check(sizes):
        many = MonitorSession(devices=DEVS)
        i = 0
        for k in sizes:
            many.process_batch(replies[i : i + k])
            i += k
        for b in _batched(replies[i:], 8):
            many.process_batch(b)
        _assert_same_session(one, many)

    check()


def test_a_restart_inside_a_batch_is_a_baseline_between_its_rows():
    one, many = MonitorSession(), MonitorSession()
    first = [reply(k, {A: (0, 0.01 * k), B: (0, 0.01 * k)}) for k in range(0, 50, 10)]
    second = [reply(k, {A: (0, 0.01 * k), B: (0, 0.01 * k)}, node=1) for k in range(0, 50, 10)]
    for r in first + second:
        one.process(r)
    assert many.process_batch(first + second) == len(one.history) == 8
    assert many.stats.restarts == one.stats.restarts == 1
    assert np.array_equal(one.history.column("y"), many.history.column("y"))
