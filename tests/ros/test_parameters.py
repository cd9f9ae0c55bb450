"""mm_pc.ros.parameters: the descriptors every node builds its parameter table with."""

from __future__ import annotations

import pytest

pytest.importorskip("rcl_interfaces")

from mm_pc.ros.parameters import LIVE_NOTE, float_range, int_range, mark_live, ranged, read_only


def test_ranges_are_typed_after_the_default():
    d = ranged("polls per second", 1000.0, 10.0, 2000.0)
    assert d.read_only
    assert not d.integer_range
    r = d.floating_point_range[0]
    assert (r.from_value, r.to_value, r.step) == (10.0, 2000.0, 0.0)
    i = ranged("cpi", 1600, 50, 16000, 50).integer_range[0]
    assert (i.from_value, i.to_value, i.step) == (50, 16000, 50)
    assert type(i.from_value) is int
    for default, lo, hi in ((True, 0, 1), ("x", 0, 1), (1.0, None, 2.0), (1, 0, None)):
        plain = ranged("no range", default, lo, hi)
        assert not plain.integer_range and not plain.floating_point_range


def test_helpers_build_the_same_keywords_a_descriptor_takes():
    assert float_range(0.1, 60.0)["floating_point_range"][0].to_value == 60.0
    assert int_range(0, 15, 1)["integer_range"][0].step == 1
    d = read_only("seed", **int_range(0, 2**31))
    assert d.description == "seed" and d.integer_range[0].to_value == 2**31


def test_live_parameters_become_writable_and_say_so():
    table = {"rate": (15.0, read_only("Hz")), "beagle": ("mm_beagle", read_only("node"))}
    mark_live(table, ("rate",))
    assert not table["rate"][1].read_only
    assert table["rate"][1].description == "Hz" + LIVE_NOTE
    assert table["beagle"][1].read_only and table["beagle"][1].description == "node"
