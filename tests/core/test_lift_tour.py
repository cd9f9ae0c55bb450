"""The issue-11 figures of mm-bench pose (mm_pc.bench.pose_polls) hold their goals.

Noise-free, counts whole at 1600 CPI per poll: deterministic, so the goals are asserted.
"""

from __future__ import annotations

import pytest

from mm_pc.bench.pose_polls import lift_tour_errors, per_poll_error


@pytest.fixture(scope="module")
def lifts():
    return lift_tour_errors()


def test_a_lifted_sensor_costs_exact_at_most_5_mm_with_window_filling(lifts):
    assert lifts["lift_tour_error_m_exact"] <= 0.005
    by = lifts["lift_tour_by_rule"]
    # the one-poll rule multiplied one poll's rounding by the gap length
    assert by["one_poll_fill"]["exact"] > 10 * lifts["lift_tour_error_m_exact"]
    assert by["no_fill"]["exact"] > 0.1
    assert by["no_lift"]["exact"] < 0.001


def test_two_sensor_never_diverges_with_the_lift_mask(lifts):
    assert lifts["lift_tour_error_m_two_sensor"] <= 0.01
    assert (
        lifts["lift_tour_error_m_two_sensor"]
        < lifts["lift_tour_by_rule"]["no_fill"]["two-sensor"] / 100
    )
    assert all(s > 0 for s in lifts["lift_tour_fill_sigma_m"])


def test_per_poll_integration_at_15_hz():
    r = per_poll_error()
    # the integration itself: far below 0.2 mm per 10 m once the counts are unbiased
    assert r["per_poll_15hz_error_m_per_10m_rounded_counts"] <= 0.0002
    assert r["per_poll_15hz_by_method"]["two-sensor"]["per_poll_m_per_10m"] <= 0.0002
    # exact with floored counts: half a count of dX bias over sy = 4.9 cm turns it
    assert 0.0005 < r["per_poll_15hz_error_m_per_10m"] < 0.002
