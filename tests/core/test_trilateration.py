"""Trilateration: the seed's pair construction and least squares, against exact geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_pc.bench.maps_trilateration import bench_trilateration
from mm_pc.core.angles import compass_to_rep103, rep103_to_compass
from mm_pc.core.maps.trilateration import (
    MAX_RESIDUAL_SIGMAS,
    Beacon,
    Fix,
    TrilaterationError,
    best_three,
    least_squares_fix,
    pair_candidates,
    plane_distances,
    seed_fix,
    simulate_ranges,
)

# Hand-checkable example in the spirit of the seed's (its numbers were images and are lost):
# robot at (3, 4); A = (0, 0) 12 m high (5-12-13 triangle), B = (6, 0), C = (-2, 8).
# Pair AB: d = 6, l_A = l_B = 5, cos(delta) = 36/60 -> candidates (3, 4) and (3, -4).
# Pair BC: BC = (-8, 8), x_BC < 0 (the seed's kappa = 360 deg - gamma case: gamma = 45 deg,
# kappa_BC = 315 deg), d = 8 sqrt 2, l_B = 5, l_C = sqrt 41, cos(delta) = 112 / (80 sqrt 2)
# -> delta = 8.13 deg, kappa_B = 323.13 or 306.87 deg -> candidates (3, 4) and (2, 3).
# |z| = 0, sqrt 2, 8, sqrt 50: the first is the fix.
EXAMPLE = (Beacon(0.0, 0.0, 12.0, "A"), Beacon(6.0, 0.0, 0.0, "B"), Beacon(-2.0, 8.0, 0.0, "C"))
EXAMPLE_RANGES = (13.0, 5.0, math.sqrt(41.0))
SQUARE = tuple(
    Beacon(x, y, 1.0, n) for x, y, n in ((0, 0, "SW"), (30, 0, "SE"), (30, 30, "NE"), (0, 30, "NW"))
)
FIXERS = (seed_fix, least_squares_fix)


# ---------------------------------------------------------------- plane distances, angles


def test_plane_distance_is_the_other_leg_of_the_right_triangle():
    beacons = [Beacon(0, 0, 12.0), Beacon(1, 1, 3.0), Beacon(2, 2, -3.0), Beacon(3, 3, 2.0)]
    d = plane_distances(beacons, [13.0, 5.0, 5.0, 2.0])
    np.testing.assert_allclose(d, [5.0, 4.0, 4.0, 0.0], atol=1e-12)


def test_range_shorter_than_height_is_an_error_naming_the_beacon():
    beacons = [Beacon(0, 0, 1.0, "gate"), Beacon(5, 0, 1.0)]
    ranges = np.array([0.99, 6.0])
    with pytest.raises(TrilaterationError, match=r"0\.99 m to beacon 0 \(gate\) is shorter"):
        plane_distances(beacons, ranges)
    np.testing.assert_array_equal(ranges, [0.99, 6.0])  # input left alone


def test_compass_angles_map_to_rep103():
    # north, east, south, west in the seed's compass angles
    for kappa, theta in ((0, 90), (90, 0), (180, -90), (270, 180), (315, 135)):
        assert math.degrees(compass_to_rep103(math.radians(kappa))) == pytest.approx(theta)
        assert math.degrees(rep103_to_compass(math.radians(theta))) % 360 == pytest.approx(kappa)
    # the seed's x_AB < 0 case: BC = (-8, 8) has kappa_BC = 360 - 45 = 315 deg
    assert math.degrees(rep103_to_compass(math.atan2(8, -8))) == pytest.approx(315.0)


def test_pair_candidates_of_the_worked_example():
    c, gap = pair_candidates((0, 0), (6, 0), 5.0, 5.0)
    assert gap == 0.0
    np.testing.assert_allclose(c, [[3, 4], [3, -4]], atol=1e-12)
    c, gap = pair_candidates((6, 0), (-2, 8), 5.0, math.sqrt(41))
    assert gap == 0.0
    np.testing.assert_allclose(sorted(map(tuple, c)), [(2, 3), (3, 4)], atol=1e-12)


def test_pair_candidates_that_miss_report_the_gap_and_the_nearest_point():
    c, gap = pair_candidates((0, 0), (10, 0), 4.0, 5.0)  # 1 m apart
    assert gap == pytest.approx(1.0)
    np.testing.assert_allclose(c, [[4, 0], [4, 0]], atol=1e-12)
    c, gap = pair_candidates((0, 0), (1, 0), 5.0, 2.0)  # circle B inside circle A
    assert gap == pytest.approx(2.0)
    np.testing.assert_allclose(c, [[5, 0], [5, 0]], atol=1e-12)


# ---------------------------------------------------------------- worked example, S_phi


def test_seed_worked_example():
    fix = seed_fix(EXAMPLE, EXAMPLE_RANGES)
    assert (fix.x, fix.y) == pytest.approx((3.0, 4.0), abs=1e-12)
    assert fix.quality < 1e-12
    assert fix.used == (0, 1, 2)
    assert fix.method == "seed"
    assert fix.covariance is None
    ls = least_squares_fix(EXAMPLE, EXAMPLE_RANGES)
    assert (ls.x, ls.y) == pytest.approx((3.0, 4.0), abs=1e-12)


def test_seed_quality_is_the_smallest_difference_and_s_phi_rejects():
    # C's range 5 mm long: pair BC's true candidate moves ~4x that (the pair's triangle is
    # flat at B, delta = 8 deg), so |z|_min ~ 0.02 m like the seed's example
    ranges = (13.0, 5.0, math.sqrt(41.0) + 0.005)
    fix = seed_fix(EXAMPLE, ranges, s_phi=0.5)
    q1, _ = pair_candidates((6, 0), (-2, 8), 5.0, ranges[2])
    assert fix.quality == pytest.approx(min(np.hypot(*(q - (3, 4))) for q in q1), rel=1e-9)
    assert 0.01 < fix.quality < 0.03
    assert (fix.x, fix.y) == pytest.approx((3.0, 4.0), abs=1e-12)  # pair AB is exact
    with pytest.raises(TrilaterationError, match=rf"quality \|z\|_min = {fix.quality:.6g} m > "):
        seed_fix(EXAMPLE, ranges, s_phi=0.01)
    assert seed_fix(EXAMPLE, ranges, s_phi=math.inf).quality == fix.quality


# ---------------------------------------------------------------- exact recovery


@st.composite
def scenes(draw):
    """Beacons on a circle, well spread, with heights; the robot inside their hull."""
    n = draw(st.integers(3, 6))
    radius = draw(st.floats(2.0, 60.0))
    cx, cy = draw(st.floats(-100, 100)), draw(st.floats(-100, 100))
    gaps = draw(st.lists(st.floats(0.3, 1.0), min_size=n, max_size=n))
    phase = draw(st.floats(0, 2 * math.pi))
    angles = phase + 2 * math.pi * np.cumsum(gaps) / sum(gaps)
    heights = draw(st.lists(st.floats(0.0, 3.0), min_size=n, max_size=n))
    beacons = [
        Beacon(cx + radius * math.cos(a), cy + radius * math.sin(a), h)
        for a, h in zip(angles, heights, strict=True)
    ]
    w = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n))) + 1e-3
    xy = np.array([(b.x, b.y) for b in beacons])
    robot = (w / w.sum()) @ xy
    return beacons, float(robot[0]), float(robot[1]), radius


@settings(max_examples=150, deadline=None)
@given(scenes())
def test_exact_ranges_give_the_exact_position_with_both_methods(scene):
    beacons, x, y, radius = scene
    ranges = simulate_ranges(beacons, x, y, 0.0, 0)
    ls = least_squares_fix(beacons, ranges)
    assert math.hypot(ls.x - x, ls.y - y) < 1e-9 * (1 + radius)
    assert ls.quality < 1e-9
    assert ls.used == tuple(range(len(beacons)))
    seed = seed_fix(beacons, ranges, s_phi=1e-3)
    # arccos near 0 or pi loses half the digits: sqrt(eps) * radius
    assert math.hypot(seed.x - x, seed.y - y) < 1e-6 * (1 + radius)
    assert len(seed.used) == 3 and len(set(seed.used)) == 3


def test_robot_on_a_beacon_pair_line_and_at_a_beacon():
    beacons = [Beacon(0, 0), Beacon(10, 0), Beacon(0, 10, 2.0)]
    for x, y in ((5.0, 0.0), (0.0, 0.0), (0.0, 10.0), (5.0, 5.0)):
        r = simulate_ranges(beacons, x, y, 0.0, 0)
        for fixer in FIXERS:
            f = fixer(beacons, r)
            assert (f.x, f.y) == pytest.approx((x, y), abs=1e-6), fixer.__name__


# ---------------------------------------------------------------- noise


def _errors(fixer, sigma, n=300, seed=7):
    rng = np.random.default_rng(seed)
    errs, nees = [], []
    for x, y in rng.uniform(2, 28, size=(n, 2)):
        f = fixer(SQUARE, simulate_ranges(SQUARE, x, y, sigma, rng), sigma=sigma)
        e = np.array([f.x - x, f.y - y])
        errs.append(e @ e)
        nees.append(e @ np.linalg.solve(np.array(f.covariance), e))
    return math.sqrt(np.mean(errs)), float(np.mean(nees))


def test_least_squares_error_scales_with_noise_and_matches_its_covariance():
    small, nees_small = _errors(least_squares_fix, 0.01)
    large, nees_large = _errors(least_squares_fix, 0.1)
    assert 7 < large / small < 13  # linear in sigma
    # 4 ranges at sigma over a 30 m square: sigma * GDOP ~ 0.7 - 1.2 sigma
    assert 0.5 * 0.1 < large < 1.5 * 0.1
    # normalised estimation error squared of a consistent 2-D estimate averages 2
    for nees in (nees_small, nees_large):
        assert 1.6 < nees < 2.4


def test_seed_error_grows_with_noise():
    rng = np.random.default_rng(3)
    rms = []
    for sigma in (0.01, 0.1):
        errs = []
        for x, y in rng.uniform(5, 25, size=(200, 2)):
            r = simulate_ranges(SQUARE, x, y, sigma, rng)
            try:
                f = seed_fix(SQUARE, r, s_phi=math.inf)
            except TrilaterationError:
                continue
            errs.append(math.hypot(f.x - x, f.y - y))
        assert len(errs) > 190
        rms.append(math.sqrt(np.mean(np.square(errs))))
    assert rms[0] < 0.1
    assert 5 < rms[1] / rms[0] < 20


def test_simulate_ranges_noise_and_reproducibility():
    r0 = simulate_ranges(SQUARE, 10.0, 20.0, 0.0, 1)
    np.testing.assert_allclose(r0[0], math.sqrt(100 + 400 + 1))
    a = simulate_ranges(SQUARE, 10.0, 20.0, 0.5, 42)
    b = simulate_ranges(SQUARE, 10.0, 20.0, 0.5, np.random.default_rng(42))
    np.testing.assert_array_equal(a, b)
    many = np.array([simulate_ranges(SQUARE, 10, 20, 0.5, s) - r0 for s in range(400)])
    assert np.std(many) == pytest.approx(0.5, rel=0.1)
    with pytest.raises(TrilaterationError, match="sigma must be a number >= 0"):
        simulate_ranges(SQUARE, 10, 20, -1.0, 0)


# ---------------------------------------------------------------- choice of three


def test_best_three_without_estimate_takes_the_roundest_triangle():
    beacons = [Beacon(0, 0), Beacon(10, 0), Beacon(5, 0.5), Beacon(5, 8.66)]
    assert best_three(beacons) == (0, 1, 3)  # equilateral; (0, 1, 2) is nearly flat


def test_best_three_with_estimate_prefers_low_gdop_and_skips_collinear():
    # 0, 1, 2 on a line through the robot's neighbourhood, 3 far off it
    beacons = [Beacon(0, 0), Beacon(10, 0), Beacon(20, 0), Beacon(10, 10)]
    assert best_three(beacons) in {(0, 1, 3), (0, 2, 3), (1, 2, 3)}
    used = best_three(beacons, near=(10, 3))
    assert 3 in used and used != (0, 1, 2)
    # near the robot a tall beacon's slant range hardly moves with x, y: avoid it
    tall = [Beacon(0, 0), Beacon(10, 0), Beacon(10, 10), Beacon(1, 1, 30.0)]
    assert best_three(tall, near=(2, 2)) == (0, 1, 2)


def test_seed_fix_with_more_beacons_uses_the_best_three():
    beacons = [*SQUARE, Beacon(15.0, 0.5, 1.0), Beacon(15.0, 29.5, 1.0)]
    r = simulate_ranges(beacons, 12.0, 17.0, 0.0, 0)
    f = seed_fix(beacons, r)
    assert (f.x, f.y) == pytest.approx((12.0, 17.0), abs=1e-6)
    assert f.used == best_three(beacons, near=(12.0, 17.0))


# ---------------------------------------------------------------- degenerate input


@pytest.mark.parametrize("fixer", FIXERS)
def test_collinear_beacons_are_rejected(fixer):
    beacons = [Beacon(0, 0), Beacon(5, 5), Beacon(10, 10), Beacon(-3, -3)]
    with pytest.raises(TrilaterationError, match="collinear"):
        fixer(beacons, simulate_ranges(beacons, 3, 0, 0.0, 0))
    with pytest.raises(TrilaterationError, match="collinear"):
        fixer(beacons[:3], simulate_ranges(beacons[:3], 3, 0, 0.0, 0))
    with pytest.raises(TrilaterationError, match="collinear"):
        best_three(beacons)


@pytest.mark.parametrize("fixer", FIXERS)
def test_coincident_beacons_are_rejected(fixer):
    beacons = [Beacon(0, 0), Beacon(0, 0), Beacon(5, 5)]
    with pytest.raises(TrilaterationError, match="collinear \\(or coincide\\)"):
        fixer(beacons, [1.0, 1.0, 6.0])


@pytest.mark.parametrize("fixer", FIXERS)
def test_ranges_that_do_not_intersect_are_rejected(fixer):
    ranges = [1.0, 1.0, 1.0]  # three small circles around far apart beacons
    with pytest.raises(TrilaterationError, match="do not intersect"):
        fixer(SQUARE[:3], ranges)


def test_seed_small_misses_are_tolerated_up_to_s_phi():
    beacons = [Beacon(0, 0), Beacon(10, 0), Beacon(5, 10)]
    r = simulate_ranges(beacons, 5.0, 0.0, 0.0, 0)  # on the line AB: circles touch
    r[0] -= 0.01  # now A's and B's circles miss by 1 cm
    f = seed_fix(beacons, r, s_phi=0.05)
    assert (f.x, f.y) == pytest.approx((4.99, 0.0), abs=1e-9)
    with pytest.raises(TrilaterationError, match=r"circles miss by 0\.01 m > s_phi = 0\.005 m"):
        seed_fix(beacons, r, s_phi=0.005)


def test_least_squares_rejects_residuals_beyond_the_noise():
    r = simulate_ranges(SQUARE, 10, 10, 0.0, 0)
    r[2] += 2.0  # one wrong range, far beyond sigma
    with pytest.raises(TrilaterationError, match=rf"> {MAX_RESIDUAL_SIGMAS:g} \* sigma"):
        least_squares_fix(SQUARE, r, sigma=0.05)
    f = least_squares_fix(SQUARE, r, sigma=1.0)  # plausible at 1 m noise
    assert 0.3 < f.quality < 1.0


@pytest.mark.parametrize("fixer", FIXERS)
def test_range_shorter_than_height_in_a_fix(fixer):
    with pytest.raises(TrilaterationError, match="shorter than its height 1 m"):
        fixer(SQUARE, [0.5, 30.0, 42.0, 30.0])


@pytest.mark.parametrize("fixer", [*FIXERS, best_three])
def test_fewer_than_three_beacons(fixer):
    with pytest.raises(TrilaterationError, match="need at least 3 beacons for a 2-D fix, got 2"):
        if fixer is best_three:
            fixer(SQUARE[:2])
        else:
            fixer(SQUARE[:2], [5.0, 30.0])


@pytest.mark.parametrize("fixer", FIXERS)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_ranges(fixer, bad):
    with pytest.raises(TrilaterationError, match=r"ranges must be finite \(m\); ranges\[1\]"):
        fixer(SQUARE, [20.0, bad, 20.0, 20.0])


@pytest.mark.parametrize("fixer", FIXERS)
def test_mismatched_lengths(fixer):
    with pytest.raises(TrilaterationError, match="got 3 ranges for 4 beacons"):
        fixer(SQUARE, [20.0, 20.0, 20.0])


@pytest.mark.parametrize("fixer", FIXERS)
def test_bad_range_values(fixer):
    with pytest.raises(TrilaterationError, match=r"ranges must be >= 0 m; ranges\[0\] = -1"):
        fixer(SQUARE, [-1.0, 20.0, 20.0, 20.0])
    with pytest.raises(TrilaterationError, match="ranges must be a 1-D sequence"):
        fixer(SQUARE, [[20.0, 20.0, 20.0, 20.0]])
    with pytest.raises(TrilaterationError, match="ranges must be numbers"):
        fixer(SQUARE, ["a", 20.0, 20.0, 20.0])


@pytest.mark.parametrize("field", ["x", "y", "height"])
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_beacon_must_be_finite(field, bad):
    kwargs = {"x": 1.0, "y": 2.0, "height": 0.5, field: bad}
    with pytest.raises(TrilaterationError, match=f"Beacon {field} must be finite"):
        Beacon(**kwargs)


def test_beacons_must_be_beacons():
    with pytest.raises(TrilaterationError, match=r"beacons\[1\] must be a Beacon, got tuple"):
        plane_distances([Beacon(0, 0), (1, 2)], [1.0, 2.0])
    with pytest.raises(TrilaterationError, match="Beacon x must be a real number"):
        Beacon("1", 2.0)


def test_bad_parameters():
    r = simulate_ranges(SQUARE, 10, 10, 0.0, 0)
    for s_phi in (-0.1, math.nan, "0.5"):
        with pytest.raises(TrilaterationError, match="s_phi must be a number >= 0 m"):
            seed_fix(SQUARE, r, s_phi=s_phi)
    for sigma in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(TrilaterationError, match="sigma must be finite and > 0 m"):
            least_squares_fix(SQUARE, r, sigma=sigma)
    with pytest.raises(TrilaterationError, match="initial must be two finite numbers"):
        least_squares_fix(SQUARE, r, initial=(1.0, math.nan))
    with pytest.raises(TrilaterationError, match="near must be two finite numbers"):
        best_three(SQUARE, near=(1.0, 2.0, 3.0))


def test_least_squares_from_a_given_start_and_covariance_shape():
    r = simulate_ranges(SQUARE, 10, 25, 0.0, 0)
    f = least_squares_fix(SQUARE, r, sigma=0.1, initial=(25.0, 3.0))
    assert (f.x, f.y) == pytest.approx((10.0, 25.0), abs=1e-9)
    cov = np.array(f.covariance)
    assert cov.shape == (2, 2)
    np.testing.assert_allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    # sigma scales the covariance quadratically, the position not at all
    g = least_squares_fix(SQUARE, r, sigma=0.2)
    np.testing.assert_allclose(np.array(g.covariance), 4 * cov, rtol=1e-9)
    assert isinstance(f, Fix) and f.method == "least_squares"


def test_fix_is_immutable():
    f = seed_fix(EXAMPLE, EXAMPLE_RANGES)
    with pytest.raises(AttributeError):
        f.x = 1.0  # type: ignore[misc]


# ---------------------------------------------------------------- benchmark


def test_benchmark_keys_and_sane_values():
    out = bench_trilateration(seconds_budget=0.2)
    for key in ("trilateration_fixes_per_s", "trilateration_fixes_per_s_seed"):
        assert out[key] > 10
    assert 0 < out["trilateration_error_m"] < 0.2
    assert 0 < out["trilateration_error_m_seed"] < 1.0
    rows = out["trilateration_error_vs_noise"]
    assert [r["sigma_m"] for r in rows] == [0.01, 0.05, 0.1, 0.2]
    for r in rows:
        assert set(r) >= {"sigma_m", "ls_rms_m", "seed_rms_m", "seed_rejected"}
        assert 0 < r["ls_rms_m"] < 10 * r["sigma_m"]
        assert 0 <= r["seed_rejected"] <= 1
