"""Coverage grid map (seed 001): the seed's component tests (cases 1-11) and the rest.

The seed's test map ``Karte.mat`` is not published; :func:`karte` builds one
with the features the cases need: a perimeter along the south edge and a
measured-looking west edge that steps one cell east at y = 1.8 m, so that
(0.0, 3.0) m lies outside the perimeter (unknown) and (0.3, 3.0) m on it.
"""

from __future__ import annotations

import math
import zipfile

import numpy as np
import pytest
import yaml
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from mm_pc.bench.maps_grid import bench_grid, lawn_polygon, mowing_path
from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.maps.coverage_map import (
    CODE_NAMES,
    COLORS_RGB,
    COLORS_RGB8,
    MOWED,
    MOWER,
    OBSTACLE,
    PERIMETER,
    SEED_SHAPE,
    UNKNOWN,
    UNMOWED,
    CoverageMap,
    UpdateResult,
)
from mm_pc.core.odometry import Odometry, Sample
from mm_pc.sim import robot as sim

COLOUR = {
    "white": (255, 255, 255),
    "red": (255, 0, 0),
    "dark green": (128, 204, 0),
    "light green": (0, 255, 0),
    "blue": (0, 0, 255),
    "magenta": (255, 128, 255),
}


def karte(nx: int = SEED_SHAPE[1], ny: int = SEED_SHAPE[0]) -> np.ndarray:
    """A seed-like map, codes[iy, ix]: perimeter ring with a step in the west edge."""
    a = np.zeros((ny, nx), dtype=np.uint8)
    a[1 : ny - 2, 1 : nx - 2] = UNMOWED
    a[0, : nx - 1] = PERIMETER  # south edge, from x = 0
    a[ny - 2, 1 : nx - 1] = PERIMETER  # north edge
    a[: ny - 1, nx - 2] = PERIMETER  # east edge
    a[:6, 0] = PERIMETER  # west edge, x 0..0.3 m, up to y = 1.8 m
    a[5:, 1] = PERIMETER  # then one cell east
    a[6:, 0] = UNKNOWN
    a[ny - 1, :] = UNKNOWN
    return a


def colour(m: CoverageMap, cell: tuple[int, int]) -> str:
    rgb = tuple(int(c) for c in m.rgb(north_up=False)[cell])
    return next(name for name, value in COLOUR.items() if value == rgb)


def drive(m: CoverageMap, pos_alt, x: float, y: float, bumper: int = 0):
    """The seed's call: the mower was at PosAlt, is now at (x, y).
    Returns (result, shown codes before this call)."""
    m.update(*pos_alt)
    before = m.codes.copy()
    return m.update(x, y, bumper=bumper), before


def diff(before: np.ndarray, after: np.ndarray) -> set[tuple[int, int, int]]:
    rows, cols = np.nonzero(before != after)
    return {(int(i), int(j), int(after[i, j])) for i, j in zip(rows, cols, strict=True)}


# --- the seed's component test table ---------------------------------------------------------


def test_case01_mower_moves_no_cell_further_no_new_cell_is_marked_blue():
    m = CoverageMap.from_array(karte())
    r, before = drive(m, (0.0, 0.0), 0.1, 0.0)
    assert r == UpdateResult((0, 0), False, False, ())
    assert np.array_equal(m.codes, before)
    assert np.count_nonzero(m.codes == MOWER) == 1 and colour(m, (0, 0)) == "blue"


def test_case02_mower_drives_on_the_perimeter_new_cell_blue_old_cell_red():
    m = CoverageMap.from_array(karte())
    r, before = drive(m, (0.3, 0.0), 0.6, 0.0)
    assert r.cell == (0, 2) and r.entered and not r.outside
    assert set(r.changed) == {(0, 2, MOWER), (0, 1, PERIMETER)} == diff(before, m.codes)
    assert colour(m, (0, 2)) == "blue" and colour(m, (0, 1)) == "red"


def test_case03_mower_moves_one_cell_further_new_cell_blue():
    m = CoverageMap.from_array(karte())
    r, before = drive(m, (0.0, 0.0), 0.3, 0.0)
    assert r.cell == (0, 1) and r.entered
    assert colour(m, (0, 1)) == "blue"
    assert colour(m, (0, 0)) == "red"  # the cell left was perimeter and stays so
    assert set(r.changed) == diff(before, m.codes) == {(0, 1, MOWER), (0, 0, PERIMETER)}


def test_case04_mower_hits_an_obstacle_new_cell_magenta_old_cell_light_green():
    # x = 34 m lies outside the seed's own 81 x 71 map (21.3 m wide); a wider lawn
    # (121 cells = 36.3 m) holds it. See the next test for the seed-size map.
    m = CoverageMap.from_array(karte(nx=121))
    r, before = drive(m, (33.7, 4.0), 34.0, 4.0, bumper=1)
    new, old = (13, 113), (13, 112)  # floor(4/0.3), floor(34/0.3), floor(33.7/0.3)
    assert r.cell == new and r.entered
    assert set(r.changed) == {(*new, OBSTACLE), (*old, MOWED)} == diff(before, m.codes)
    assert colour(m, new) == "magenta" and colour(m, old) == "light green"
    assert m.base[new] == OBSTACLE and m.base[old] == MOWED
    # never erased: drive off, back on without the bumper, off again
    for x in (33.7, 34.0, 34.3, 34.0, 33.7):
        m.update(x, 4.0)
    assert m.codes[new] == OBSTACLE and m.base[new] == OBSTACLE


def test_case04_on_the_seed_size_map_34_m_is_outside_and_changes_nothing():
    m = CoverageMap.from_array(karte())
    r, before = drive(m, (33.7, 4.0), 34.0, 4.0, bumper=1)
    assert r == UpdateResult(None, False, True, ())
    assert np.array_equal(m.codes, before) and np.array_equal(m.base, karte())
    assert m.mower_cell is None


def test_case05_mower_crosses_the_perimeter_into_unknown_new_cell_white_old_cell_red():
    m = CoverageMap.from_array(karte())
    r, before = drive(m, (0.3, 3.0), 0.0, 3.0)
    new, old = (10, 0), (10, 1)
    assert r.cell == new and r.entered and m.mower_cell == new
    assert colour(m, new) == "white" and colour(m, old) == "red"
    assert set(r.changed) == {(*old, PERIMETER)} == diff(before, m.codes)
    # back inside: the unknown cell left behind stays unknown
    r = m.update(0.3, 3.0)
    assert set(r.changed) == {(*old, MOWER)} and colour(m, new) == "white"


def test_case06_mower_drives_on_unmowed_lawn_new_cell_blue_old_cell_light_green():
    k = karte()
    assert k[1, 1] == UNMOWED and k[2, 2] == UNMOWED
    m = CoverageMap.from_array(k)
    r, before = drive(m, (0.3, 0.3), 0.6, 0.6)
    assert set(r.changed) == {(2, 2, MOWER), (1, 1, MOWED)} == diff(before, m.codes)
    assert colour(m, (2, 2)) == "blue" and colour(m, (1, 1)) == "light green"


def test_case06b_mower_drives_on_mowed_lawn_new_cell_blue_old_cell_light_green():
    k = karte()
    k[1, 1] = k[2, 2] = MOWED
    m = CoverageMap.from_array(k)
    r, before = drive(m, (0.3, 0.3), 0.6, 0.6)
    assert set(r.changed) == {(2, 2, MOWER), (1, 1, MOWED)} == diff(before, m.codes)
    assert colour(m, (2, 2)) == "blue" and colour(m, (1, 1)) == "light green"


def _trail_cells(m: CoverageMap, xy: np.ndarray) -> list[tuple[int, int]]:
    """Cells visited in order (consecutive repeats dropped), computed independently."""
    ix = np.floor((xy[:, 0] - m.origin[0]) / m.cell_size).astype(int)
    iy = np.floor((xy[:, 1] - m.origin[1]) / m.cell_size).astype(int)
    cells = list(zip(iy.tolist(), ix.tolist(), strict=True))
    return [c for i, c in enumerate(cells) if i == 0 or c != cells[i - 1]]


def _check_trail(m: CoverageMap, start: np.ndarray, results, trail) -> None:
    """After driving ``trail`` on an all-lawn area: the trail is mowed, the last
    cell holds the mower, nothing else changed, and replaying every update's
    ``changed`` on the start picture gives the final picture (a GUI's redraw)."""
    assert sum(r.entered for r in results) == len(trail)
    assert m.mower_cell == trail[-1] and m.codes[trail[-1]] == MOWER
    assert np.count_nonzero(m.codes == MOWER) == 1
    mowed = set(zip(*np.nonzero(m.codes == MOWED), strict=True))
    assert mowed == set(trail) - {trail[-1]}
    picture = start.copy()
    for r in results:
        for iy, ix, code in r.changed:
            picture[iy, ix] = code
    assert np.array_equal(picture, m.codes)
    untouched = np.ones(m.shape, bool)
    untouched[tuple(np.array(list(set(trail))).T)] = False
    assert np.array_equal(m.codes[untouched], start[untouched])


def test_case07_simulated_meander_at_a_fixed_cycle_updates_the_map_cyclically():
    v, w = sim.meander(speed=0.2, lane_length=3.0, lanes=6, lane_spacing=0.3)
    poses = sim.integrate_pose(v, w, sim.DT)[::50]  # one update per 50 ms cycle
    xy = poses[:, :2] + [2.0, 2.0]  # odom origin at (2, 2) m on the map
    m = CoverageMap.from_array(karte())
    start = m.codes.copy()
    results = [m.update(x, y) for x, y in xy.tolist()]
    trail = _trail_cells(m, xy)
    assert len(trail) > 60  # six lanes of ten cells at least
    _check_trail(m, start, results, trail)


def test_case08_integration_odometry_at_15_hz_drives_the_map():
    # The seed embeds its function in Simulink; here the map is fed by the real
    # pose pipeline: simulated sensor samples at 15 Hz -> Odometry -> map.
    v, w = sim.meander(speed=0.2, lane_length=3.0, lanes=4, lane_spacing=0.3)
    req = sim.request_samples(v, w, DEFAULT_MOUNTS, request_hz=15.0)
    odo = Odometry(DEFAULT_MOUNTS)
    offset = np.array([3.0, 3.0])
    m = CoverageMap.from_array(karte())
    start = m.codes.copy()
    results, xy = [], []
    for dt, d in zip(req.dt.tolist(), req.d.tolist(), strict=True):
        pose = odo.update(Sample.of(dt, *d))
        xy.append((pose.x + offset[0], pose.y + offset[1]))
        results.append(m.update(*xy[-1]))
    assert np.hypot(*(np.array(xy[-1]) - offset - req.truth[-1, :2])) < 0.005  # sane poses
    _check_trail(m, start, results, _trail_cells(m, np.array(xy)))


@pytest.mark.parametrize(
    ("x", "y", "bumper", "match"),
    [
        (math.nan, 1.0, 0, "position must be finite"),
        (1.0, math.nan, 0, "position must be finite"),
        (math.inf, 1.0, 0, "position must be finite"),
        (1.0, -math.inf, 0, "position must be finite"),
        (1.0, 1.0, 2, "bumper must be True/False"),
        (1.0, 1.0, 0.5, "bumper must be True/False"),
        (1.0, 1.0, "1", "bumper must be True/False"),
    ],
)
def test_case09_input_parameters_bad_values_raise_and_leave_the_map_unchanged(x, y, bumper, match):
    m = CoverageMap.from_array(karte())
    m.update(0.45, 0.45)
    codes, base, cell = m.codes.copy(), m.base.copy(), m.mower_cell
    with pytest.raises(ValueError, match=match):
        m.update(x, y, bumper=bumper)
    assert np.array_equal(m.codes, codes) and np.array_equal(m.base, base)
    assert m.mower_cell == cell


positions = st.floats(min_value=-1.0, max_value=4.0, allow_nan=False)


@settings(max_examples=80, deadline=None)
@given(
    base=st.lists(st.sampled_from([0, 1, 2, 3, 5]), min_size=100, max_size=100),
    steps=st.lists(st.tuples(positions, positions, st.booleans()), min_size=1, max_size=40),
)
def test_case10_output_parameters_match_the_rules_for_any_input(base, steps):
    """PosNeu and Karte of the seed: ``cell``/``mower_cell`` and ``changed`` against
    an independent account of the rules, for random lawns and random drives."""
    m = CoverageMap.from_array(np.array(base).reshape(10, 10))
    left_rule = {UNKNOWN: UNKNOWN, PERIMETER: PERIMETER, UNMOWED: MOWED, MOWED: MOWED}
    left_rule[OBSTACLE] = OBSTACLE
    for x, y, bumper in steps:
        codes0, base0, old = m.codes.copy(), m.base.copy(), m.mower_cell
        r = m.update(x, y, bumper=bumper)
        ix, iy = math.floor(x / 0.3), math.floor(y / 0.3)
        inside = 0 <= ix < 10 and 0 <= iy < 10
        assert r.outside == (not inside)
        assert r.cell == ((iy, ix) if inside else None)
        assert m.mower_cell == (r.cell if inside else old)
        assert set(r.changed) == diff(codes0, m.codes) and len(r.changed) == len(set(r.changed))
        assert r.entered == (inside and r.cell != old)
        if r.entered and old is not None:
            assert m.base[old] == m.codes[old] == left_rule[base0[old]]
        if r.entered:
            unknown = base0[r.cell] == UNKNOWN
            want = OBSTACLE if bumper else UNKNOWN if unknown else MOWER
            assert m.codes[r.cell] == want
        elif inside and bumper:
            assert m.codes[r.cell] == m.base[r.cell] == OBSTACLE
        elif inside:
            assert r.changed == ()
        # obstacles are never erased; the mower is never stored in the base layer
        assert np.all(m.base[base0 == OBSTACLE] == OBSTACLE)
        assert not np.any(m.base == MOWER)
        shown = m.base.copy()
        if m.mower_cell is not None and m.codes[m.mower_cell] == MOWER:
            shown[m.mower_cell] = MOWER
        assert np.array_equal(m.codes, shown)


def test_case11_runtime_measurement_reports_positive_times():
    m = CoverageMap.from_array(karte())
    r, _ = drive(m, (0.0, 0.0), 0.3, 0.0)  # the seed's input for case 11
    assert r.cell == (0, 1)
    out = bench_grid(seconds_budget=0.2)
    assert set(out) == {
        "grid_update_us_p50",
        "grid_update_us_p99",
        "grid_update_us_p50_1000",
        "grid_update_us_p99_1000",
        "grid_init_ms",
        "grid_init_polygon_ms",
    }
    for key, value in out.items():
        assert isinstance(value, float) and math.isfinite(value) and value > 0, key


# --- codes, colours, index convention, border ----------------------------------------------------


def test_colour_table_is_the_seeds_colour_map():
    assert CODE_NAMES == ("unknown", "perimeter", "unmowed", "mowed", "mower", "obstacle")
    assert COLORS_RGB[2] == (0.5, 0.8, 0.0) and COLORS_RGB[5] == (1.0, 0.5, 1.0)
    names = ["white", "red", "dark green", "light green", "blue", "magenta"]
    assert [tuple(c) for c in COLORS_RGB8.tolist()] == [COLOUR[n] for n in names]
    with pytest.raises(ValueError):
        COLORS_RGB8[0, 0] = 1


def test_index_convention_row_is_y_column_is_x_with_origin_and_half_open_cells():
    m = CoverageMap((4, 6), cell_size=0.5, origin=(-1.0, 2.0))
    assert m.shape == (4, 6)
    assert m.cell_of(-1.0, 2.0) == (0, 0)  # the origin is the south-west corner of (0, 0)
    assert m.cell_of(-0.5, 2.0) == (0, 1)  # a boundary belongs to the upper cell
    assert m.cell_of(1.99, 2.1) == (0, 5)
    assert m.cell_of(-0.9, 3.99) == (3, 0)
    assert m.cell_of(2.0, 2.0) is None and m.cell_of(0.0, 4.0) is None  # far edges
    assert m.cell_of(-1.01, 2.5) is None and m.cell_of(0.0, 1.99) is None
    assert m.cell_center(3, 0) == (-0.75, 3.75)
    m2 = CoverageMap.from_array(karte())
    m2.update(*m2.cell_center(3, 7))
    assert m2.codes[3, 7] == MOWER  # array[row = iy, col = ix]
    img = m2.rgb()  # north up: image row 0 is the northern row
    assert img.shape == (81, 71, 3) and tuple(img[81 - 1 - 3, 7]) == COLOUR["blue"]


def test_border_outside_is_reported_the_mower_stays_at_its_last_cell_inside():
    m = CoverageMap.from_array(karte())
    m.update(0.45, 1.05)  # cell (3, 1)
    codes = m.codes.copy()
    for x, y in ((-0.01, 1.0), (0.45, -5.0), (71 * 0.3, 1.0), (1.0, 81 * 0.3), (1e300, 1e300)):
        assert m.update(x, y, bumper=True) == UpdateResult(None, False, True, ())
        assert np.array_equal(m.codes, codes) and m.mower_cell == (3, 1)
    r = m.update(0.75, 1.05)  # back in: the last inside cell is the one left behind
    assert set(r.changed) == {(3, 2, MOWER), (3, 1, MOWED)}


def test_bumper_while_staying_in_a_cell_marks_it_an_obstacle():
    m = CoverageMap.from_array(karte())
    m.update(0.45, 0.45)
    r = m.update(0.5, 0.5, bumper=True)
    assert r == UpdateResult((1, 1), False, False, ((1, 1, OBSTACLE),))
    assert m.update(0.55, 0.55, bumper=True).changed == ()
    m.update(0.75, 0.45)
    assert m.codes[1, 1] == OBSTACLE


def test_first_update_in_unknown_and_bumper_in_unknown():
    m = CoverageMap.from_array(karte())
    assert m.update(0.1, 3.0) == UpdateResult((10, 0), True, False, ())
    r = m.update(0.1, 3.4, bumper=True)
    assert set(r.changed) == {(11, 0, OBSTACLE)}


# --- construction and bad arguments -------------------------------------------------------


def test_new_map_is_the_seeds_size_and_all_unknown():
    m = CoverageMap()
    assert m.shape == (81, 71) and m.cell_size == 0.3 and m.origin == (0.0, 0.0)
    assert not np.any(m.codes) and m.mower_cell is None
    with pytest.raises(ValueError):
        m.codes[0, 0] = 1  # read-only views
    with pytest.raises(ValueError):
        m.base[0, 0] = 1


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cell_size": 0.0}, "cell size must be a finite number of metres > 0"),
        ({"cell_size": -0.3}, "cell size must be a finite number of metres > 0"),
        ({"cell_size": math.nan}, "cell size must be a finite number of metres > 0"),
        ({"cell_size": math.inf}, "cell size must be a finite number of metres > 0"),
        ({"cell_size": "big"}, "cell size must be a number"),
        ({"shape": (0, 5)}, r"map shape \(ny, nx\) must be two integers > 0"),
        ({"shape": (5, -1)}, r"map shape \(ny, nx\) must be two integers > 0"),
        ({"shape": (2.5, 3)}, r"map shape \(ny, nx\) must be two integers > 0"),
        ({"shape": (True, 3)}, r"map shape \(ny, nx\) must be two integers > 0"),
        ({"shape": 5}, r"map shape must be \(ny, nx\)"),
        ({"origin": (math.nan, 0.0)}, "origin must be finite"),
        ({"origin": (0.0,)}, r"origin must be \(x0, y0\)"),
    ],
)
def test_bad_map_arguments_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CoverageMap(**kwargs)


@pytest.mark.parametrize(
    ("codes", "match"),
    [
        (np.full((3, 3), 4), r"unknown cell code\(s\) \[4\].*4 mower is runtime state"),
        (np.array([[0, 7], [9, 1]]), r"unknown cell code\(s\) \[7, 9\]"),
        (np.array([[0, -1]]), r"unknown cell code\(s\) \[-1\]"),
        (np.array([[0.5, 1.0]]), "whole numbers"),
        (np.zeros(5), "2-D"),
        (np.zeros((0, 3)), "non-empty"),
        (np.array([["a"]]), "whole numbers"),
    ],
)
def test_from_array_rejects_unknown_codes(codes, match):
    with pytest.raises(ValueError, match=match):
        CoverageMap.from_array(codes)


def test_from_array_copies_its_input():
    k = karte()
    m = CoverageMap.from_array(k.astype(float))
    k[:] = 0
    assert np.array_equal(m.base, karte()) and m.base.dtype == np.uint8


# --- from a measured perimeter polygon -----------------------------------------------------


def test_polygon_rectangle_gives_a_perimeter_ring_around_unmowed_cells():
    m = CoverageMap.from_polygon([(0.45, 0.45), (2.55, 0.45), (2.55, 1.65), (0.45, 1.65)])
    # floor(1.65/0.3) + 1 rows, floor(2.55/0.3) + 1 columns, + 1 margin each
    assert m.shape == (6 + 1, 9 + 1)
    want = np.zeros(m.shape, dtype=np.uint8)
    want[1:6, 1:9] = PERIMETER
    want[2:5, 2:8] = UNMOWED
    assert np.array_equal(m.codes, want)


def test_polygon_of_the_benchmark_lawn_fills_the_seed_map():
    m = CoverageMap.from_polygon(lawn_polygon(), shape=SEED_SHAPE)
    counts = np.bincount(m.codes.ravel(), minlength=6)
    assert counts[UNMOWED] > 3000 and counts[PERIMETER] > 200 and counts[UNKNOWN] > 500
    assert counts[MOWED] == counts[MOWER] == counts[OBSTACLE] == 0
    # the perimeter closes: no unmowed cell touches an unknown cell (4-neighbours)
    c = m.codes
    for a, b in ((c[1:], c[:-1]), (c[:, 1:], c[:, :-1])):
        assert not np.any((a == UNMOWED) & (b == UNKNOWN) | (a == UNKNOWN) & (b == UNMOWED))


def _inside_reference(poly, px, py) -> bool:
    inside = False
    for (ax, ay), (bx, by) in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        if (ay <= py) != (by <= py):
            xc = ax + (py - ay) * (bx - ax) / (by - ay)
            if xc < px:
                inside = not inside
    return inside


def _segment_touches_box(a, b, lo, hi, eps=1e-9) -> bool:
    """Liang-Barsky: does segment a-b meet the box [lo, hi] (grown by eps)?"""
    t0, t1 = 0.0, 1.0
    for k in (0, 1):
        d = b[k] - a[k]
        for p, q in ((-d, a[k] - (lo[k] - eps)), (d, (hi[k] + eps) - a[k])):
            if abs(p) < 1e-12:
                if q < 0:
                    return False
            else:
                t = q / p
                if p < 0:
                    t0 = max(t0, t)
                else:
                    t1 = min(t1, t)
    return t0 <= t1


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.floats(0.0, 2.9), st.floats(0.0, 2.9)),
        min_size=3,
        max_size=8,
    )
)
def test_polygon_raster_matches_a_brute_force_reference(pts):
    poly = np.array(pts)
    x, y = poly[:, 0], poly[:, 1]
    assume(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) > 1e-6)
    m = CoverageMap.from_polygon(poly, shape=(10, 10))
    s = 0.3
    for iy in range(10):
        for ix in range(10):
            lo, hi = (ix * s, iy * s), ((ix + 1) * s, (iy + 1) * s)
            on_edge = any(
                _segment_touches_box(a, b, lo, hi)
                for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True)
            )
            code = m.codes[iy, ix]
            if code == PERIMETER:
                assert on_edge, (iy, ix)
            elif on_edge:  # touches only within eps (a corner or an edge along a line)
                assert not any(
                    _segment_touches_box(a, b, lo, hi, eps=-1e-9)
                    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True)
                ), (iy, ix)
            if code != PERIMETER:
                want = UNMOWED if _inside_reference(poly, (ix + 0.5) * s, (iy + 0.5) * s) else 0
                assert code == want, (iy, ix)


@pytest.mark.parametrize(
    ("poly", "kwargs", "match"),
    [
        ([(0, 0), (1, 1)], {}, "at least 3 distinct vertices, got 2"),
        ([(0, 0), (1, 1), (0, 0)], {}, "at least 3 distinct vertices, got 2"),
        ([(0, 0), (1, math.nan), (1, 1)], {}, "finite metres"),
        ([(0, 0), (1, math.inf), (1, 1)], {}, "finite metres"),
        ([(0, 0), (1, 1), (2, 2)], {}, "zero area"),
        ([(0, 0, 0), (1, 0, 0), (1, 1, 0)], {}, r"\(N, 2\) array"),
        ([(0, 0), (1, 0), (1,)], {}, r"\(N, 2\) array"),
        ([(-0.1, 0), (1, 0), (1, 1)], {}, "west or south of the map origin"),
        ([(0, 0), (3, 0), (3, 3)], {"shape": (5, 5)}, r"needs at least \(11, 11\) cells"),
        ([(0, 0), (1, 0), (1, 1)], {"cell_size": 0}, "cell size must be"),
        ([(0, 0), (1, 0), (1, 1)], {"margin_cells": -1}, "margin_cells must be"),
    ],
)
def test_bad_polygons_raise(poly, kwargs, match):
    with pytest.raises(ValueError, match=match):
        CoverageMap.from_polygon(poly, **kwargs)


# --- files ---------------------------------------------------------------------------------


def _mowed_map() -> CoverageMap:
    m = CoverageMap.from_array(karte(), cell_size=0.25, origin=(1.0, -2.0))
    for x, y in mowing_path(m, 300)[150:]:
        m.update(x, y)
    m.update(*m.cell_center(30, 30), bumper=True)
    return m


@pytest.mark.parametrize("which", ["npz", "yaml"])
def test_save_and_load_round_trip_without_the_mower(tmp_path, which):
    m = _mowed_map()
    npz, side = m.save(tmp_path / "lawn.yaml")
    assert (npz.name, side.name) == ("lawn.npz", "lawn.yaml")
    meta = yaml.safe_load(side.read_text())
    assert meta["cell_size"] == 0.25 and meta["origin"] == [1.0, -2.0] and meta["shape"] == [81, 71]
    assert meta["colors_rgb8"]["obstacle"] == [255, 128, 255]
    m2 = CoverageMap.load(npz if which == "npz" else side)
    assert np.array_equal(m2.base, m.base) and m2.base.dtype == np.uint8
    assert m2.cell_size == 0.25 and m2.origin == (1.0, -2.0)
    assert m2.mower_cell is None and not np.any(m2.codes == MOWER)
    assert np.count_nonzero(m2.base == MOWED) > 100 and m2.base[30, 30] == OBSTACLE


def _bad_file(tmp_path, kind):
    good_npz, side = _mowed_map().save(tmp_path / "good")
    path = tmp_path / "bad.npz"
    if kind == "garbage":
        path.write_bytes(b"not a map at all")
    elif kind == "truncated":
        path.write_bytes(good_npz.read_bytes()[:200])
    elif kind == "npy":
        np.save(tmp_path / "bad.npy", karte())
        path = tmp_path / "bad.npy"
    elif kind == "missing_key":
        np.savez(path, format=np.array("mm_pc.core.maps.coverage_map"), codes=karte())
    elif kind == "other_format":
        np.savez(path, format="x", codes=karte(), cell_size=0.3, origin=[0.0, 0.0])
    elif kind in ("code_4", "code_9", "cell_size", "origin"):
        codes = karte()
        codes[3, 3] = {"code_4": 4, "code_9": 9}.get(kind, codes[3, 3])
        np.savez(
            path,
            format="mm_pc.core.maps.coverage_map",
            codes=codes,
            cell_size=-1.0 if kind == "cell_size" else 0.3,
            origin=[math.nan, 0.0] if kind == "origin" else [0.0, 0.0],
        )
    elif kind == "sidecar_mismatch":
        meta = yaml.safe_load(side.read_text())
        meta["cell_size"] = 0.5
        path = tmp_path / "good.yaml"
        path.write_text(yaml.safe_dump(meta))
    elif kind == "sidecar_garbage":
        path = tmp_path / "good.yaml"
        path.write_text("a: [unclosed")
    elif kind == "sidecar_path":
        meta = yaml.safe_load(side.read_text())
        meta["data"] = "../elsewhere.npz"
        path = tmp_path / "good.yaml"
        path.write_text(yaml.safe_dump(meta))
    return path


@pytest.mark.parametrize(
    ("kind", "match"),
    [
        ("garbage", "is not a readable coverage map"),
        ("truncated", "is not a readable coverage map"),
        ("npy", "not an .npz archive"),
        ("missing_key", r"missing entries \['cell_size', 'origin'\]"),
        ("other_format", "format is 'x'"),
        ("code_4", r"unknown cell code\(s\) \[4\]"),
        ("code_9", r"unknown cell code\(s\) \[9\]"),
        ("cell_size", "cell size must be a finite number of metres > 0"),
        ("origin", "origin must be finite"),
        ("sidecar_mismatch", "sidecar shape/cell_size/origin disagree"),
        ("sidecar_garbage", "not valid YAML"),
        ("sidecar_path", "'data' must name an .npz file next to the sidecar"),
    ],
)
def test_loading_a_bad_file_raises_a_clear_value_error(tmp_path, kind, match):
    path = _bad_file(tmp_path, kind)
    with pytest.raises(ValueError, match=match):
        CoverageMap.load(path)


def test_loading_a_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        CoverageMap.load(tmp_path / "nothing.npz")


def test_save_replaces_files_whole(tmp_path):
    m = _mowed_map()
    npz, _ = m.save(tmp_path / "lawn.npz")
    CoverageMap((2, 2)).save(tmp_path / "lawn")
    assert CoverageMap.load(npz).shape == (2, 2)
    assert zipfile.is_zipfile(npz)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lawn.npz", "lawn.yaml"]
