"""The pose EKF (mm_pc.core.fusion.ekf) and the simulated mowing run it is proven on
(mm_pc.sim.field_run).

Unit tests hold the motion model to mm_pc.core.odometry and to the closed form of a
constant twist, the Jacobians to finite differences, and every update to its
algebra; the system test replays one seeded ~205 m run and checks that the
fused error stays bounded while raw mouse odometry drifts by metres.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_pc.core.angles import compass_to_rep103, quaternion_yaw, wrap_pi
from mm_pc.core.fusion.ekf import (
    DEFAULT_P0,
    GATE_2D,
    PoseEKF,
    increments_from_poses,
    pose_increment,
)
from mm_pc.core.fusion.inputs import gps_inflation
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.maps.trilateration import Beacon
from mm_pc.core.odometry import Odometry, Pose2D, Sample
from mm_pc.core.uncertainty import Q_POS, Q_YAW_DIST, Q_YAW_TURN
from mm_pc.sim import field_run as fs
from mm_pc.sim import robot as sim


def constant_twist_end(start, fwd, dtheta):
    """End pose of a constant twist (closed form, independent of the arc/sinc code)."""
    x, y, yaw = start
    if dtheta == 0:
        return np.array([x + fwd * math.cos(yaw), y + fwd * math.sin(yaw), yaw])
    r = fwd / dtheta
    return np.array(
        [
            x + r * (math.sin(yaw + dtheta) - math.sin(yaw)),
            y - r * (math.cos(yaw + dtheta) - math.cos(yaw)),
            yaw + dtheta,
        ]
    )


def state_of(ekf: PoseEKF):
    return ekf.state.copy(), ekf.covariance.copy()


def assert_unchanged(ekf: PoseEKF, before) -> None:
    s, p = before
    assert np.array_equal(ekf.state, s)
    assert np.array_equal(ekf.covariance, p)


def assert_spd(p: np.ndarray) -> None:
    assert np.all(np.isfinite(p))
    assert np.array_equal(p, p.T)
    assert np.linalg.eigvalsh(p)[0] > 0


# --- predict: the motion model -------------------------------------------------------------


@pytest.mark.parametrize(("fwd", "dtheta"), [(0.5, 0.0), (-0.2, 0.0), (0.3, 0.7), (0.0, -1.2)])
def test_predict_matches_the_closed_form_of_a_constant_twist(fwd, dtheta):
    start = (1.0, -2.0, 2.5)
    ekf = PoseEKF(Pose2D(*start))
    ekf.predict(fwd, 0.0, dtheta)
    assert ekf.state == pytest.approx(constant_twist_end(start, fwd, dtheta), abs=1e-14)


@settings(max_examples=60, deadline=None)
@given(
    v=st.floats(-0.5, 0.5),
    omega=st.floats(-3.0, 3.0),
    steps=st.integers(1, 40),
    yaw0=st.floats(-10.0, 10.0),
)
def test_noise_free_predict_follows_exact_odometry_sample_by_sample(v, omega, steps, yaw0):
    """The same increments through Odometry.update (method exact) and PoseEKF.predict."""
    dt = 1 / 15
    mount = DEFAULT_MOUNTS[0]
    dx, dy = sim.sensor_displacements(np.array([v]), np.array([omega]), dt, mount)
    sample = Sample.of(dt, (float(dx[0]), float(dy[0])))
    start = Pose2D(0.3, -0.4, yaw0)
    odo = Odometry([mount], "exact", pose=start)
    ekf = PoseEKF(start)
    # the increments the exact method recovers from the counts (its split)
    fwd = float(dy[0]) + (mount.right / mount.forward) * float(dx[0])
    dtheta = -float(dx[0]) / mount.forward
    for _ in range(steps):
        p = odo.update(sample)
        ekf.predict(fwd, 0.0, dtheta)
    assert ekf.state == pytest.approx(p.as_array(), abs=1e-12)


def test_predict_replays_an_odometry_run_through_increments_from_poses():
    """Odometry poses -> increments -> predict chain gives the poses back (the nav_msgs path)."""
    v, w = sim.meander(speed=0.2)
    r = sim.request_samples(v, w, DEFAULT_MOUNTS, 15.0)
    start = Pose2D(3.0, 1.0, -2.0)
    poses = np.vstack([start.as_array(), Odometry(DEFAULT_MOUNTS, pose=start).integrate(r.dt, r.d)])
    ekf = PoseEKF(start)
    out = [ekf.state]
    for a, b, c in increments_from_poses(poses):
        ekf.predict(a, b, c)
        out.append(ekf.state)
    assert np.max(np.abs(np.array(out) - poses)) < 1e-9


def test_pose_increment_inverts_predict_also_with_wrapped_yaw():
    before = Pose2D(1.0, 2.0, math.pi - 0.1)
    ekf = PoseEKF(before)
    ekf.predict(0.4, 0.05, 0.3)  # crosses +pi
    after = ekf.pose
    wrapped = Pose2D(after.x, after.y, wrap_pi(after.yaw))
    assert wrapped.yaw < 0
    for target in (after, wrapped):
        inc = pose_increment(before, target)
        assert inc == pytest.approx((0.4, 0.05, 0.3), abs=1e-12)
    rows = np.array([before.as_array(), wrapped.as_array()])
    assert increments_from_poses(rows)[0] == pytest.approx([0.4, 0.05, 0.3], abs=1e-12)


def test_quaternion_yaw_inverts_a_planar_quaternion():
    for yaw in (-3.0, -1.0, 0.0, 0.5, 3.1):
        assert quaternion_yaw(0, 0, math.sin(yaw / 2), math.cos(yaw / 2)) == pytest.approx(yaw)
    assert quaternion_yaw(0, 0, math.sin(4.0), math.cos(4.0)) == pytest.approx(8.0 - 2 * math.pi)
    with pytest.raises(ValueError, match="zero length"):
        quaternion_yaw(0.0, 0.0, 0.0, 0.0)


def _numeric_jacobians(state, u, eps=1e-6):
    def f(s, inc):
        e = PoseEKF(Pose2D(*s))
        e.predict(*inc)
        return e.state

    fj, gj = np.zeros((3, 3)), np.zeros((3, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = eps
        fj[:, j] = (f(state + d, u) - f(state - d, u)) / (2 * eps)
        gj[:, j] = (f(state, u + d) - f(state, u - d)) / (2 * eps)
    return fj, gj


@pytest.mark.parametrize(
    "u", [(0.5, 0.1, 0.4), (0.3, -0.05, 1e-7), (0.0, 0.0, -2.0), (1.0, 0.0, 0.0)]
)
def test_predict_covariance_is_f_p_ft_plus_g_m_gt_with_finite_difference_jacobians(u):
    state = np.array([1.0, 2.0, 0.3])
    p0 = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, -0.003], [0.002, -0.003, 0.01]])
    m = np.diag([1e-4, 4e-4, 9e-4])
    fj, gj = _numeric_jacobians(state, np.array(u))
    ekf = PoseEKF(Pose2D(*state), p0)
    ekf.predict(*u, q=m)
    assert ekf.covariance == pytest.approx(fj @ p0 @ fj.T + gj @ m @ gj.T, abs=1e-9)


def test_default_process_noise_grows_with_distance_and_turn_only():
    ekf = PoseEKF(Pose2D(0.0, 0.0, 0.0), np.eye(3) * 1e-12)
    ekf.predict(0.0, 0.0, 0.0)
    assert ekf.covariance == pytest.approx(np.eye(3) * 1e-12, abs=1e-15)  # standing still
    ekf.predict(1.0, 0.0, 0.0)
    p = ekf.covariance
    assert p[0, 0] == pytest.approx(Q_POS, rel=1e-6)
    # lateral: q_pos plus the heading noise over the chord (d/2)^2 * var_yaw
    assert p[1, 1] == pytest.approx(Q_POS + 0.25 * Q_YAW_DIST, rel=1e-6)
    assert p[2, 2] == pytest.approx(Q_YAW_DIST, rel=1e-6)
    spin = PoseEKF(Pose2D(), np.eye(3) * 1e-12)
    spin.predict(0.0, 0.0, -math.pi)
    assert spin.covariance[2, 2] == pytest.approx(Q_YAW_TURN * math.pi, rel=1e-6)
    assert spin.covariance[0, 0] == pytest.approx(1e-12)


# --- updates ---------------------------------------------------------------------------------


def test_a_precise_position_fix_pulls_the_state_to_it():
    ekf = PoseEKF(Pose2D(0.0, 0.0, 0.5), np.diag([1.0, 1.0, 0.1]))
    assert ekf.update_position((0.8, -0.6), np.eye(2) * 1e-6)
    assert ekf.state[:2] == pytest.approx([0.8, -0.6], abs=2e-6)
    assert ekf.state[2] == 0.5  # no correlation in P: yaw untouched
    assert ekf.covariance[:2, :2] == pytest.approx(np.eye(2) * 1e-6, rel=1e-5)
    assert_spd(ekf.covariance)


def test_equal_weights_give_the_mean_and_half_the_variance():
    ekf = PoseEKF(Pose2D(1.0, 1.0, 0.0), np.diag([0.04, 0.04, 0.01]))
    assert ekf.update_position([2.0, 3.0], np.diag([0.04, 0.04]), gate=None)
    assert ekf.state == pytest.approx([1.5, 2.0, 0.0])
    assert np.diag(ekf.covariance) == pytest.approx([0.02, 0.02, 0.01])


def test_gate_rejects_an_outlier_and_leaves_the_filter_unchanged():
    ekf = PoseEKF(Pose2D(5.0, 5.0, 0.0), np.diag([0.01, 0.01, 0.01]))
    before = state_of(ekf)
    assert not ekf.update_position((15.0, 5.0), np.eye(2) * 0.25)  # 10 m off, sigma ~0.5 m
    assert ekf.last_distance2 == pytest.approx(100 / 0.26)
    assert ekf.last_distance2 > GATE_2D
    assert_unchanged(ekf, before)
    assert ekf.update_position((15.0, 5.0), np.eye(2) * 0.25, gate=None)  # forced
    assert ekf.state[0] > 5.3


def test_gate_cov_gates_with_the_single_fix_accuracy():
    ekf = PoseEKF(Pose2D(0.0, 0.0, 0.0), np.diag([0.01, 0.01, 0.01]))
    r = np.eye(2) * 1.0
    before = state_of(ekf)
    # inflated R alone would let a 8 m ghost through; the fix's own R does not
    assert not ekf.update_position((8.0, 0.0), r * 100, gate_cov=r)
    assert_unchanged(ekf, before)
    assert ekf.update_position((1.0, 0.0), r * 100, gate_cov=r)
    assert ekf.state[0] == pytest.approx(0.01 / (0.01 + 100))  # weighted by the inflated R


@pytest.mark.parametrize("branch", [0, 2, -1])
def test_heading_update_across_plus_minus_pi_takes_the_short_way(branch):
    yaw = math.pi - 0.01 + 2 * math.pi * branch  # continuous yaw, any number of turns
    ekf = PoseEKF(Pose2D(0.0, 0.0, yaw), np.diag([0.01, 0.01, 0.01]))
    assert ekf.update_heading(-math.pi + 0.01, 0.01)  # 0.02 rad ahead, across the seam
    assert ekf.state[2] == pytest.approx(yaw + 0.01)  # halfway, on the same branch
    assert ekf.covariance[2, 2] == pytest.approx(0.005)


def test_heading_from_the_seed_compass_convention():
    ekf = PoseEKF(Pose2D(0.0, 0.0, 0.0), np.diag([0.01, 0.01, 1.0]))
    ekf.update_heading(float(compass_to_rep103(0.0)), 1e-8)  # compass north
    assert ekf.state[2] == pytest.approx(math.pi / 2, abs=1e-6)


def test_heading_gate_rejects_a_wild_compass_reading():
    ekf = PoseEKF(Pose2D(0.0, 0.0, 0.2), np.diag([0.01, 0.01, 1e-4]))
    before = state_of(ekf)
    assert not ekf.update_heading(1.2, (2 * math.pi / 180) ** 2)
    assert_unchanged(ekf, before)


def test_axis_update_changes_only_that_axis():
    ekf = PoseEKF(Pose2D(0.3, 4.0, 1.0), np.diag([0.09, 0.04, 0.01]))
    assert ekf.update_axis("x", 0.0, 1e-6)
    x1 = 0.3 * 1e-6 / (0.09 + 1e-6)  # x + K (0 - x), K = Pxx / (Pxx + r)
    assert ekf.state[0] == pytest.approx(x1, rel=1e-9)
    assert ekf.state[1:] == pytest.approx([4.0, 1.0], abs=0)
    p = ekf.covariance
    assert p[1:, 1:] == pytest.approx(np.diag([0.04, 0.01]), abs=0)
    assert p[0, 0] == pytest.approx(1e-6, rel=1e-4)
    ekf.update_axis("y", 10.0, 1e-6)
    y1 = 10.0 - 6.0 * 1e-6 / (0.04 + 1e-6)
    assert ekf.state == pytest.approx([x1, y1, 1.0], rel=1e-9)


def test_axis_update_moves_a_correlated_coordinate_by_its_correlation():
    p0 = np.array([[0.09, 0.03, 0.0], [0.03, 0.04, 0.0], [0.0, 0.0, 0.01]])
    ekf = PoseEKF(Pose2D(1.0, 1.0, 0.0), p0)
    ekf.update_axis("x", 0.0, 0.01)
    gain = p0[:, 0] / (p0[0, 0] + 0.01)
    assert ekf.state == pytest.approx(np.array([1.0, 1.0, 0.0]) - gain)


def test_ranges_converge_to_the_true_position_and_drop_a_multipath_range():
    beacons = fs.corner_beacons()
    truth = (7.0, 3.0)
    rng = np.random.default_rng(3)
    ekf = PoseEKF(Pose2D(8.0, 2.0, 0.0), np.diag([2.0, 2.0, 0.1]))
    for _ in range(50):
        r = fs.simulate_ranges(beacons, *truth, 0.05, rng)
        assert ekf.update_ranges(beacons, r, 0.05)
    assert ekf.state[:2] == pytest.approx(truth, abs=0.03)
    assert np.all(np.sqrt(np.diag(ekf.covariance)[:2]) < 0.02)
    # a 1 m NLOS range is dropped, the other three are used
    r = fs.simulate_ranges(beacons, *truth, 0.0, rng)
    r[2] += 1.0
    before = ekf.state
    assert ekf.update_ranges(beacons, r, 0.05)
    assert ekf.state[:2] == pytest.approx(truth, abs=0.03)
    assert np.hypot(*(ekf.state[:2] - before[:2])) < 0.02
    before = state_of(ekf)
    assert not ekf.update_ranges(beacons, r + 1.0, 0.05)  # all four off: nothing applied
    assert_unchanged(ekf, before)


def test_a_single_range_corrects_only_along_the_beacon_direction():
    ekf = PoseEKF(Pose2D(3.0, 0.0, 0.0), np.diag([1.0, 1.0, 0.1]))
    assert ekf.update_ranges([(0.0, 0.0, 0.0)], [4.0], 0.01, gate=None)  # beacon due west
    assert ekf.state[0] == pytest.approx(4.0, abs=1e-3)
    assert ekf.state[1] == 0.0
    assert ekf.covariance[1, 1] == pytest.approx(1.0)


def test_ranges_with_beacon_height_use_the_slant_distance():
    beacons = [Beacon(0.0, 0.0, 1.0), Beacon(10.0, 0.0, 1.0), Beacon(0.0, 10.0, 1.0)]
    ekf = PoseEKF(Pose2D(3.0, 4.0, 0.0), np.diag([1e-4, 1e-4, 0.1]))
    slant = [math.sqrt(25 + 1), math.sqrt(49 + 16 + 1), math.sqrt(9 + 36 + 1)]
    assert ekf.update_ranges(beacons, slant, 0.05)
    assert ekf.state[:2] == pytest.approx([3.0, 4.0], abs=1e-12)  # zero innovation


ops = st.lists(
    st.one_of(
        st.tuples(st.just("predict"), st.floats(-2, 2), st.floats(-0.5, 0.5), st.floats(-3.5, 3.5)),
        st.tuples(
            st.just("position"),
            st.floats(-50, 50),
            st.floats(-50, 50),
            st.floats(1e-6, 100.0),
            st.floats(-0.99, 0.99),
        ),
        st.tuples(st.just("heading"), st.floats(-10, 10), st.floats(1e-8, 10.0)),
        st.tuples(st.just("axis"), st.sampled_from("xy"), st.floats(-50, 50), st.floats(1e-8, 1.0)),
        st.tuples(st.just("ranges"), st.floats(0, 60), st.floats(1e-3, 1.0)),
    ),
    min_size=1,
    max_size=30,
)


@settings(max_examples=80, deadline=None)
@given(ops=ops)
def test_covariance_stays_symmetric_positive_definite(ops):
    ekf = PoseEKF(Pose2D(1.0, 2.0, 0.3), np.diag([0.5, 0.5, 0.2]))
    beacons = fs.corner_beacons()
    for op in ops:
        kind = op[0]
        if kind == "predict":
            ekf.predict(*op[1:])
        elif kind == "position":
            _, x, y, var, rho = op
            cov = var * np.array([[1.0, rho], [rho, 1.0]])
            ekf.update_position((x, y), cov, gate=None)
        elif kind == "heading":
            ekf.update_heading(op[1], op[2], gate=None)
        elif kind == "axis":
            ekf.update_axis(op[1], op[2], op[3])
        else:
            ekf.update_ranges(beacons, [op[1]] * 4, op[2], gate=None)
        assert_spd(ekf.covariance)
        assert np.all(np.isfinite(ekf.state))


# --- bad input ------------------------------------------------------------------------------

NAN = float("nan")
BAD_CALLS = [
    ("predict", (NAN, 0.0, 0.0), {}, "fwd must be finite"),
    ("predict", (0.1, math.inf, 0.0), {}, "left must be finite"),
    ("predict", (0.1, 0.0, "a"), {}, "dtheta must be a number"),
    ("predict", (0.1, 0.0, 0.0), {"q": np.eye(2)}, r"q must have shape \(3, 3\)"),
    ("predict", (0.1, 0.0, 0.0), {"q": -np.eye(3)}, "q must be positive semi-definite"),
    ("predict", (0.1, 0.0, 0.0), {"q": [[1, 2, 0], [0, 1, 0], [0, 0, 1]]}, "symmetric"),
    ("update_position", ((1.0,), np.eye(2)), {}, "two numbers"),
    ("update_position", ((1.0, NAN), np.eye(2)), {}, "fix y must be finite"),
    ("update_position", ((1.0, 2.0), np.eye(3)), {}, r"cov2x2 must have shape \(2, 2\)"),
    ("update_position", ((1.0, 2.0), [[1.0, 2.0], [2.0, 1.0]]), {}, "positive definite"),
    ("update_position", ((1.0, 2.0), np.zeros((2, 2))), {}, "positive definite"),
    ("update_position", ((1.0, 2.0), np.eye(2)), {"gate": 0.0}, "gate must be > 0"),
    ("update_position", ((1.0, 2.0), np.eye(2)), {"gate_cov": [[NAN, 0], [0, 1]]}, "finite"),
    ("update_heading", (NAN, 0.1), {}, "yaw must be finite"),
    ("update_heading", (0.1, 0.0), {}, "heading variance must be > 0"),
    ("update_heading", (0.1, 0.1), {"gate": -1.0}, "gate must be > 0"),
    ("update_axis", ("z", 0.0, 0.1), {}, "axis must be 'x' or 'y'"),
    ("update_axis", ("x", 0.0, -0.1), {}, "axis variance must be > 0"),
    ("update_axis", ("x", math.inf, 0.1), {}, "value must be finite"),
    ("update_ranges", ([], [], 0.05), {}, "at least one beacon"),
    ("update_ranges", ([(0, 0, 1), (5, 0, 1)], [3.0], 0.05), {}, "1 range.*2 beacon"),
    ("update_ranges", ([(0, 0, 1)], [-3.0], 0.05), {}, "finite and >= 0"),
    ("update_ranges", ([(0, 0, 1)], [3.0], 0.0), {}, "sigma must be finite and > 0"),
    ("update_ranges", ([(0, 0, 1)], [3.0], [0.1, 0.2]), {}, "sigma one number"),
    ("update_ranges", ([(0, 0, 1, 2)], [3.0], 0.1), {}, "beacon 0 .* must have x, y"),
    ("update_ranges", ([(0, NAN, 1)], [3.0], 0.1), {}, "beacon 0 y must be finite"),
    ("reset", (Pose2D(0.0, NAN, 0.0),), {}, "pose y must be finite"),
    ("reset", ((1.0, 2.0, 3.0),), {}, "pose must be a Pose2D"),
    ("reset", (None, np.diag([1.0, 1.0, 0.0])), {}, "P must be positive definite"),
]


@pytest.mark.parametrize(("method", "args", "kwargs", "match"), BAD_CALLS)
def test_bad_input_raises_and_leaves_the_filter_unchanged(method, args, kwargs, match):
    ekf = PoseEKF(Pose2D(1.0, 2.0, 0.3), np.diag([0.5, 0.4, 0.2]))
    ekf.predict(0.2, 0.0, 0.1)
    ekf.update_position((1.1, 2.1), np.eye(2) * 0.1)
    before = state_of(ekf)
    last = ekf.last_distance2
    with pytest.raises(ValueError, match=match):
        getattr(ekf, method)(*args, **kwargs)
    assert_unchanged(ekf, before)
    assert ekf.last_distance2 == last


def test_bad_constructor_arguments():
    with pytest.raises(ValueError, match="q_pos must be >= 0"):
        PoseEKF(q_pos=-1.0)
    with pytest.raises(ValueError, match="q_yaw_turn must be finite"):
        PoseEKF(q_yaw_turn=NAN)
    with pytest.raises(ValueError, match="P must be symmetric"):
        PoseEKF(P=[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]])
    ekf = PoseEKF()
    assert ekf.pose == Pose2D() and np.array_equal(ekf.covariance, DEFAULT_P0)


def test_reset_and_the_read_only_views():
    ekf = PoseEKF(Pose2D(1.0, 2.0, 3.0))
    ekf.predict(1.0, 0.0, 0.5)
    ekf.update_heading(3.4, 0.01)
    p = ekf.covariance
    p[0, 0] = 99.0  # a copy: the filter is not changed through it
    assert ekf.covariance[0, 0] != 99.0
    ekf.reset(Pose2D(-4.0, 5.0, 7.0), np.diag([0.1, 0.2, 0.3]))
    assert ekf.pose == Pose2D(-4.0, 5.0, 7.0)  # continuous yaw kept as given
    assert np.array_equal(ekf.covariance, np.diag([0.1, 0.2, 0.3]))
    assert ekf.last_distance2 is None
    ekf.reset()
    assert ekf.pose == Pose2D() and np.array_equal(ekf.covariance, DEFAULT_P0)


def test_increment_helpers_reject_bad_poses():
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        increments_from_poses(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="finite"):
        increments_from_poses([[0, 0, 0], [NAN, 0, 0]])
    with pytest.raises(ValueError, match="finite"):
        pose_increment(Pose2D(), Pose2D(math.inf, 0.0, 0.0))


# --- the simulated run (system test) --------------------------------------------------------


@pytest.fixture(scope="module")
def run():
    return fs.simulate_field_run(1)


@pytest.fixture(scope="module")
def fused(run):
    stats = {}
    return fs.run_fusion(run, stats=stats), stats


def test_the_simulated_run_is_a_200_m_mowing_run_with_every_sensor(run):
    n = run.mouse.shape[0]
    assert 195 < run.run_length_m < 215
    assert run.truth.shape == run.raw.shape == run.raw_wheels.shape == (n + 1, 3)
    assert np.diff(run.t)[:-1] == pytest.approx(np.full(n - 1, 1 / fs.ODOM_HZ))  # last: the rest
    assert run.t[-1] == pytest.approx(run.run_length_m / fs.SPEED, rel=1e-3)
    x, y = run.truth[:, 0], run.truth[:, 1]
    assert -1 < x.min() < 0 and fs.PLOT_W < x.max() < fs.PLOT_W + 1
    assert y.min() < 0 and y.max() > fs.PLOT_H
    # rates: 2 Hz GPS, 5 Hz beacons, 10 Hz compass
    assert len(run.gps) == n // 10 and len(run.ranges) == n // 4 and len(run.compass) == n // 2
    assert np.diff([g.t for g in run.gps]) == pytest.approx(0.5)
    # every wire is crossed; each lane end crosses the east/west wire twice
    wires = {(c.wire.axis, c.wire.value) for c in run.contacts}
    assert wires == {("x", 0.0), ("x", fs.PLOT_W), ("y", 0.0), ("y", fs.PLOT_H)}
    assert len(run.contacts) == 2 + 2 * (fs.LANES - 1)
    for c in run.contacts:
        i = 0 if c.wire.axis == "x" else 1
        assert abs(run.truth[c.k, i] - c.wire.value) < fs.SPEED / fs.ODOM_HZ + 1e-9
    # GPS: lat/lon round trip, some epochs flagged bad, error realistic
    g = run.gps[0]
    assert run.grid.to_local(g.lat, g.lon) == pytest.approx(g.xy, abs=1e-6)
    bad = [q for q in run.gps if q.quality.hdop > 2 or q.quality.satellites < 5]
    assert 0.03 < len(bad) / len(run.gps) < 0.15
    assert 0.5 < np.median([q.error_m for q in run.gps]) < 4.0
    # ranges are slant ranges (beacons 1 m up) with 5 cm noise and a few long NLOS ones
    ks = [m.k for m in run.ranges]
    bxy = np.array([(b.x, b.y) for b in run.beacons])
    true_r = np.hypot(np.hypot(*(run.truth[ks, None, :2] - bxy).transpose(2, 0, 1)), 1.0)
    resid = np.array([m.ranges for m in run.ranges]) - true_r
    good = np.abs(resid) < 0.25
    assert np.std(resid[good]) == pytest.approx(fs.RANGE_SIGMA, rel=0.05)
    assert 0.01 < np.mean(~good) < 0.03 and np.all(resid[~good] > 0)


def test_the_simulated_run_is_reproducible(run):
    again = fs.simulate_field_run(1)
    assert np.array_equal(again.raw, run.raw) and again.gps == run.gps
    other = fs.simulate_field_run(2)
    assert not np.array_equal(other.raw, run.raw)


def test_without_corrections_the_filter_is_the_raw_odometry(run):
    poses = fs.run_fusion(run, use=())
    assert np.max(np.abs(poses - run.raw)) < 1e-9


def test_fused_error_stays_bounded_while_raw_odometry_drifts(run, fused):
    poses, stats = fused
    raw = fs.errors(run, run.raw)
    fus = fs.errors(run, poses)
    assert fus["final_m"] < 0.5 and fus["max_m"] < 0.5
    assert raw["final_m"] > 3 * fus["final_m"]
    assert raw["max_m"] > 3 * fus["max_m"]
    assert raw["final_m"] > 2.0  # raw really drifts: metres after 200 m
    # bounded, not just small at the end: the last quarter is no worse than the first
    e = np.hypot(*(poses[:, :2] - run.truth[:, :2]).T)
    q = e.size // 4
    assert e[-q:].max() < 2 * e[:q].max() + 0.05
    # every source contributed; ghosts and outliers were gated
    by = stats["by_input"]
    assert all(by[name]["applied"] > 0 for name in ("gps", "beacons", "compass", "perimeter"))
    assert by["gps"]["skipped"] > 0 and by["gps"]["rejected"] > 0
    assert stats["predicts"] == run.mouse.shape[0]


def test_gps_compass_and_wire_alone_also_bound_the_error(run):
    fus = fs.errors(run, fs.run_fusion(run, use=("gps", "compass", "perimeter")))
    raw = fs.errors(run, run.raw)
    assert fus["max_m"] < 1.0
    assert raw["max_m"] > 3 * fus["max_m"]


def test_wheel_odometry_as_motion_model_with_trilaterated_fixes(run):
    fus = fs.errors(run, fs.run_fusion(run, use=("trilateration", "compass"), motion="wheels"))
    assert fus["max_m"] < 0.5
    assert fs.errors(run, run.raw_wheels)["final_m"] > 3 * fus["final_m"]


def test_run_fusion_rejects_unknown_inputs(run):
    with pytest.raises(ValueError, match="use must be a collection"):
        fs.run_fusion(run, use="gps")
    with pytest.raises(ValueError, match="use must be a collection"):
        fs.run_fusion(run, use=("gps", "lidar"))
    with pytest.raises(ValueError, match="motion must be one of"):
        fs.run_fusion(run, motion="legs")


def test_lawn_path_rejects_a_bad_speed():
    with pytest.raises(ValueError, match="speed must be a finite number of m/s > 0"):
        fs.lawn_path(speed=0.0)


def test_gps_inflation_is_the_gauss_markov_factor():
    assert gps_inflation(0.5, 30.0) == pytest.approx(
        (1 + math.exp(-1 / 60)) / (1 - math.exp(-1 / 60))
    )
    assert gps_inflation(1e6, 1.0) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="must be > 0"):
        gps_inflation(0.0, 30.0)


def test_sensor_mount_used_by_the_simulation_is_off_the_axle():
    # the exact method needs a sensor off the axle line (sy != 0)
    assert isinstance(DEFAULT_MOUNTS[0], SensorMount) and DEFAULT_MOUNTS[0].forward != 0


def test_predict_with_a_subnormal_turn():
    """Hypothesis found c = 5e-324, whose half is 0.0 (a division by zero before)."""
    ekf = PoseEKF()
    ekf.predict(0.5, 0.0, 5e-324)
    assert ekf.pose.x == 0.5 and ekf.pose.yaw == 5e-324
