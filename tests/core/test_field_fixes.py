"""Wheel odometry, compass, GPS and perimeter fixes (mm_pc.core.fixes, seed 004).

Expected values are worked out by hand from geometry (noted next to each), or
are the seed's own numbers; the frame conversions get hypothesis round trips.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_pc.core.angles import compass_to_rep103, rep103_to_compass, wrap_pi
from mm_pc.core.fixes.gps import (
    GpsQuality,
    LocalGrid,
    gps_accuracy_m,
    gps_fix_usable,
    wgs84_m_per_deg,
)
from mm_pc.core.fixes.perimeter import (
    PerimeterSegment,
    correct_at_wire,
    nearest_segment,
    perimeter_correction,
    rectangle_perimeter,
    sensor_position,
)
from mm_pc.core.fixes.seed_rules import gps_correction, seed_gentle_step, seed_pivot_step
from mm_pc.core.fixes.wheels import WheelOdometry, blend_heading, body_increment, tick_length
from mm_pc.core.odometry import Pose2D

PI = math.pi
angles = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False)


def circle_dist(a: float, b: float) -> float:
    """Smallest angle between two directions (rad)."""
    return abs((a - b + PI) % (2 * PI) - PI)


# --- angle conversion --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("heading", "yaw"),
    [
        (0.0, PI / 2),  # north = +y
        (PI / 2, 0.0),  # east = +x
        (PI, -PI / 2),  # south
        (3 * PI / 2, PI),  # west (the seed writes 3*pi/4 by mistake)
        (PI / 4, PI / 4),  # north-east is its own mirror image
        (5 * PI / 4, -3 * PI / 4),  # south-west
    ],
)
def test_compass_cardinal_points(heading, yaw):
    assert compass_to_rep103(heading) == pytest.approx(yaw, abs=1e-12)
    assert rep103_to_compass(yaw) == pytest.approx(heading, abs=1e-12)


def test_compass_conversion_returns_float_for_scalars_and_arrays_for_arrays():
    assert isinstance(compass_to_rep103(0.0), float)
    assert isinstance(rep103_to_compass(0.0), float)
    h = np.array([0.0, PI / 2, PI, 3 * PI / 2])
    np.testing.assert_allclose(compass_to_rep103(h), [PI / 2, 0.0, -PI / 2, PI], atol=1e-12)
    np.testing.assert_allclose(rep103_to_compass([PI / 2, 0.0]), [0.0, PI / 2], atol=1e-12)


@given(angles)
def test_compass_round_trip(h):
    yaw = compass_to_rep103(h)
    assert -PI < yaw <= PI
    back = rep103_to_compass(yaw)
    assert 0.0 <= back < 2 * PI
    assert circle_dist(back, h) < 1e-9


@given(angles)
def test_rep103_round_trip_and_direction_vector(yaw):
    h = rep103_to_compass(yaw)
    assert 0.0 <= h < 2 * PI
    # The same direction: compass (sin h, cos h) = REP 103 (cos yaw, sin yaw), x east, y north.
    assert math.sin(h) == pytest.approx(math.cos(yaw), abs=1e-9)
    assert math.cos(h) == pytest.approx(math.sin(yaw), abs=1e-9)
    assert circle_dist(compass_to_rep103(h), yaw) < 1e-9


@given(st.lists(angles, min_size=1, max_size=20))
def test_compass_vectorised_matches_scalar(hs):
    out = compass_to_rep103(np.array(hs))
    assert out.shape == (len(hs),)
    np.testing.assert_allclose(out, [compass_to_rep103(h) for h in hs], atol=0)


def test_wrap_edges_stay_in_their_ranges():
    assert wrap_pi(-PI) == PI
    assert wrap_pi(PI) == PI
    # arrays take the same wrap element by element (pln2033.angles.wrap_pi), edges included
    edges = np.array([-PI, PI, 3 * PI, -3 * PI, -0.1, 0.0])
    assert wrap_pi(edges).tolist() == [wrap_pi(float(a)) for a in edges]
    assert wrap_pi(np.array(-PI)) == PI and wrap_pi(np.zeros(0)).shape == (0,)
    assert -PI < wrap_pi(-1e-300) <= PI
    assert 0.0 <= rep103_to_compass(PI / 2 + 1e-300) < 2 * PI
    assert rep103_to_compass(PI / 2 - 1e-17) < 2 * PI


@pytest.mark.parametrize("bad", [math.nan, math.inf, "north", None])
def test_compass_conversion_rejects_non_finite(bad):
    with pytest.raises(ValueError, match="compass heading must be finite"):
        compass_to_rep103(bad)
    with pytest.raises(ValueError, match="yaw must be finite"):
        rep103_to_compass(bad)
    with pytest.raises(ValueError, match="finite"):
        compass_to_rep103(np.array([0.0, bad if bad is not None else math.nan], dtype=object))


# --- heading blend -----------------------------------------------------------------------------


def test_blend_weights_and_the_seam():
    assert blend_heading(0.2, 0.6, 0.0) == 0.2
    assert blend_heading(0.2, 0.6, 1.0) == pytest.approx(0.6)
    assert blend_heading(0.2, 0.6, 0.25) == pytest.approx(0.3)
    # Across +-pi: 3.0 and -3.0 are 2*pi - 6 = 0.283 rad apart; half way is 3.0 + 0.1416 = pi.
    assert blend_heading(3.0, -3.0, 0.5) == pytest.approx(3.0 + (PI - 3.0))
    assert blend_heading(-3.0, 3.0, 0.5) == pytest.approx(-3.0 - (PI - 3.0))


def test_blend_keeps_the_odometry_branch():
    # Two turns counted: yaw = 4*pi + 0.1; compass says 0.3 -> 4*pi + 0.2 at w = 0.5.
    assert blend_heading(4 * PI + 0.1, 0.3, 0.5) == pytest.approx(4 * PI + 0.2)


@given(angles, angles, st.floats(0.0, 1.0))
def test_blend_moves_the_short_way_by_the_weight(o, c, w):
    out = blend_heading(o, c, w)
    gap = circle_dist(o, c)
    assert abs(out - o) == pytest.approx(w * gap, abs=1e-9)
    assert circle_dist(out, c) == pytest.approx((1 - w) * gap, abs=1e-9)


def test_blend_vectorised():
    out = blend_heading(np.array([0.0, 3.0]), np.array([1.0, -3.0]), 0.5)
    np.testing.assert_allclose(out, [0.5, PI])


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((0.0, 0.0, 1.5), r"weight must be in \[0, 1\]"),
        ((0.0, 0.0, -0.1), r"weight must be in \[0, 1\]"),
        ((0.0, 0.0, math.nan), "weight must be finite"),
        ((math.nan, 0.0, 0.5), "odometry yaw must be finite"),
        ((0.0, math.inf, 0.5), "compass yaw must be finite"),
    ],
)
def test_blend_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        blend_heading(*args)


# --- wheel odometry ----------------------------------------------------------------------------


def test_seed_tick_length_is_47_mm():
    # Seed: 180 mm wheel, 12 pulses per turn -> 47 mm per pulse (pi * 0.18 / 12 = 0.04712).
    assert tick_length(0.18, 12) == pytest.approx(0.047124, abs=1e-6)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((0.0, 12), r"wheel diameter \(m\) must be > 0"),
        ((0.18, 0), "ticks per revolution must be an integer >= 1"),
        ((0.18, 12.5), "ticks per revolution must be an integer"),
    ],
)
def test_tick_length_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        tick_length(*args)


def test_body_increment_by_hand():
    # forward (0.3 + 0.5)/2 = 0.4, no sideways motion, turn (0.5 - 0.3)/0.4 = +0.5 (left, CCW).
    assert body_increment(0.3, 0.5, 0.4) == pytest.approx((0.4, 0.0, 0.5))
    odo = WheelOdometry(0.4)
    assert odo.body_increment(0.5, 0.3) == pytest.approx((0.4, 0.0, -0.5))
    assert odo.pose == Pose2D()  # pure: no state change


def test_straight_north():
    odo = WheelOdometry(0.4, pose=Pose2D(1.0, 2.0, PI / 2))
    pose = odo.update(0.5, 0.5)
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((1.0, 2.5, PI / 2))
    assert odo.pose == pose


@pytest.mark.parametrize("steps", [1, 7, 100])
def test_left_quarter_circle_is_exact_at_any_step_size(steps):
    # Facing east at the origin, a left circle of radius R about (0, R): a quarter ends at
    # (R, R) facing north. Wheel arcs: (R -+ b/2) * pi/2.
    r, b = 1.5, 0.4
    odo = WheelOdometry(b)
    for _ in range(steps):
        odo.update((r - b / 2) * PI / 2 / steps, (r + b / 2) * PI / 2 / steps)
    assert (odo.pose.x, odo.pose.y, odo.pose.yaw) == pytest.approx((r, r, PI / 2), abs=1e-12)


def test_spin_on_the_spot_keeps_the_position():
    odo = WheelOdometry(0.4, pose=Pose2D(3.0, 4.0, 0.0))
    odo.update(-0.1 * PI, 0.1 * PI)  # turn = 0.2*pi/0.4 = pi/2
    assert (odo.pose.x, odo.pose.y, odo.pose.yaw) == pytest.approx((3.0, 4.0, PI / 2), abs=1e-12)


def test_pivot_quarter_turn_about_the_left_wheel():
    # Facing north at the origin, track 0.4: the left wheel stands at (-0.2, 0). The right
    # wheel rolls a quarter circle of radius 0.4 (0.2*pi); the centre swings about the left
    # wheel from (+0.2, 0) relative to (0, +0.2): ends at (-0.2, 0.2) facing west.
    odo = WheelOdometry(0.4, pose=Pose2D(0.0, 0.0, PI / 2))
    pose = odo.pivot(0.4 * PI / 2, about="left")
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((-0.2, 0.2, PI), abs=1e-12)


def test_pivot_quarter_turn_about_the_right_wheel():
    # Mirror image: the right wheel stands at (0.2, 0); ends at (0.2, 0.2) facing east.
    odo = WheelOdometry(0.4, pose=Pose2D(0.0, 0.0, PI / 2))
    pose = odo.pivot(0.4 * PI / 2, about="right")
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((0.2, 0.2, 0.0), abs=1e-12)


def test_pivot_half_turn_ends_a_track_width_aside():
    # Half a turn about the left wheel puts the centre on the far side: 0.4 m to the left.
    odo = WheelOdometry(0.4)  # facing east, left = north
    odo.pivot(0.4 * PI, about="left")
    assert (odo.pose.x, odo.pose.y, odo.pose.yaw) == pytest.approx((0.0, 0.4, PI), abs=1e-12)


@settings(max_examples=60)
@given(
    st.floats(-5, 5),
    st.floats(-5, 5),
    st.floats(-10, 10),
    st.floats(-2.0, 2.0),
    st.sampled_from(["left", "right"]),
)
def test_pivot_agrees_with_the_arc_update(x, y, yaw, d, about):
    a = WheelOdometry(0.35, pose=Pose2D(x, y, yaw))
    b = WheelOdometry(0.35, pose=Pose2D(x, y, yaw))
    a.pivot(d, about)
    b.update(0.0, d) if about == "left" else b.update(d, 0.0)
    assert a.pose.as_array() == pytest.approx(b.pose.as_array(), abs=1e-9)
    # Driving the same wheel back undoes it.
    a.pivot(-d, about)
    assert a.pose.as_array() == pytest.approx([x, y, yaw], abs=1e-9)


def test_update_ticks_with_the_seed_wheel():
    odo = WheelOdometry(0.4, metres_per_tick=tick_length(0.18, 12), pose=Pose2D(0, 0, PI / 2))
    odo.update_ticks(12, 12)  # one wheel turn each: pi * 0.18 m north
    assert (odo.pose.x, odo.pose.y) == pytest.approx((0.0, PI * 0.18), abs=1e-12)


def test_integrate_matches_repeated_update():
    rng = np.random.default_rng(4)
    dl, dr = rng.uniform(-0.05, 0.05, 50), rng.uniform(-0.05, 0.05, 50)
    one = WheelOdometry(0.4, pose=Pose2D(1.0, -2.0, 0.3))
    many = WheelOdometry(0.4, pose=Pose2D(1.0, -2.0, 0.3))
    rows = [one.update(float(a), float(b)).as_array() for a, b in zip(dl, dr, strict=True)]
    out = many.integrate(dl, dr)
    np.testing.assert_allclose(out, np.array(rows), atol=1e-12)
    assert many.pose.as_array() == pytest.approx(one.pose.as_array(), abs=1e-12)
    assert many.integrate([], []).shape == (0, 3)


def test_blend_compass_into_the_pose():
    odo = WheelOdometry(0.4, pose=Pose2D(1.0, 2.0, 0.0))  # facing east
    pose = odo.blend_compass(0.0, 1.0)  # compass: north
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((1.0, 2.0, PI / 2))
    pose = odo.blend_compass(PI / 2, 0.5)  # compass: east -> half way back
    assert pose.yaw == pytest.approx(PI / 4)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda o: o.update(math.nan, 0.1), r"left wheel travel \(m\) must be finite"),
        (lambda o: o.update(0.1, math.inf), r"right wheel travel \(m\) must be finite"),
        (lambda o: o.pivot(0.1, "middle"), "about must be 'left' or 'right'"),
        (lambda o: o.pivot(math.nan, "left"), "pivot wheel travel"),
        (lambda o: o.update_ticks(1, 1), "update_ticks needs metres_per_tick"),
        (lambda o: o.integrate([0.1, 0.2], [0.1]), "left and right travels differ"),
        (lambda o: o.integrate([0.1, math.nan], [0.1, 0.1]), "left wheel travels"),
        (lambda o: o.blend_compass(math.nan, 0.5), "compass heading must be finite"),
        (lambda o: o.blend_compass(0.0, 2.0), r"weight must be in \[0, 1\]"),
        (lambda o: o.reset(Pose2D(math.nan, 0, 0)), "pose x must be finite"),
        (lambda o: o.reset((0, 0, 0)), "pose must be a mm_pc.core.odometry.Pose2D"),
    ],
)
def test_wheel_odometry_rejects_bad_input_and_keeps_its_pose(call, match):
    start = Pose2D(1.0, 2.0, 0.5)
    odo = WheelOdometry(0.4, pose=start)
    with pytest.raises(ValueError, match=match):
        call(odo)
    assert odo.pose == start


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"track_width": -0.4}, r"track width \(m\) must be > 0"),
        ({"track_width": math.nan}, r"track width \(m\) must be finite"),
        ({"track_width": 0.4, "metres_per_tick": 0.0}, "metres per tick must be > 0"),
        ({"track_width": 0.4, "pose": Pose2D(0, math.inf, 0)}, "pose y must be finite"),
    ],
)
def test_wheel_odometry_rejects_bad_construction(kwargs, match):
    with pytest.raises(ValueError, match=match):
        WheelOdometry(**kwargs)


# --- the seed's own formulas, compared ------------------------------------------------------------


@given(st.floats(0, 2 * PI), st.floats(-1, 1))
def test_seed_straight_step_agrees_through_the_angle_conversion(h, d):
    x, y, h_new = seed_gentle_step(2.0, 3.0, h, d, d, 0.4)
    odo = WheelOdometry(0.4, pose=Pose2D(2.0, 3.0, compass_to_rep103(h)))
    odo.update(d, d)
    assert (x, y) == pytest.approx((odo.pose.x, odo.pose.y), abs=1e-12)
    assert h_new == h


def test_seed_gentle_step_error_on_a_quarter_circle():
    # Right quarter circle of radius 1 m from heading north, track 0.4 m, in steps of about
    # one tick (34 steps of 46 mm): the truth ends at (1, 1) facing east.
    r, b, n = 1.0, 0.4, 34
    ds = PI / 2 * r / n
    dl, dr = ds * (r + b / 2) / r, ds * (r - b / 2) / r
    x = y = h = 0.0
    odo = WheelOdometry(b, pose=Pose2D(0.0, 0.0, compass_to_rep103(0.0)))
    for _ in range(n):
        x, y, h = seed_gentle_step(x, y, h, dl, dr, b)
        odo.update(dl, dr)
    assert (odo.pose.x, odo.pose.y) == pytest.approx((1.0, 1.0), abs=1e-12)
    assert rep103_to_compass(odo.pose.yaw) == pytest.approx(PI / 2)
    assert h == pytest.approx(PI / 2)  # the seed's heading is right ...
    assert math.hypot(x - 1.0, y - 1.0) == pytest.approx(0.0327, abs=5e-4)  # ... 3.3 cm off
    # In one step the seed's formula moves the whole arc along the final heading.
    x1, y1, _ = seed_gentle_step(0.0, 0.0, 0.0, n * dl, n * dr, b)
    assert (x1, y1) == pytest.approx((PI / 2, 0.0), abs=1e-12)


def test_seed_pivot_taken_literally_swings_backwards():
    # Heading north, left wheel stands, right wheel rolls a quarter turn (0.2*pi m).
    # Truth (see test_pivot_quarter_turn_about_the_left_wheel): (-0.2, 0.2) facing west.
    x, y, h = seed_pivot_step(0.0, 0.0, 0.0, 0.0, 0.4 * PI / 2, 0.4)
    assert (x, y) == pytest.approx((-0.2, -0.2), abs=1e-12)  # behind the axle: wrong sense
    assert h % (2 * PI) == pytest.approx(3 * PI / 2)  # compass heading west: right
    with pytest.raises(ValueError, match="one standing wheel"):
        seed_pivot_step(0.0, 0.0, 0.0, 0.1, 0.1, 0.4)


# --- GPS local grid ------------------------------------------------------------------------------


def test_wgs84_scales_match_textbook_values():
    # 1 deg latitude: 110 574 m at the equator, 111 132 m at 45 deg; longitude 111 320 / 78 847 m.
    assert wgs84_m_per_deg(0.0) == pytest.approx((110574, 111320), abs=1.0)
    assert wgs84_m_per_deg(45.0) == pytest.approx((111132, 78847), abs=1.0)
    grid = LocalGrid(45.0, 7.0)
    assert (grid.m_per_deg_lat, grid.m_per_deg_lon) == pytest.approx((111132, 78847), abs=1.0)


def test_from_plot_uses_the_known_plot_size():
    # A 40 m x 30 m plot; its NE corner surveyed 0.0004 deg east and 0.0003 deg north.
    grid = LocalGrid.from_plot(48.2, 16.3, 48.2003, 16.3004, 40.0, 30.0)
    assert grid.m_per_deg_lon == pytest.approx(100000.0)
    assert grid.m_per_deg_lat == pytest.approx(100000.0)
    assert grid.to_local(48.2, 16.3) == pytest.approx((0.0, 0.0), abs=1e-9)
    assert grid.to_local(48.2003, 16.3004) == pytest.approx((40.0, 30.0), abs=1e-6)
    assert grid.to_local(48.20015, 16.3002) == pytest.approx((20.0, 15.0), abs=1e-6)
    assert grid.to_geodetic(40.0, 30.0) == pytest.approx((48.2003, 16.3004), abs=1e-12)


def test_grid_vectorised_and_across_the_antimeridian():
    grid = LocalGrid(-40.0, 179.9999, m_per_deg_lat=1e5, m_per_deg_lon=1e5)
    x, y = grid.to_local(np.array([-40.0, -39.9999]), np.array([179.9999, -179.9999]))
    np.testing.assert_allclose(x, [0.0, 20.0], atol=1e-6)  # 0.0002 deg east, over the seam
    np.testing.assert_allclose(y, [0.0, 10.0], atol=1e-6)
    lat, lon = grid.to_geodetic(x, y)
    np.testing.assert_allclose(lat, [-40.0, -39.9999], atol=1e-12)
    np.testing.assert_allclose(lon, [179.9999, -179.9999], atol=1e-9)
    assert isinstance(grid.to_local(-40.0, 179.9999)[0], float)


@given(
    st.floats(-80, 80),
    st.floats(-180, 180),
    st.floats(-500, 500),
    st.floats(-500, 500),
)
def test_grid_round_trip(lat0, lon0, x, y):
    grid = LocalGrid(lat0, lon0)
    lat, lon = grid.to_geodetic(x, y)
    assert grid.to_local(lat, lon) == pytest.approx((x, y), abs=1e-6)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: LocalGrid(91.0, 0.0), r"origin latitude \(deg\) must be within \[-90, 90\]"),
        (lambda: LocalGrid(89.5, 0.0), r"origin latitude must be within \(-89, 89\)"),
        (lambda: LocalGrid(0.0, 181.0), r"origin longitude \(deg\) must be within"),
        (lambda: LocalGrid(math.nan, 0.0), "origin latitude .* finite"),
        (lambda: LocalGrid(0.0, 0.0, m_per_deg_lat=-1.0), "metres per degree of latitude"),
        (lambda: LocalGrid.from_plot(48.2, 16.3, 48.1, 16.4, 40, 30), "NE corner must be north"),
        (lambda: LocalGrid.from_plot(48.2, 16.3, 48.3, 16.2, 40, 30), "NE corner must be east"),
        (lambda: LocalGrid.from_plot(48.2, 16.3, 48.3, 16.4, 0, 30), r"plot width \(m\) must"),
        (lambda: LocalGrid(0.0, 0.0).to_local(95.0, 0.0), r"latitude \(deg\) must be within"),
        (lambda: LocalGrid(0.0, 0.0).to_local(0.0, math.nan), r"longitude \(deg\) must be"),
        (lambda: LocalGrid(0.0, 0.0).to_geodetic(0.0, 2e7), "beyond a pole"),
    ],
)
def test_grid_rejects_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call()


# --- GPS quality and the correction rule ------------------------------------------------------


def test_gps_quality_rules():
    good = GpsQuality(hdop=0.9, satellites=8, fix_type=1)
    assert gps_fix_usable(good)
    assert not gps_fix_usable(GpsQuality(2.1, 8, 1))  # HDOP too high
    assert not gps_fix_usable(GpsQuality(0.9, 4, 1))  # too few satellites
    assert not gps_fix_usable(GpsQuality(0.9, 8, 0))  # no fix
    assert not gps_fix_usable(GpsQuality(0.9, 8, 6))  # dead reckoning, not a measurement
    assert not gps_fix_usable(GpsQuality(0.0, 8, 1))  # HDOP 0: "unknown"
    assert gps_fix_usable(GpsQuality(3.0, 4, 2), max_hdop=3.0, min_satellites=4)
    # Seed: +-2.5 m in good conditions (HDOP ~1), +-5 m near walls (HDOP ~2).
    assert gps_accuracy_m(GpsQuality(1.0, 8, 1)) == pytest.approx(2.5)
    assert gps_accuracy_m(GpsQuality(2.0, 8, 1)) == pytest.approx(5.0)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((-0.5, 8, 1), "HDOP must be >= 0"),
        ((math.nan, 8, 1), "HDOP must be finite"),
        ((1.0, -1, 1), "satellites must be >= 0"),
        ((1.0, 8.0, 1), "satellites must be an integer"),
        ((1.0, 8, 9), r"fix type must be in 0\.\.8"),
    ],
)
def test_gps_quality_rejects_bad_values(args, match):
    with pytest.raises(ValueError, match=match):
        GpsQuality(*args)


def test_gps_correction_only_beyond_the_accuracy():
    good = GpsQuality(1.0, 8, 1)  # accuracy 2.5 m
    assert gps_correction((0.0, 0.0), (2.4, 0.0), good) is None
    assert gps_correction((0.0, 0.0), (1.5, 2.0), good) is None  # 2.5 m: not more than
    assert gps_correction((0.0, 0.0), (3.0, 4.0), good) == pytest.approx((3.0, 4.0))
    # Boundary mode: from 5 m away move to 2.5 m from the fix, along the line: (1.5, 2.0).
    assert gps_correction((0.0, 0.0), (3.0, 4.0), good, mode="boundary") == pytest.approx(
        (1.5, 2.0)
    )


def test_gps_correction_ignores_a_poor_fix_however_far():
    assert gps_correction((0.0, 0.0), (30.0, 40.0), GpsQuality(5.0, 8, 1)) is None
    assert gps_correction((0.0, 0.0), (30.0, 40.0), GpsQuality(1.0, 3, 1)) is None
    assert gps_correction((0.0, 0.0), (30.0, 40.0), GpsQuality(5.0, 8, 1), max_hdop=6.0) == (
        30.0,
        40.0,
    )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"estimate_xy": (math.nan, 0.0)}, "estimate x must be finite"),
        ({"gps_xy": (1.0,)}, r"GPS position must be an \(x, y\) pair"),
        ({"quality": (1.0, 8, 1)}, "quality must be a GpsQuality"),
        ({"mode": "halfway"}, "mode must be 'gps' or 'boundary'"),
        ({"uere_m": 0.0}, r"UERE \(m\) must be > 0"),
        ({"max_hdop": -1.0}, "max HDOP must be > 0"),
    ],
)
def test_gps_correction_rejects_bad_input(kwargs, match):
    args = {"estimate_xy": (0.0, 0.0), "gps_xy": (3.0, 4.0), "quality": GpsQuality(1.0, 8, 1)}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        gps_correction(**args)


# --- perimeter wire ----------------------------------------------------------------------------


def test_seed_examples_heading_west_and_north():
    wire = rectangle_perimeter(20.0, 15.0)
    # Heading west near the west edge: contact means x = 0, y untouched.
    assert correct_at_wire((0.4, 6.0), wire, yaw=PI) == (0.0, 6.0)
    # Heading north near the north edge: y = max, x untouched.
    assert correct_at_wire((7.0, 14.6), wire, yaw=PI / 2) == (7.0, 15.0)


def test_seed_extension_left_and_right_front_sensors():
    # Heading south-west (compass 225 deg) into the SW corner; sensors 0.3 m forward, 0.2 m
    # to either side. Left-front offset = 0.3*(-s, -s) + 0.2*(s, -s) = (-0.1 s, -0.5 s),
    # s = sqrt(1/2): it points south, so it meets the south wire (y = 0).
    wire = rectangle_perimeter(20.0, 15.0)
    yaw = compass_to_rep103(5 * PI / 4)
    s = math.sqrt(0.5)
    left, right = (0.3, 0.2), (0.3, -0.2)
    assert sensor_position((0.6, 0.5), yaw, left) == pytest.approx((0.6 - 0.1 * s, 0.5 - 0.5 * s))
    assert correct_at_wire((0.6, 0.5), wire, yaw, left) == pytest.approx((0.6, 0.5 * s))
    # The right-front sensor points west: it fixes x = 0.
    assert correct_at_wire((0.5, 0.6), wire, yaw, right) == pytest.approx((0.5 * s, 0.6))


def test_perimeter_correction_direct():
    assert perimeter_correction((1.0, 2.0), ("x", 0.0)) == (0.0, 2.0)
    assert perimeter_correction((1.0, 2.0), PerimeterSegment("y", 9.0)) == (1.0, 9.0)
    # A sensor 0.25 m ahead, facing east, on the wire x = 5: the centre is at x = 4.75.
    assert perimeter_correction((4.0, 2.0), ("x", 5.0), 0.0, (0.25, 0.0)) == (4.75, 2.0)


def test_segment_distance_and_nearest():
    seg = PerimeterSegment("x", 0.0, 0.0, 10.0)
    assert seg.distance((3.0, 5.0)) == 3.0
    assert seg.distance((3.0, 14.0)) == 5.0  # past the end: to (0, 10), a 3-4-5 triangle
    wire = rectangle_perimeter(20.0, 15.0)
    assert nearest_segment((19.0, 7.0), wire) == wire[1]  # east
    assert nearest_segment((10.0, 7.5), wire, max_distance=5.0) is None
    assert nearest_segment((0.0, 0.0), wire) == wire[0]  # tie at the corner: the first
    assert correct_at_wire((10.0, 7.5), wire, max_distance=5.0) is None


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: PerimeterSegment("z", 0.0), "perimeter axis must be 'x' or 'y'"),
        (lambda: PerimeterSegment("x", math.nan), r"wire coordinate \(m\) must be finite"),
        (lambda: PerimeterSegment("x", 0.0, 5.0, 1.0), "start <= end"),
        (lambda: perimeter_correction((1.0, 2.0), "x"), "contact must be a PerimeterSegment"),
        (lambda: perimeter_correction((math.inf, 2.0), ("x", 0.0)), "estimate x"),
        (lambda: nearest_segment((0.0, 0.0), []), "at least one perimeter segment"),
        (lambda: nearest_segment((0.0, 0.0), rectangle_perimeter(1, 1), -1.0), "max distance"),
        (lambda: rectangle_perimeter(-1.0, 5.0), r"plot width \(m\) must be > 0"),
        (lambda: sensor_position((0.0, 0.0), math.nan), "yaw must be finite"),
    ],
)
def test_perimeter_rejects_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call()
