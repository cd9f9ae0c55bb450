"""A whole simulated mowing run leaves the plot mowed (issue 29 finding 13): the sim map is
fed with the mower's cutting deck (model.maps.SIM_CUT_WIDTH, as wide as the lanes are
apart), not its centre alone (then 71 % of the lawn stayed "unmowed").
"""

from __future__ import annotations

import numpy as np
import pytest

from mm_pc.core.maps.coverage_map import MOWED, MOWER, UNMOWED, CoverageMap
from mm_pc.monitor.model import maps as mm
from mm_pc.sim.field_run import LANE_SPACING


def test_the_deck_is_as_wide_as_the_lanes_are_apart():
    assert mm.SIM_CUT_WIDTH == LANE_SPACING


def test_a_whole_run_fed_in_pieces_leaves_under_5_percent_unmowed():
    run = mm.build_sim_run(1)
    truth = run.sim.truth
    cmap = mm.sim_map(run)
    lawn = np.count_nonzero(cmap.codes == UNMOWED)
    lo, result = 0, None
    for hi in range(97, len(truth), 97):  # as the view plays it: a piece per tick
        mm.feed_positions(cmap, truth[lo : hi + 1, 0], truth[lo : hi + 1, 1], mm.SIM_CUT_WIDTH)
        lo = hi
    _changed, result = mm.feed_positions(cmap, truth[lo:, 0], truth[lo:, 1], mm.SIM_CUT_WIDTH)
    left = np.count_nonzero(cmap.codes == UNMOWED)
    assert left / lawn < 0.05, (left, lawn)
    # the mower where the run ends (the deck's centre), not at the deck's edge
    assert result.cell == cmap.mower_cell == cmap.cell_of(truth[-1, 0], truth[-1, 1])
    centre_only = mm.sim_map(run)
    mm.feed_positions(centre_only, truth[:, 0], truth[:, 1])
    assert np.count_nonzero(centre_only.codes == UNMOWED) / lawn > 0.6  # what it was


def test_a_deck_mows_the_cells_across_the_travel_and_shows_the_mower_at_its_centre():
    cmap = CoverageMap.from_array(np.full((20, 20), UNMOWED, dtype=np.uint8), 0.3)
    y = np.full(11, 3.15)  # the centre of row 10, driving east along it
    x = np.linspace(1.05, 4.05, 11)
    changed, result = mm.feed_positions(cmap, x, y, 0.8)
    codes = cmap.codes
    assert result.cell == (10, 13)  # floor(3.15 / 0.3), floor(4.05 / 0.3)
    assert codes[10, 13] == MOWER and (10, 13, MOWER) in changed[-2:]
    # the deck reaches 0.4 m to each side: rows 9..11 (y 2.75..3.55 m)
    assert np.all(codes[9:12, 3:13] == MOWED)
    assert np.all(codes[:9] == UNMOWED) and np.all(codes[12:] == UNMOWED)
    assert changed and all(c in (MOWED, MOWER) for *_cell, c in changed)


def test_no_width_feeds_the_centre_only_as_before():
    cmap = CoverageMap.from_array(np.full((20, 20), UNMOWED, dtype=np.uint8), 0.3)
    mm.feed_positions(cmap, np.linspace(1.05, 4.05, 11), np.full(11, 3.15))
    assert np.count_nonzero(cmap.codes == MOWED) == 10
    assert np.all(cmap.codes[9] == UNMOWED) and np.all(cmap.codes[11] == UNMOWED)


@pytest.mark.parametrize("width", [0.0, -1.0, float("nan")])
def test_no_deck_for_zero_negative_or_nan_width(width):
    assert mm._deck_offsets(width, 0.3).size == 0
