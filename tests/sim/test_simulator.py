"""The ground-truth simulator's new parts: the meander and per-request samples."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_pc.core.frames import m_to_counts
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.sim import robot as sim


def per_step(v, w, mounts=DEFAULT_MOUNTS):
    return np.stack(
        [np.stack(sim.sensor_displacements(v, w, sim.DT, m), axis=-1) for m in mounts], axis=1
    )


def test_meander_is_about_20_m_of_lanes_and_ends_on_the_far_side():
    v, w = sim.trajectory("meander")
    length = float(np.sum(v) * sim.DT)
    assert 19.5 < length < 20.5
    end = sim.integrate_pose(v, w, sim.DT)[-1]
    # 5 lanes of 3.4 m, 0.5 m apart, alternate U-turns: ends 3.4 m ahead, 2 m left, heading 0
    assert end == pytest.approx([3.4, 2.0, 0.0], abs=2e-3)
    assert set(np.unique(w).round(6)) == {-0.8, 0.0, 0.8}


def test_existing_api_is_unchanged():
    for name in ("still", "straight", "figure_eight", "square", "round_trip"):
        v, w = sim.trajectory(name)
        cx, cy = sim.cumulative_sensor_path(v, w, sim.DT, DEFAULT_MOUNTS[0])
        assert cx.shape == cy.shape == (v.size + 1,)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 5000), hz=st.floats(0.5, 2000.0))
def test_request_boundaries_cover_the_run(n, hz):
    ends = sim.request_boundaries(n, hz)
    assert ends[-1] == n
    assert np.all(np.diff(np.concatenate([[0], ends])) > 0)
    steps = 1000.0 / hz
    inner = np.diff(np.concatenate([[0], ends]))[:-1]
    assert np.all(inner <= math.ceil(steps) + 1)
    assert np.all(inner >= max(1, math.floor(steps) - 1))


def test_15_hz_intervals_are_66_or_67_polls():
    ends = sim.request_boundaries(10_000, 15.0)
    assert set(np.diff(ends[:-1]).tolist()) <= {66, 67}


def test_at_1_khz_the_samples_are_the_per_step_displacements():
    v, w = sim.trajectory("figure_eight")
    r = sim.request_samples(v, w, DEFAULT_MOUNTS, 1000.0)
    assert np.allclose(r.d, per_step(v, w), atol=1e-15)
    assert np.allclose(r.dt, sim.DT)
    assert np.array_equal(r.truth, sim.integrate_pose(v, w, sim.DT))


@settings(max_examples=40, deadline=None)
@given(hz=st.floats(1.0, 1000.0), name=st.sampled_from(["figure_eight", "square", "meander"]))
def test_counts_are_conserved_at_any_request_rate(hz, name):
    v, w = sim.trajectory(name)
    r = sim.request_samples(v, w, DEFAULT_MOUNTS, hz)
    total = per_step(v, w).sum(axis=0)
    assert np.allclose(r.d.sum(axis=0), total, atol=1e-9)
    assert r.dt.sum() == pytest.approx(v.size * sim.DT)
    assert np.array_equal(r.truth, sim.integrate_pose(v, w, sim.DT)[r.end_step - 1])


def test_cpi_quantisation_reports_whole_counts_and_never_loses_one():
    v, w = sim.trajectory("figure_eight")
    cpi = 800.0
    r = sim.request_samples(v, w, DEFAULT_MOUNTS, 15.0, cpi=cpi)
    counts = m_to_counts(r.d, cpi)
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    exact_cum = m_to_counts(np.cumsum(per_step(v, w), axis=0)[r.end_step - 1], cpi)
    got_cum = np.cumsum(np.round(counts), axis=0)
    assert np.all((exact_cum - got_cum >= -1e-6) & (exact_cum - got_cum < 1 + 1e-6))


def test_noise_is_in_counts_reproducible_and_needs_a_cpi():
    v, w = sim.trajectory("straight")
    a = sim.request_samples(v, w, cpi=1600, noise_counts=0.5, rng=7)
    b = sim.request_samples(v, w, cpi=1600, noise_counts=0.5, rng=7)
    clean = sim.request_samples(v, w, cpi=1600)
    assert np.array_equal(a.d, b.d)
    diff = m_to_counts(a.d - clean.d, 1600).sum(axis=0)  # random walk, sigma 0.5*sqrt(n)
    assert np.all(np.abs(diff) < 6 * 0.5 * math.sqrt(v.size))
    assert np.any(diff != 0)
    with pytest.raises(ValueError, match="needs a cpi"):
        sim.request_samples(v, w, noise_counts=0.5)
    with pytest.raises(ValueError, match="noise_counts must be >= 0"):
        sim.request_samples(v, w, cpi=1600, noise_counts=-1.0)


def test_lifts_drop_the_counts_of_lifted_milliseconds():
    v, w = sim.trajectory("straight")
    mask = sim.lift_mask(v.size, [(1.0, 0.25), (3.0, 0.1)])
    assert mask.sum() == 350
    r = sim.request_samples(v, w, DEFAULT_MOUNTS, 100.0, lifted=mask)
    clean = sim.request_samples(v, w, DEFAULT_MOUNTS, 100.0)
    lost = clean.d.sum(axis=0) - r.d.sum(axis=0)
    assert lost[:, 1] == pytest.approx([0.35 * 0.2, 0.35 * 0.2])
    assert r.lifted_steps.sum(axis=0).tolist() == [350, 350]
    # one sensor only
    per_sensor = np.stack([mask, np.zeros_like(mask)], axis=1)
    r1 = sim.request_samples(v, w, DEFAULT_MOUNTS, 100.0, lifted=per_sensor)
    assert r1.lifted_steps.sum(axis=0).tolist() == [350, 0]
    assert np.allclose(r1.d[:, 1], clean.d[:, 1])
    with pytest.raises(ValueError, match="lifted must have shape"):
        sim.request_samples(v, w, DEFAULT_MOUNTS, 100.0, lifted=mask[:-1])
    with pytest.raises(ValueError, match="a lift needs"):
        sim.lift_mask(10, [(-1.0, 0.1)])


def test_mounting_error_turns_the_reported_vector_by_minus_yaw():
    v, w = sim.trajectory("straight")
    yaw = math.radians(5.0)
    mounts = sim.with_mount_yaw(DEFAULT_MOUNTS, yaw)
    r = sim.request_samples(v, w, mounts, 15.0)
    total = r.d.sum(axis=0)[0]
    # straight ahead ideally reads (0, 1 m); a sensor turned +5 deg reads it turned -5 deg
    assert total == pytest.approx([math.sin(yaw) * 1.0, math.cos(yaw) * 1.0])
    assert sim.with_mount_yaw(DEFAULT_MOUNTS, [0.1, 0.2])[1].yaw == 0.2
    with pytest.raises(ValueError, match="2 mount"):
        sim.with_mount_yaw(DEFAULT_MOUNTS, [0.1])


def test_bad_arguments():
    v, w = sim.trajectory("straight")
    for hz in (0.0, -5.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="request rate"):
            sim.request_samples(v, w, request_hz=hz)
    with pytest.raises(ValueError, match="equal length"):
        sim.request_samples(v, w[:-1])
    with pytest.raises(ValueError, match="cpi must be > 0"):
        sim.request_samples(v, w, cpi=0.0)


def test_a_single_sensor_and_an_odd_mount_work():
    v, w = sim.trajectory("square")
    m = (SensorMount(-0.1, 0.03, 0.2),)
    r = sim.request_samples(v, w, m, 30.0, cpi=3200, noise_counts=0.1, rng=1)
    assert r.d.shape == (r.dt.size, 1, 2)
