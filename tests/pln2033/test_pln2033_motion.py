"""Motion sources: the true sensor-frame displacement the emulator counts."""

from __future__ import annotations

import itertools
import math

import pytest
from fakes import FakeClock
from hypothesis import given, settings
from hypothesis import strategies as st

from pln2033 import INCH_M
from pln2033.motion import ConstantVelocity, Rotated, SampledPath, Stationary
from pln2033.pln2033 import PLN2033, EmulatedPLN2033, RegisterMap

MAP = RegisterMap.default()



def approx2(xy, abs=1e-12):
    return pytest.approx(xy, abs=abs)


# --- Stationary, ConstantVelocity ------------------------------------------------------------


def test_stationary():
    assert Stationary().displacement(0.0, 100.0) == (0.0, 0.0)


@pytest.mark.parametrize(("vx", "vy"), [(0.1, 0.2), (-0.3, 0.0), (0.0, -1.5)])
def test_constant_velocity(vx, vy):
    cv = ConstantVelocity(vx, vy)
    assert cv.displacement(2.0, 2.5) == approx2((vx * 0.5, vy * 0.5))
    assert cv.displacement(3.0, 3.0) == (0.0, 0.0)


# --- SampledPath ---------------------------------------------------------------------------------

X = [0.0, 1.0, 3.0]
Y = [0.0, -2.0, -2.0]


def test_sampled_path_interpolates_linearly():
    p = SampledPath(X, Y, dt=0.5)
    assert p.duration == 1.0
    assert p.position(0.0) == (0.0, 0.0)
    assert p.position(0.25) == approx2((0.5, -1.0))
    assert p.position(0.5) == approx2((1.0, -2.0))
    assert p.position(0.75) == approx2((2.0, -2.0))
    assert p.position(0.999) == approx2((2.996, -2.0), abs=1e-9)
    assert p.displacement(0.25, 0.75) == approx2((1.5, -1.0))


def test_sampled_path_holds_before_the_start_and_after_the_end():
    p = SampledPath(X, Y, dt=0.5, t_start=10.0)
    assert p.position(0.0) == (0.0, 0.0)
    assert p.position(10.0) == (0.0, 0.0)
    assert p.position(10.25) == approx2((0.5, -1.0))
    assert p.position(11.0) == approx2((3.0, -2.0))
    assert p.position(50.0) == approx2((3.0, -2.0))
    assert p.displacement(11.0, 50.0) == (0.0, 0.0)
    assert p.displacement(9.0, 12.0) == approx2((3.0, -2.0))


def test_sampled_path_is_relative_to_its_first_sample():
    p = SampledPath([5.0, 6.0], [-1.0, 1.0], dt=1.0)
    assert p.position(0.0) == (0.0, 0.0)
    assert p.position(1.0) == approx2((1.0, 2.0))


def test_sampled_path_loop_repeats_from_where_the_lap_ended():
    p = SampledPath(X, Y, dt=0.5, loop=True)
    assert p.position(1.0) == approx2((3.0, -2.0))
    assert p.position(1.25) == approx2((3.5, -3.0))
    assert p.position(2.0) == approx2((6.0, -4.0))
    assert p.position(10.75) == approx2((10 * 3.0 + 2.0, 10 * -2.0 - 2.0), abs=1e-9)
    assert p.displacement(0.0, 3.0) == approx2((9.0, -6.0))


@pytest.mark.parametrize("lap", [1, 2, 7, 1000])
def test_sampled_path_loop_is_continuous_across_lap_boundaries(lap):
    p = SampledPath(X, Y, dt=0.5, loop=True)
    eps = 1e-9
    at = p.position(lap * p.duration)
    before = p.position(lap * p.duration - eps)
    after = p.position(lap * p.duration + eps)
    assert at == approx2((3.0 * lap, -2.0 * lap), abs=1e-9)
    # The last interval moves x by 2.0 per 0.5 s and the first by (1, -2) per 0.5 s.
    assert math.dist(before, at) < 10 * eps
    assert math.dist(after, at) < 10 * eps


@given(
    xs=st.lists(st.floats(-10, 10), min_size=2, max_size=8),
    data=st.data(),
    dt=st.floats(0.01, 2.0),
    loop=st.booleans(),
)
@settings(max_examples=100, deadline=None)
def test_sampled_path_displacements_add_up(xs, data, dt, loop):
    """d(a, b) + d(b, c) == d(a, c) in any call order (the path caches its last time)."""
    ys = data.draw(st.lists(st.floats(-10, 10), min_size=len(xs), max_size=len(xs)))
    times = sorted(data.draw(st.lists(st.floats(-1.0, 30.0), min_size=3, max_size=10)))
    p = SampledPath(xs, ys, dt=dt, loop=loop)
    fresh = SampledPath(xs, ys, dt=dt, loop=loop)
    sx = sy = 0.0
    for a, b in itertools.pairwise(times):
        dx, dy = p.displacement(a, b)
        sx += dx
        sy += dy
    total = fresh.displacement(times[0], times[-1])
    scale = 1.0 + max(abs(v) for v in xs + ys) * (1 + times[-1] / dt)
    assert sx == pytest.approx(total[0], abs=1e-9 * scale)
    assert sy == pytest.approx(total[1], abs=1e-9 * scale)
    # A non-consecutive query after the walk is still right (no stale cache).
    mid = times[len(times) // 2]
    x0, y0 = fresh.position(mid)
    x1, y1 = fresh.position(times[-1])
    assert p.displacement(mid, times[-1]) == pytest.approx((x1 - x0, y1 - y0), abs=1e-12)


@given(
    xs=st.lists(st.floats(-10, 10), min_size=2, max_size=6),
    t=st.floats(0.0, 100.0),
)
def test_sampled_path_loop_position_matches_lap_arithmetic(xs, t):
    ys = [-v for v in xs]
    dt = 0.1
    p = SampledPath(xs, ys, dt=dt, loop=True)
    laps = math.floor(t / p.duration)
    rest = t - laps * p.duration
    once = SampledPath(xs, ys, dt=dt)
    ex, ey = once.position(rest)
    ex += laps * (xs[-1] - xs[0])
    ey += laps * (ys[-1] - ys[0])
    x, y = p.position(t)
    assert x == pytest.approx(ex, abs=1e-7 * (1 + laps))
    assert y == pytest.approx(ey, abs=1e-7 * (1 + laps))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (([0.0, 1.0], [0.0], 0.1), "two equally long position lists of length >= 2"),
        (([0.0], [0.0], 0.1), "two equally long position lists of length >= 2"),
        (([0.0, 1.0], [0.0, 1.0], 0.0), "dt must be > 0, got 0.0"),
        (([0.0, 1.0], [0.0, 1.0], -1.0), "dt must be > 0, got -1.0"),
        (([0.0, 1.0], [0.0, 1.0], float("nan")), "dt must be > 0, got nan"),
    ],
)
def test_sampled_path_rejects_bad_input(args, message):
    with pytest.raises(ValueError) as info:
        SampledPath(*args)
    assert message in str(info.value)


def test_sampled_path_drives_the_emulator():
    """A 1 cm square driven at 1 kHz polls comes back as counts of the path."""
    xs = [0.0, 0.01, 0.01, 0.0, 0.0]
    ys = [0.0, 0.0, 0.01, 0.01, 0.0]
    clock = FakeClock()
    emu = EmulatedPLN2033(SampledPath(xs, ys, dt=0.25), regmap=MAP, clock=clock)
    drv = PLN2033(emu, regmap=MAP)
    drv.set_cpi(2000)
    x = y = 0
    corners = {}
    for i in range(1, 1001):
        clock.t = i / 1000
        m = drv.read_motion()
        x += m.dx
        y += m.dy
        if i % 250 == 0:
            corners[i // 250] = (x, y)
    side = 0.01 * 2000 / INCH_M  # 787.4 counts
    assert corners[1] == pytest.approx((side, 0), abs=1)
    assert corners[2] == pytest.approx((side, side), abs=1)
    assert corners[3] == pytest.approx((0, side), abs=1)
    assert corners[4] == pytest.approx((0, 0), abs=1)
    assert (x, y) == (emu.stats.counted_x, emu.stats.counted_y)


# --- Rotated ------------------------------------------------------------------------------


@pytest.mark.parametrize("deg", [10.0, 45.0, 90.0])
def test_rotated_turns_the_vector_by_minus_yaw(deg):
    yaw = math.radians(deg)
    fwd = Rotated(ConstantVelocity(0.0, 1.0), yaw).displacement(0.0, 1.0)
    right = Rotated(ConstantVelocity(1.0, 0.0), yaw).displacement(0.0, 1.0)
    # Sensor turned CCW by yaw: pure forward motion shows up with a +x (right) part.
    assert fwd == approx2((math.sin(yaw), math.cos(yaw)))
    assert right == approx2((math.cos(yaw), -math.sin(yaw)))
    fwd_neg = Rotated(ConstantVelocity(0.0, 1.0), -yaw).displacement(0.0, 1.0)
    assert fwd_neg == approx2((-math.sin(yaw), math.cos(yaw)))


def test_rotated_90_degrees_exactly():
    dx, dy = Rotated(ConstantVelocity(1.0, 2.0), math.pi / 2).displacement(0.0, 1.0)
    assert (dx, dy) == approx2((2.0, -1.0))


@given(
    vx=st.floats(-5, 5),
    vy=st.floats(-5, 5),
    yaw=st.floats(-math.pi, math.pi),
)
def test_rotated_keeps_length_and_undoes_with_minus_yaw(vx, vy, yaw):
    src = ConstantVelocity(vx, vy)
    dx, dy = Rotated(src, yaw).displacement(0.0, 1.0)
    assert math.hypot(dx, dy) == pytest.approx(math.hypot(vx, vy), abs=1e-9)
    back = Rotated(Rotated(src, yaw), -yaw).displacement(0.0, 1.0)
    assert back == pytest.approx((vx, vy), abs=1e-9)


def test_rotated_through_the_emulator():
    yaw = math.radians(5.0)
    clock = FakeClock()
    emu = EmulatedPLN2033(Rotated(ConstantVelocity(0.0, 0.2), yaw), regmap=MAP, clock=clock)
    drv = PLN2033(emu, regmap=MAP)
    x = y = 0
    for i in range(1, 501):
        clock.t = i / 1000
        m = drv.read_motion()
        x += m.dx
        y += m.dy
    dist = 0.2 * 0.5 * 1000 / INCH_M
    assert x == pytest.approx(dist * math.sin(yaw), abs=1)
    assert y == pytest.approx(dist * math.cos(yaw), abs=1)
    assert math.degrees(math.atan2(x, y)) == pytest.approx(5.0, abs=0.05)
