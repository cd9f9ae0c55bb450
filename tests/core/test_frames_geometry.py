"""Units, frames and robot geometry (mm_pc.core.frames, mm_pc.core.geometry).

The sign conventions checked here are the ones every pose method builds on:
sensor X right / Y forward; base_link x forward / y left; a mounting yaw
turns the reported vector by -yaw, exactly as pln2033.motion.Rotated does.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_pc.core.frames import INCH_M, base_to_sensor, counts_to_m, m_to_counts, sensor_to_base
from mm_pc.core.geometry import DEFAULT_GEOMETRY, DEFAULT_MOUNTS, RobotGeometry, SensorMount
from mm_pc.sim.robot import sensor_displacements
from pln2033.motion import ConstantVelocity, Rotated

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
cpis = st.integers(min_value=100, max_value=6400)


# --- frames ---------------------------------------------------------------------------


@given(finite, finite)
def test_sensor_base_round_trip(x, y):
    bx, by = sensor_to_base(x, y)
    sx, sy = base_to_sensor(bx, by)
    assert float(sx) == x and float(sy) == y
    bx2, by2 = sensor_to_base(*base_to_sensor(x, y))
    assert float(bx2) == x and float(by2) == y


@given(st.lists(st.tuples(finite, finite), min_size=1, max_size=50))
def test_sensor_base_round_trip_arrays(pairs):
    x = np.array([p[0] for p in pairs])
    y = np.array([p[1] for p in pairs])
    sx, sy = base_to_sensor(*sensor_to_base(x, y))
    np.testing.assert_array_equal(sx, x)
    np.testing.assert_array_equal(sy, y)


def test_sensor_axes_map_to_rep103():
    # Forward motion changes only sensor Y and is base_link +x.
    assert tuple(map(float, sensor_to_base(0.0, 1.0))) == (1.0, 0.0)
    # Sensor +X is the robot's right, i.e. base_link -y.
    assert tuple(map(float, sensor_to_base(1.0, 0.0))) == (0.0, -1.0)
    # base_link +y (left) is sensor -X.
    assert tuple(map(float, base_to_sensor(0.0, 1.0))) == (-1.0, 0.0)


@given(st.integers(min_value=-(2**31), max_value=2**31), cpis)
def test_counts_metres_round_trip(counts, cpi):
    m = counts_to_m(counts, cpi)
    assert float(m_to_counts(m, cpi)) == pytest.approx(counts, abs=1e-6)


def test_counts_to_m_values():
    assert float(counts_to_m(1600, 1600)) == pytest.approx(INCH_M)
    assert INCH_M == 0.0254
    np.testing.assert_allclose(counts_to_m(np.array([0, 400, -800]), 400), [0, 0.0254, -0.0508])
    # Per-sample CPI arrays broadcast.
    np.testing.assert_allclose(counts_to_m([100, 100], [100, 200]), [0.0254, 0.0127])


@pytest.mark.parametrize("cpi", [0, -100, float("nan"), float("inf"), [400, 0]])
def test_cpi_must_be_positive(cpi):
    with pytest.raises(ValueError, match="CPI must be a positive number"):
        counts_to_m(10, cpi)
    with pytest.raises(ValueError, match="CPI must be a positive number"):
        m_to_counts(0.01, cpi)


# --- geometry -------------------------------------------------------------------------


def test_default_robot_derived_values():
    g = DEFAULT_GEOMETRY
    assert g.axis_length == pytest.approx(0.079)
    assert g.distance_to_wheel == pytest.approx(0.0395)
    s1, s2 = g.mounts
    assert (s1, s2) == DEFAULT_MOUNTS
    # Sensor 1: 3.95 cm right, 4.9 cm forward of the axle centre.
    assert s1.right == pytest.approx(0.0395) and s1.forward == pytest.approx(0.049)
    assert (s1.x, s1.y) == pytest.approx((0.049, -0.0395))
    # Sensor 2 mirrored to the left.
    assert s2.right == pytest.approx(-0.0395) and s2.forward == pytest.approx(0.049)
    r = math.hypot(0.0395, 0.049)
    assert s1.radius == pytest.approx(r) and s2.radius == pytest.approx(r)
    assert s1.radius == pytest.approx(0.06294, abs=1e-5)
    # base_link angle to the sensor: right of forward is negative (CW).
    assert s1.sensor_angle == pytest.approx(-math.atan2(0.0395, 0.049))
    assert s2.sensor_angle == pytest.approx(math.atan2(0.0395, 0.049))
    assert math.degrees(s2.sensor_angle) == pytest.approx(38.88, abs=0.01)
    # Seed's slope m = -sx/sy.
    assert s1.slope == pytest.approx(-0.0395 / 0.049)
    assert s2.slope == pytest.approx(0.0395 / 0.049)
    assert SensorMount(0.0, 0.03).slope == math.inf


def test_slope_is_the_sensor_dy_dx_of_a_pure_rotation():
    for mount in DEFAULT_MOUNTS:
        dx, dy = sensor_displacements(np.array([0.0]), np.array([1.0]), 0.001, mount)
        assert float(dy[0] / dx[0]) == pytest.approx(mount.slope)


def test_pivot_turn_left_signs():
    """Turning CCW (left) on the spot: the right-front sensor moves left and forward."""
    right_front = DEFAULT_MOUNTS[0]
    dx, dy = sensor_displacements(np.array([0.0]), np.array([1.0]), 0.001, right_front)
    assert dx[0] < 0 and dy[0] > 0
    # Exact kinematics of the design notes: dtheta = -dX/sy.
    assert float(-dx[0] / right_front.forward) == pytest.approx(0.001)


@given(
    st.floats(min_value=-math.pi, max_value=math.pi),
    st.floats(min_value=-1.0, max_value=1.0),
    st.floats(min_value=-1.0, max_value=1.0),
)
@settings(max_examples=50)
def test_mount_yaw_agrees_with_pln2033_rotated(yaw, v, omega):
    """SensorMount.yaw and pln2033.motion.Rotated turn the reported vector the same way."""
    mount = SensorMount(0.049, -0.0395, yaw)
    ideal = SensorMount(0.049, -0.0395, 0.0)
    dx, dy = sensor_displacements(np.array([v]), np.array([omega]), 0.001, mount)
    ix, iy = sensor_displacements(np.array([v]), np.array([omega]), 0.001, ideal)
    rx, ry = Rotated(ConstantVelocity(ix[0] / 0.001, iy[0] / 0.001), yaw).displacement(0.0, 0.001)
    assert float(dx[0]) == pytest.approx(rx, abs=1e-15)
    assert float(dy[0]) == pytest.approx(ry, abs=1e-15)


def test_positive_yaw_reports_forward_as_rightward_x():
    # Axes turned CCW by yaw: forward motion shows up with +X (the ideal vector turned by -yaw).
    dx, dy = sensor_displacements(np.array([1.0]), np.array([0.0]), 1.0, SensorMount(0, 0, 0.1))
    assert float(dx[0]) == pytest.approx(math.sin(0.1))
    assert float(dy[0]) == pytest.approx(math.cos(0.1))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"mounts": ()}, "at least one sensor mount"),
        ({"mounts": DEFAULT_MOUNTS, "axis_length": 0.0}, "axle length must be > 0"),
        ({"mounts": DEFAULT_MOUNTS, "axis_length": -0.1}, "axle length must be > 0"),
        ({"mounts": DEFAULT_MOUNTS, "axis_length": float("nan")}, "axle length must be > 0"),
        ({"mounts": (SensorMount(float("nan"), 0.0),)}, "non-finite"),
        ({"mounts": (SensorMount(0.05, float("inf")),)}, "non-finite"),
        ({"mounts": (SensorMount(0.05, 0.0, float("nan")),)}, "non-finite"),
    ],
)
def test_robot_geometry_rejects_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        RobotGeometry(**kwargs)


def test_geometry_is_immutable():
    with pytest.raises(AttributeError):
        DEFAULT_MOUNTS[0].x = 1.0  # type: ignore[misc]
