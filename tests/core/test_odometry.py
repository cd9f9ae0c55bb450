"""Pose math (mm_pc.core.odometry) against the ground-truth simulator.

The simulator computes counts from the twist without any pose integration,
and the truth pose in closed form, so agreement here is a real check of the
kinematics, not of one formula against itself.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_pc.core.frames import base_to_sensor
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.odometry import METHODS, Odometry, Pose2D, Sample
from mm_pc.sim import robot as sim

ALL_METHODS = sorted(METHODS)


def constant_twist_truth(vx, vy, omega, duration, yaw0=0.0):
    """Closed-form end pose of a constant body twist (independent of arc_poses)."""
    if abs(omega * duration) < 1e-12:
        fx, fy = vx * duration, vy * duration
    else:
        s = math.sin(omega * duration)
        one_minus_c = 2.0 * math.sin(omega * duration / 2.0) ** 2  # 1 - cos, no cancellation
        fx = (vx * s - vy * one_minus_c) / omega
        fy = (vx * one_minus_c + vy * s) / omega
    cy, sy = math.cos(yaw0), math.sin(yaw0)
    return np.array([cy * fx - sy * fy, sy * fx + cy * fy, yaw0 + omega * duration])


def slip_counts(vx, vy, omega, dt, mounts):
    """Sensor-frame displacement (N?, n, 2) of a constant twist with lateral slip vy."""
    rows = []
    for m in mounts:
        bx = (vx - omega * m.y) * dt  # body velocity at the sensor, base_link
        by = (vy + omega * m.x) * dt
        sx, sy = base_to_sensor(bx, by)
        rows.append((float(sx), float(sy)))
    return np.array(rows)


def run(name, mounts=DEFAULT_MOUNTS, request_hz=1000.0, **kw):
    v, w = sim.trajectory(name) if isinstance(name, str) else name
    return sim.request_samples(v, w, mounts, request_hz, **kw)


# --- the exact method inverts the simulator ---------------------------------------------

off_axle = st.floats(0.005, 0.3) | st.floats(-0.3, -0.005)


@settings(max_examples=150, deadline=None)
@given(
    v=st.floats(-1.0, 1.0),
    omega=st.floats(-4.0, 4.0),
    duration=st.floats(0.01, 3.0),
    request_hz=st.floats(1.0, 1000.0),
    fwd=off_axle,
    right=st.floats(-0.3, 0.3),
)
def test_exact_inverts_the_simulator_for_any_arc(v, omega, duration, request_hz, fwd, right):
    mount = SensorMount(x=fwd, y=-right)
    n = max(1, round(duration / sim.DT))
    vv, ww = np.full(n, v), np.full(n, omega)
    r = sim.request_samples(vv, ww, (mount,), request_hz)
    poses = Odometry((mount,)).integrate(r.dt, r.d)
    truth = constant_twist_truth(v, 0.0, omega, n * sim.DT)
    assert np.abs(poses[-1] - truth).max() < 1e-9
    assert np.abs(poses - r.truth).max() < 1e-9


@pytest.mark.parametrize("method", ["exact", "two-sensor"])
@pytest.mark.parametrize("path", ["straight", "square", "round_trip", "figure_eight", "meander"])
def test_scripted_paths_end_where_the_simulator_says(method, path):
    r = run(path)
    poses = Odometry(DEFAULT_MOUNTS, method).integrate(r.dt, r.d)
    assert np.abs(poses - r.truth).max() < 1e-9


@pytest.mark.parametrize("method", ["exact", "two-sensor"])
@pytest.mark.parametrize("path", ["straight", "round_trip", "figure_eight"])
def test_at_15_hz_only_intervals_spanning_a_twist_change_cost_anything(method, path):
    # Exact per request for a constant twist; an interval that straddles a
    # change of twist (straight -> turn) is a second-order error, < 1 mm here.
    r = run(path, request_hz=15.0)
    poses = Odometry(DEFAULT_MOUNTS, method).integrate(r.dt, r.d)
    assert np.hypot(*(poses[-1, :2] - r.truth[-1, :2])) < 1e-3
    assert abs(poses[-1, 2] - r.truth[-1, 2]) < 1e-9  # yaw is linear in the counts


def test_pivot_turn_on_the_spot():
    n = round(math.pi / 1.0 / sim.DT)  # half a turn at 1 rad/s
    r = run((np.zeros(n), np.ones(n)))
    for method in ("exact", "two-sensor", "seed-approach2"):
        p = Odometry(DEFAULT_MOUNTS, method).integrate(r.dt, r.d)[-1]
        assert np.allclose(p, [0.0, 0.0, n * sim.DT], atol=1e-12), method


def test_the_other_sensor_and_a_sensor_behind_the_axle_work_too():
    mounts = (SensorMount(-0.06, 0.02), SensorMount(0.049, 0.0395))
    r = run("figure_eight", mounts=mounts, request_hz=1000.0)
    for sensor in (0, 1):
        p = Odometry(mounts, sensor=sensor).integrate(r.dt, r.d)
        assert np.abs(p - r.truth).max() < 1e-9


@pytest.mark.parametrize("method", ["exact", "two-sensor", "seed-approach2"])
def test_mounting_yaw_is_undone(method):
    mounts = sim.with_mount_yaw(DEFAULT_MOUNTS, [math.radians(5.0), math.radians(-12.0)])
    r = run("figure_eight", mounts=mounts)
    p = Odometry(mounts, method).integrate(r.dt, r.d)
    tol = 1e-9 if method != "seed-approach2" else 1e-3
    assert np.abs(p - r.truth).max() < tol
    # ... and ignoring it is visibly wrong
    wrong = Odometry(DEFAULT_MOUNTS, method).integrate(r.dt, r.d)
    assert np.abs(wrong - r.truth).max() > 0.05


# --- two-sensor least squares ----------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(
    vx=st.floats(-1.0, 1.0),
    vy=st.floats(-0.3, 0.3),
    omega=st.floats(-4.0, 4.0),
    dt=st.floats(1e-3, 0.2),
)
def test_two_sensor_recovers_vx_vy_omega_including_lateral_slip(vx, vy, omega, dt):
    d = slip_counts(vx, vy, omega, dt, DEFAULT_MOUNTS)
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    abc, _ = odo._impl.solve(d[None])
    assert np.allclose(abc[0], [vx * dt, vy * dt, omega * dt], atol=1e-12)
    pose = odo.update(Sample.of(dt, *d))
    assert np.allclose(pose.as_array(), constant_twist_truth(vx, vy, omega, dt), atol=1e-12)
    assert odo.residual < 1e-12


def test_two_sensor_tracks_a_slipping_arc_that_the_one_sensor_method_gets_wrong():
    vx, vy, omega, dt, n = 0.2, 0.03, 0.5, 0.01, 400
    d = np.repeat(slip_counts(vx, vy, omega, dt, DEFAULT_MOUNTS)[None], n, axis=0)
    truth = constant_twist_truth(vx, vy, omega, n * dt)
    two = Odometry(DEFAULT_MOUNTS, "two-sensor").integrate(dt, d)[-1]
    one = Odometry(DEFAULT_MOUNTS, "exact").integrate(dt, d)[-1]
    assert np.abs(two - truth).max() < 1e-9
    assert np.abs(one - truth).max() > 0.1  # no-slip assumption broken


def test_residual_is_zero_for_consistent_and_positive_for_inconsistent_data():
    r = run("figure_eight", request_hz=50.0)
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    _, resid = odo.integrate(r.dt, r.d, return_residual=True)
    assert resid.max() < 1e-15
    bad = r.d.copy()
    bad[:, 1, 0] += 1e-4  # sensor 2's X disagrees with sensor 1's by 0.1 mm per sample
    _, resid = Odometry(DEFAULT_MOUNTS, "two-sensor").integrate(r.dt, bad, return_residual=True)
    # the only redundancy of this geometry is dX1 - dX2, the residual is |dX1 - dX2|/sqrt(2)
    assert np.allclose(resid, 1e-4 / math.sqrt(2), rtol=1e-6)
    odo.update(Sample.of(0.01, (0.0, 0.001), (0.0005, 0.001)))
    assert odo.residual == pytest.approx(0.0005 / math.sqrt(2))


def test_one_sensor_methods_report_no_residual():
    odo = Odometry(DEFAULT_MOUNTS)
    odo.update(Sample.of(0.01, (0.0, 0.001), (0.0, 0.001)))
    assert odo.residual is None
    _, resid = odo.integrate(0.01, np.zeros((3, 2, 2)), return_residual=True)
    assert np.isnan(resid).all()


# --- integrate == update loop ------------------------------------------------------------


@pytest.mark.parametrize("method", ALL_METHODS)
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 60))
def test_integrate_equals_the_update_loop(method, seed, n):
    rng = np.random.default_rng(seed)
    d = rng.normal(0.0, 2e-3, (n, 2, 2))
    dt = rng.uniform(1e-3, 0.1, n)
    start = Pose2D(0.3, -0.2, 1.0)
    loop = Odometry(DEFAULT_MOUNTS, method, pose=start)
    looped, resid = [], []
    for i in range(n):
        looped.append(loop.update(Sample.of(dt[i], *d[i])).as_array())
        resid.append(np.nan if loop.residual is None else loop.residual)
    vec = Odometry(DEFAULT_MOUNTS, method, pose=start)
    poses, vres = vec.integrate(dt, d, return_residual=True)
    assert np.allclose(poses, np.array(looped), rtol=0, atol=1e-12)
    assert np.allclose(vres, resid, equal_nan=True, atol=1e-15)
    assert vec.pose == loop.pose or np.allclose(vec.pose.as_array(), loop.pose.as_array())


def test_integrate_continues_from_the_current_pose_and_reset():
    r = run("figure_eight", request_hz=500.0)
    half = len(r.dt) // 2
    odo = Odometry(DEFAULT_MOUNTS)
    odo.integrate(r.dt[:half], r.d[:half])
    rest = odo.integrate(r.dt[half:], r.d[half:])
    assert np.abs(rest - r.truth[half:]).max() < 1e-9
    odo.reset()
    assert odo.pose == Pose2D()
    odo.reset(Pose2D(1.0, 2.0, 3.0))
    assert odo.pose == Pose2D(1.0, 2.0, 3.0)
    assert odo.integrate(0.01, np.zeros((0, 2, 2))).shape == (0, 3)


def test_pose_yaw_is_continuous_and_wrapped_on_request():
    p = Pose2D(0, 0, 4 * math.pi + 0.1)
    assert p.yaw_wrapped == pytest.approx(0.1)
    # the one wrap convention, (-pi, pi] (mm_pc.core.angles)
    assert Pose2D(0, 0, math.pi).yaw_wrapped == pytest.approx(math.pi)
    assert Pose2D(0, 0, -math.pi).yaw_wrapped == pytest.approx(math.pi)


# --- the seed's approaches ---------------------------------------------------------------


def test_seed_approach1_agrees_on_a_straight_line():
    r = run("straight", request_hz=15.0)
    p = Odometry(DEFAULT_MOUNTS, "seed-approach1").integrate(r.dt, r.d)
    assert np.abs(p - r.truth).max() < 1e-12


def test_seed_approach1_turns_the_wrong_way_for_a_front_sensor():
    # pivot turn: the turn magnitude |dX|*sqrt(1+m^2)/radius = |dX|/sy is right,
    # the sign is mirrored for sensors in front of the axle, right or left
    n = round(1.0 / sim.DT)
    r = run((np.zeros(n), np.full(n, 0.8)))
    for sensor in (0, 1):
        p = Odometry(DEFAULT_MOUNTS, "seed-approach1", sensor=sensor).integrate(r.dt, r.d)[-1]
        assert p[2] == pytest.approx(-0.8, abs=1e-12)
    behind = (SensorMount(-0.049, -0.0395),)
    r = run((np.zeros(n), np.full(n, 0.8)), mounts=behind)
    p = Odometry(behind, "seed-approach1").integrate(r.dt, r.d)[-1]
    assert p[2] == pytest.approx(0.8, abs=1e-12)  # behind the axle the sign happens to be right


def test_seed_approach1_differs_from_exact_on_an_arc():
    # quarter circle of radius 0.4 m at 0.2 m/s (0.63 m): documented in docs/pose-math.md
    n = round((math.pi / 2) / 0.5 / sim.DT)
    r = run((np.full(n, 0.2), np.full(n, 0.5)), request_hz=100.0)
    exact = Odometry(DEFAULT_MOUNTS).integrate(r.dt, r.d)[-1]
    seed = Odometry(DEFAULT_MOUNTS, "seed-approach1").integrate(r.dt, r.d)[-1]
    assert np.abs(exact - r.truth[-1]).max() < 1e-9
    assert seed[2] == pytest.approx(-exact[2], abs=1e-9)  # mirrored turn
    assert np.hypot(*(seed[:2] - exact[:2])) > 0.5  # ends on the other side
    # Even with the sign fixed, |Vs| - |Vr| is not the forward part dY - m*dX:
    dx, dy = r.d[0, 0]
    m = DEFAULT_MOUNTS[0].slope
    seed_fwd = math.hypot(dx, dy) - abs(dx) * math.hypot(1, m)
    exact_fwd = dy - m * dx
    assert 0.04 < (exact_fwd - seed_fwd) / exact_fwd < 0.06  # 5 % short on this arc


def test_seed_approach2_is_exact_but_for_its_euler_step():
    r15 = run("figure_eight", request_hz=15.0)
    r1k = run("figure_eight")
    e15 = Odometry(DEFAULT_MOUNTS, "seed-approach2").integrate(r15.dt, r15.d)
    e1k = Odometry(DEFAULT_MOUNTS, "seed-approach2").integrate(r1k.dt, r1k.d)
    # yaw is the same sum as exact's; the position lags by the Euler step
    assert abs(e15[-1, 2] - r15.truth[-1, 2]) < 1e-9
    err15 = np.hypot(*(e15[:, :2] - r15.truth[:, :2]).T).max()
    err1k = np.hypot(*(e1k[:, :2] - r1k.truth[:, :2]).T).max()
    assert err1k < 1e-3 < err15
    assert err15 / err1k == pytest.approx(1000 / 15, rel=0.2)  # first order in dt


# --- bad input -----------------------------------------------------------------------------


def test_unknown_method_lists_the_known_ones():
    with pytest.raises(ValueError, match=r"known:.*exact.*seed-approach1.*two-sensor"):
        Odometry(DEFAULT_MOUNTS, "dead-reckoning")


@pytest.mark.parametrize("method", ["exact", "seed-approach1", "seed-approach2"])
def test_a_sensor_on_the_axle_line_is_refused_by_name(method):
    mounts = (SensorMount(0.049, -0.0395), SensorMount(0.0, 0.04))
    Odometry(mounts, method)  # sensor 0 is fine
    with pytest.raises(ValueError, match=r"sensor 1 .*axle line.*unobservable"):
        Odometry(mounts, method, sensor=1)


def test_two_sensor_needs_two_separate_sensors():
    with pytest.raises(ValueError, match="at least 2"):
        Odometry(DEFAULT_MOUNTS[:1], "two-sensor")
    with pytest.raises(ValueError, match="same point"):
        Odometry((SensorMount(0.05, 0.0), SensorMount(0.05, 0.0)), "two-sensor")
    Odometry((SensorMount(0.0, 0.04), SensorMount(0.0, -0.04)), "two-sensor")  # axle line ok


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"sensor": 2}, "sensor index"),
        ({"sensor": -1}, "sensor index"),
        ({"pose": Pose2D(math.nan, 0, 0)}, "finite"),
    ],
)
def test_bad_construction(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Odometry(DEFAULT_MOUNTS, **kwargs)
    with pytest.raises(ValueError, match="at least one"):
        Odometry(())
    with pytest.raises(ValueError, match="non-finite"):
        Odometry((SensorMount(math.inf, 0.0),))


@pytest.mark.parametrize("method", ALL_METHODS)
@pytest.mark.parametrize(
    "sample, match",
    [
        (Sample.of(0.0, (0, 1e-3), (0, 1e-3)), "dt must be .* > 0, got 0.0"),
        (Sample.of(-0.01, (0, 1e-3), (0, 1e-3)), "dt must be"),
        (Sample.of(math.nan, (0, 1e-3), (0, 1e-3)), "dt must be"),
        (Sample.of(math.inf, (0, 1e-3), (0, 1e-3)), "dt must be"),
        (Sample.of(0.01, (math.nan, 1e-3), (0, 1e-3)), r"sensor 0 \(dX\).* nan"),
        (Sample.of(0.01, (0, 1e-3), (0, math.inf)), r"sensor 1 \(dY\).* inf"),
        (Sample.of(0.01, (0, 1e-3)), "1 sensor displacement.* 2 mount"),
        (Sample.of(0.01, (0, 0), (0, 0), (0, 0)), "3 sensor displacement"),
        (Sample(0.01, ((0.0,), (0.0,))), "shape"),
        (Sample("soon", ((0.0, 0.0), (0.0, 0.0))), "needs dt"),
    ],
)
def test_bad_samples_are_refused_and_change_nothing(method, sample, match):
    odo = Odometry(DEFAULT_MOUNTS, method)
    odo.update(Sample.of(0.01, (1e-4, 2e-3), (1e-4, 3e-3)))
    before, resid = odo.pose, odo.residual
    with pytest.raises(ValueError, match=match):
        odo.update(sample)
    assert odo.pose == before and odo.residual == resid
    d = np.asarray(sample.d, dtype=float)[None] if sample.dt != "soon" else np.zeros((1, 2, 2))
    if sample.dt == "soon":
        return
    with pytest.raises(ValueError):
        odo.integrate(np.array([sample.dt]), d)
    assert odo.pose == before and odo.residual == resid


def test_integrate_refuses_bad_arrays_and_changes_nothing():
    odo = Odometry(DEFAULT_MOUNTS)
    good = np.full((5, 2, 2), 1e-3)
    odo.integrate(0.01, good)
    before = odo.pose
    for dt, d, match in [
        (0.01, np.zeros((5, 2)), "shape"),
        (0.01, np.zeros((5, 3, 2)), r"\(N, 2, 2\)"),
        (np.full(4, 0.01), good, "5 interval lengths"),
        (np.array([0.01, 0.01, 0.0, 0.01, 0.01]), good, "dt must be"),
        (0.01, np.where(np.arange(20).reshape(5, 2, 2) == 13, np.nan, good), "sample 3"),
    ]:
        with pytest.raises(ValueError, match=match):
            odo.integrate(dt, d)
        assert odo.pose == before


def test_a_subnormal_turn_is_a_straight_step_not_a_division_by_zero():
    """c = 5e-324 halves to 0.0: sinc must be taken of the half angle (found by hypothesis)."""
    from mm_pc.core.odometry import _arc_step

    assert _arc_step((0.0, 0.0, 0.0), 1.0, 0.0, 5e-324) == (1.0, 5e-324, 5e-324)


# --- lifted sensors -----------------------------------------------------------------------------


def test_issue_example_a_lifted_sensor_is_invisible_to_the_residual_but_dropped_by_its_flag():
    """Sensor 0 lifted (reads 0) while the robot drives 2 cm straight: without the flag
    two-sensor turns 14.5 deg with a residual of ~1e-17; with it, sensor 0 is dropped and
    sensor 1's no-slip split gives the straight 2 cm."""
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    p = odo.update(Sample.of(1 / 15, (0, 0), (0, 0.02)))
    assert math.degrees(p.yaw) == pytest.approx(-14.5, abs=0.05)
    assert odo.residual < 1e-15
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    p = odo.update(Sample.of(1 / 15, (0, 0), (0, 0.02), lifted=(True, False)))
    assert (p.x, p.y, p.yaw) == (0.02, 0.0, 0.0)
    assert math.isnan(odo.residual) and odo.lifted_samples == 1 and odo.blind_samples == 0


def _lifted_tour(lift_sensor: int = 0):
    v, w = sim.trajectory("mixed_tour")
    lift = np.zeros((v.size, 2), dtype=bool)
    lift[:, lift_sensor] = sim.lift_mask(v.size, [(3.0, 1.5), (22.0, 2.0), (41.0, 1.0), (55, 0.7)])
    r = sim.request_samples(v, w, DEFAULT_MOUNTS, 15.0, lifted=lift)
    return r, r.lifted_steps > 0


@pytest.mark.parametrize("lift_sensor", [0, 1])
def test_two_sensor_drops_a_lifted_sensor_and_stays_on_the_tour(lift_sensor):
    r, mask = _lifted_tour(lift_sensor)
    assert mask[:, lift_sensor].sum() > 50 and not mask[:, 1 - lift_sensor].any()
    blind = Odometry(DEFAULT_MOUNTS, "two-sensor").integrate(r.dt, r.d)
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    poses, resid = odo.integrate(r.dt, r.d, True, lifted=mask)
    # noise-free, no slip: the remaining sensor's no-slip split is exact per interval
    err = np.hypot(*(poses[-1, :2] - r.truth[-1, :2]))
    assert err < 1e-3
    assert np.hypot(*(blind[-1, :2] - r.truth[-1, :2])) > 0.5  # lifts unflagged: lost
    assert np.all(np.isnan(resid[mask.any(axis=1)])) and np.all(resid[~mask.any(axis=1)] < 1e-9)
    assert odo.lifted_samples == int(mask.any(axis=1).sum())


def test_update_and_integrate_agree_with_a_lift_mask():
    r, mask = _lifted_tour(0)
    n = 300
    vec = Odometry(DEFAULT_MOUNTS, "two-sensor").integrate(r.dt[:n], r.d[:n], lifted=mask[:n])
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    loop = np.array(
        [odo.update(Sample.of(r.dt[i], *r.d[i], lifted=mask[i])).as_array() for i in range(n)]
    )
    np.testing.assert_allclose(loop, vec, atol=1e-12)


def test_every_sensor_lifted_holds_the_pose_or_moves_by_the_filled_data():
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    odo.update(Sample.of(0.1, (0, 0.01), (0, 0.01)))
    p = odo.update(Sample.of(0.1, (0, 0), (0, 0), lifted=(True, True)))
    assert (p.x, p.y, p.yaw) == pytest.approx((0.01, 0.0, 0.0))
    p = odo.update(Sample.of(0.1, (0, 0.02), (0, 0.02), lifted=(True, True)))  # filled
    assert (p.x, p.y, p.yaw) == pytest.approx((0.03, 0.0, 0.0))
    assert odo.blind_samples == 2 and odo.lifted_samples == 2


@pytest.mark.parametrize("method", ["seed-approach1", "seed-approach2"])
def test_the_seed_methods_use_the_data_as_given_under_a_mask(method):
    """(``exact`` did too before issue 28; it now switches sensors, tested below.)"""
    r, mask = _lifted_tour(0)
    plain = Odometry(DEFAULT_MOUNTS, method).integrate(r.dt, r.d)
    odo = Odometry(DEFAULT_MOUNTS, method)
    masked = odo.integrate(r.dt, r.d, lifted=mask)
    np.testing.assert_array_equal(plain, masked)
    assert odo.lifted_samples == int(mask[:, 0].sum())


@pytest.mark.parametrize("lift_sensor", [0, 1])
def test_exact_switches_to_the_other_sensor_while_its_own_is_lifted_and_back(lift_sensor):
    """Its own sensor (0) lifted: the other's split, so the tour stays on the truth;
    the other sensor lifted: nothing changes (bit for bit)."""
    r, mask = _lifted_tour(lift_sensor)
    plain = Odometry(DEFAULT_MOUNTS, "exact").integrate(r.dt, r.d)
    odo = Odometry(DEFAULT_MOUNTS, "exact")
    poses = odo.integrate(r.dt, r.d, lifted=mask)
    assert odo.lifted_samples == int(mask[:, lift_sensor].sum())
    if lift_sensor == 1:
        np.testing.assert_array_equal(poses, plain)
        assert odo.switched_samples == 0
        return
    assert odo.switched_samples == int(mask[:, 0].sum()) > 50
    # noise-free, no slip: sensor 1's no-slip split is exact per interval
    assert np.hypot(*(poses[-1, :2] - r.truth[-1, :2])) < 1e-3
    assert np.hypot(*(plain[-1, :2] - r.truth[-1, :2])) > 0.5  # the lost counts integrated
    # back on its own sensor after a lift: the steps there are the unmasked ones
    first_lift = int(np.argmax(mask[:, 0]))
    np.testing.assert_array_equal(poses[:first_lift], plain[:first_lift])
    after = np.flatnonzero(~mask[:, 0] & (np.arange(len(mask)) > first_lift))[:20]
    again = Odometry(DEFAULT_MOUNTS, "exact", pose=Pose2D(*poses[after[0] - 1]))
    np.testing.assert_array_equal(again.integrate(r.dt[after], r.d[after]), poses[after])
    body = odo.body_map((True, False))
    assert not body[:, :2].any() and body[:, 2:].any()  # the covariance follows the switch


def test_exact_update_and_integrate_agree_when_switching():
    r, mask = _lifted_tour(0)
    start = max(0, int(np.argmax(mask[:, 0])) - 20)
    sl = slice(start, start + 200)
    assert mask[sl, 0].any() and not mask[sl, 0].all()
    vec_odo = Odometry(DEFAULT_MOUNTS, "exact")
    vec = vec_odo.integrate(r.dt[sl], r.d[sl], lifted=mask[sl])
    odo = Odometry(DEFAULT_MOUNTS, "exact")
    loop = np.array(
        [odo.update(Sample.of(r.dt[i], *r.d[i], lifted=mask[i])).as_array()
         for i in range(sl.start, sl.stop)]
    )  # fmt: skip
    np.testing.assert_allclose(loop, vec, atol=1e-12)
    assert odo.switched_samples == vec_odo.switched_samples == int(mask[sl, 0].sum())
    odo.reset()
    assert odo.switched_samples == 0


def test_exact_with_every_sensor_lifted_uses_its_own_data_as_given():
    odo = Odometry(DEFAULT_MOUNTS, "exact")
    p = odo.update(Sample.of(0.1, (0, 0.02), (0.001, 0.5), lifted=(True, True)))  # filled
    assert (p.x, p.y, p.yaw) == pytest.approx((0.02, 0.0, 0.0))
    assert odo.blind_samples == 1 and odo.switched_samples == 0
    on_axle = Odometry([DEFAULT_MOUNTS[0], SensorMount(0.0, 0.04)], "exact")
    p = on_axle.update(Sample.of(0.1, (0, 0.02), (0, 0.5), lifted=(True, False)))
    assert p.x == pytest.approx(0.02) and on_axle.switched_samples == 0  # no yaw there


@pytest.mark.parametrize(
    "lifted",
    [np.ones((2, 3), dtype=bool), np.ones((3, 2), dtype=bool), np.ones((2, 2), dtype=int)],
)
def test_bad_lift_mask_is_refused_and_changes_nothing(lifted):
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    with pytest.raises(ValueError, match="lifted must be a bool array of shape"):
        odo.integrate(0.1, np.zeros((2, 2, 2)), lifted=lifted)
    assert odo.pose == Pose2D() and odo.lifted_samples == 0
    with pytest.raises(ValueError, match="one bool per sensor"):
        odo.update(Sample.of(0.1, (0, 0), (0, 0), lifted=(True,)))


def test_compose_and_inverse_are_planar_transforms():
    from mm_pc.core.odometry import compose, inverse

    a = Pose2D(2.0, -1.0, math.pi / 2)
    b = Pose2D(1.0, 0.5, 0.3)
    # b's (1, 0.5) turned by 90 deg is (-0.5, 1), then moved by (2, -1)
    ab = compose(a, b)
    assert (ab.x, ab.y, ab.yaw) == pytest.approx((1.5, 0.0, math.pi / 2 + 0.3), abs=1e-12)
    for p in (a, b, compose(a, b)):
        ident = compose(p, inverse(p))
        assert (ident.x, ident.y, ident.yaw) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
        back = compose(inverse(p), p)
        assert (back.x, back.y, back.yaw) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # map -> odom from map -> base and odom -> base gives back map -> base
    map_odom = compose(a, inverse(b))
    again = compose(map_odom, b)
    assert (again.x, again.y, again.yaw) == pytest.approx((a.x, a.y, a.yaw), abs=1e-12)
