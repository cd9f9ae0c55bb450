"""The whole-mount calibration fit (mm_pc.core.calibration_fit) on simulated guided runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mm_pc.core.calibration_fit import (
    CalibrationRefusedError,
    CalibrationStep,
    check_step,
    fit_advice,
    fit_mounts,
)
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.odometry import Odometry
from mm_pc.sim import robot as sim

DEV = ("/dev/spidev1.0", "/dev/spidev1.1")
BUILT = (
    SensorMount(0.0505, -0.0385, math.radians(3.0)),
    SensorMount(0.0480, 0.0400, math.radians(-2.0)),
)


def guided(gains=None, noise=0.0, seed=1, **run):
    v, w = sim.guided_calibration_run(**run)
    r = sim.request_samples(
        v, w, BUILT, 1000.0, cpi=1600, noise_counts=noise, rng=seed, gains=gains
    )
    return [CalibrationStep(k, r.d[a:b]) for k, a, b in sim.guided_calibration_steps(**run)]


def test_recovers_yaw_scales_and_positions_from_a_quantised_run():
    gains = np.array([[1.03, 1.03], [0.98, 0.98]])  # isotropic: the yaw is observable
    fit = fit_mounts(guided(gains), DEV, DEFAULT_MOUNTS, true_distance=0.5)
    for c, m, g in zip(fit.sensors, BUILT, gains, strict=True):
        assert c.angle_offset == pytest.approx(m.yaw, abs=math.radians(0.01))
        assert c.scale_y * g[1] == pytest.approx(1.0, abs=2e-4)
        assert c.scale_x * g[0] == pytest.approx(1.0, abs=2e-3)
        assert (c.x, c.y) == (pytest.approx(m.x, abs=2e-4), pytest.approx(m.y, abs=2e-4))
        # the yaw shares the X-scale/forward-offset gauge (the anisotropy prior): wider
        assert 0 < c.angle_offset_se < math.radians(0.1)
    assert fit.spin_angles == pytest.approx([2 * math.pi, -2 * math.pi] * 2, abs=1e-3)
    assert fit.straight_lengths == pytest.approx([0.5, -0.5], abs=1e-3)
    # the seed's formula on the same straights, next to the fit
    for dev, m in zip(DEV, BUILT, strict=True):
        assert fit.straight_run[dev].angle_offset == pytest.approx(m.yaw, abs=math.radians(0.01))
    # with the calibration in force a straight drives straight (both methods)
    cal = fit.calibration()
    v, w = sim.straight(distance=2.0)
    r = sim.request_samples(v, w, BUILT, 1000.0, cpi=1600, gains=gains)
    d = np.stack([np.stack(cal.apply(dev, r.d[:, i, 0], r.d[:, i, 1]), -1)
                  for i, dev in enumerate(DEV)], axis=1)
    for method in ("exact", "two-sensor"):
        pose = Odometry(cal.mounts(DEV, DEFAULT_MOUNTS), method).integrate(r.dt, d)[-1]
        assert pose[0] == pytest.approx(2.0, abs=2e-3) and abs(pose[2]) < 1e-3, method


def test_predicted_drift_matches_the_drift_of_noisy_calibrations():
    """Over seeds, the heading drift per metre that exact keeps on a straight has the
    RMS the fit predicts (within a factor 2), and two-sensor's too."""
    v, w = sim.straight(distance=1.0)
    actual = {"exact": [], "two-sensor": []}
    predicted = {"exact": [], "two-sensor": []}
    for seed in range(8):
        fit = fit_mounts(guided(noise=0.2, seed=seed), DEV, DEFAULT_MOUNTS, true_distance=0.5)
        cal = fit.calibration()
        r = sim.request_samples(v, w, BUILT, 1000.0)  # exact counts: only the calibration errs
        d = np.stack([np.stack(cal.apply(dev, r.d[:, i, 0], r.d[:, i, 1]), -1)
                      for i, dev in enumerate(DEV)], axis=1)
        for m in actual:
            yaw = Odometry(cal.mounts(DEV, DEFAULT_MOUNTS), m).integrate(r.dt, d)[-1, 2]
            actual[m].append(yaw)
            predicted[m].append(fit.drift_per_m[m])
    for m in actual:
        rms_actual = math.sqrt(np.mean(np.square(actual[m])))
        ratio = rms_actual / math.sqrt(np.mean(np.square(predicted[m])))
        assert 0.5 < ratio < 2.0, (m, ratio)


def test_refuses_a_spin_too_small_or_far_from_the_entered_angle():
    steps = guided(spins=1, turn_rate=1.0)
    quarter = CalibrationStep("spin", steps[2].d[: steps[2].d.shape[0] // 5])
    msg = check_step(quarter, DEFAULT_MOUNTS).message
    assert msg.startswith("spin too small: about 72 deg, at least 90 deg needed")
    with pytest.raises(CalibrationRefusedError, match=r"step 3 \(spin\): spin too small"):
        fit_mounts([*steps[:2], quarter], DEV, DEFAULT_MOUNTS)
    with pytest.raises(CalibrationRefusedError, match="but each spin must turn 720 deg"):
        fit_mounts(steps, DEV, DEFAULT_MOUNTS, spin_angle=4 * math.pi)


def test_refuses_sideways_motion_a_missing_step_and_a_far_scale():
    steps = guided(spins=1)
    # the back run pushed 2 deg sideways: the straights disagree in direction
    d = steps[1].d.copy()
    d[:, :, 0] += 0.035 * d[:, :, 1]
    sideways = [steps[0], CalibrationStep("straight", d), *steps[2:]]
    apart = r"steps 1 and 2 \(straights\): /dev/spidev1.0 went 2.00 deg apart .* moved sideways"
    with pytest.raises(CalibrationRefusedError, match=apart):
        fit_mounts(sideways, DEV, DEFAULT_MOUNTS)
    with pytest.raises(CalibrationRefusedError, match="needs at least one straight and one spin"):
        fit_mounts(steps[:2], DEV, DEFAULT_MOUNTS)
    with pytest.raises(CalibrationRefusedError, match=r"scale 0\.10 is far from 1"):
        fit_mounts(steps, DEV, DEFAULT_MOUNTS, true_distance=0.05)
    with pytest.raises(ValueError, match="step kind must be one of"):
        CalibrationStep("hop", np.zeros((1, 2, 2)))
    with pytest.raises(ValueError, match="spin angle must be a finite number"):
        fit_mounts(steps, DEV, DEFAULT_MOUNTS, spin_angle=math.nan)


@pytest.mark.parametrize("off", [(1 / 1.1, 1.0), (1 / 1.1, 1 / 1.1), (1.1, 1.1)])
def test_optical_flow_height_error_is_recovered_with_the_measured_distance(off):
    """A PMW3901 whose effective CPI is 10 % off (mounted 10 % higher or lower than the
    driver's height_m: counts scale with 1/height, both axes alike) at its own 104 CPI: with
    the straights' measured length the fit's per-axis scales undo it within their stated
    accuracy (docs/pose-math.md, "Optical-flow sensors")."""
    from pln2033 import INCH_M

    gains = np.array([[g, g] for g in off])
    steps = guided_at(gains, cpi=104)
    fit = fit_mounts(steps, DEV, DEFAULT_MOUNTS, true_distance=0.5, resolution_m=INCH_M / 104)
    for c, g in zip(fit.sensors, gains, strict=True):
        assert abs(c.scale_y * g[1] - 1.0) < min(2 * c.scale_y_se, 1e-3)
        assert abs(c.scale_x * g[0] - 1.0) < min(2 * c.scale_x_se, 5e-3)
    # without the measured length the mean Y scale is fixed at 1: a height error shared by
    # both sensors is not seen; only one sensor's error relative to the other is
    fit = fit_mounts(steps, DEV, DEFAULT_MOUNTS, resolution_m=INCH_M / 104)
    corrected = [c.scale_y * g[1] for c, g in zip(fit.sensors, gains, strict=True)]
    assert corrected[0] / corrected[1] == pytest.approx(1.0, abs=1e-3)
    # (the fit's mean Y scale is 1, so what is left is 1 / mean(1 / gain) on each)
    assert corrected == pytest.approx([1 / np.mean(1 / gains[:, 1])] * 2, rel=2e-3)


def guided_at(gains, cpi):
    """:func:`guided` at another resolution (the optical-flow chips' effective CPI)."""
    v, w = sim.guided_calibration_run()
    r = sim.request_samples(v, w, BUILT, 1000.0, cpi=cpi, rng=1, gains=gains)
    return [CalibrationStep(k, r.d[a:b]) for k, a, b in sim.guided_calibration_steps()]


def test_without_a_distance_the_spins_and_the_configured_mounts_give_the_scale():
    """Both sensors count 3 % long on both axes, no length measured: the CPI as the scale
    keeps the 3 %; the spins' known angle against the configured mount radii (1-2 mm off
    the built ones, 0.08 % on the mean radius) remove it, and the advice says by how much."""
    gains = np.array([[1.03, 1.03], [1.03, 1.03]])
    steps = guided(gains, distance=0.5, spins=1)
    by_cpi = fit_mounts(steps, DEV, DEFAULT_MOUNTS)
    by_mounts = fit_mounts(steps, DEV, DEFAULT_MOUNTS, scale_reference="mounts")
    assert by_cpi.scale_reference == "sensors" and by_mounts.scale_reference == "mounts"
    for c in by_cpi.sensors:
        assert c.scale_y * 1.03 == pytest.approx(1.03, abs=2e-3)
    for c, m in zip(by_mounts.sensors, BUILT, strict=True):
        assert c.scale_y * 1.03 == pytest.approx(1.0, abs=3e-3)
        assert math.hypot(c.x, c.y) == pytest.approx(math.hypot(m.x, m.y), abs=1.5e-3)
    assert 1 / by_cpi.mounts_scale == pytest.approx(1.03, abs=3e-3)
    assert by_mounts.mounts_scale == pytest.approx(1.0, abs=1e-6)
    # 1 mm per coordinate on a 62.9 mm radius, two sensors: 1.1 %
    assert by_cpi.mounts_scale_se == pytest.approx(0.001 / 0.0629 / math.sqrt(2), rel=0.02)
    advice = fit_advice(by_cpi, "two-sensor")
    assert "the sensors' CPI" in advice and "distances read 3.0 % long (±1.1 %" in advice
    assert "measure one straight" in advice
    assert "configured mount positions (±1.1 %" in fit_advice(by_mounts, "exact")
    measured = fit_mounts(steps, DEV, DEFAULT_MOUNTS, true_distance=0.5)
    assert measured.scale_reference == "distance"
    assert "No length was measured" not in fit_advice(measured, "exact")
    with pytest.raises(ValueError, match="scale reference must be one of"):
        fit_mounts(steps, DEV, DEFAULT_MOUNTS, scale_reference="wheels")


def test_the_drift_falls_with_the_square_root_of_the_straights_and_the_advice_says_so():
    """Count noise is a random walk: straights four times as long halve the heading drift
    the calibration leaves (measured against the truth over 12 noisy runs; 40 runs gave
    1.7x and 1.8x for 0.5 -> 2 m and 1 -> 4 m), and the advice asks for them."""
    gains = np.array([[1.02, 1.03], [0.98, 0.99]])

    def drift(distance: float) -> tuple[float, str]:
        errs, advice = [], ""
        for seed in range(12):
            fit = fit_mounts(guided(gains, 0.2, seed, distance=distance, spins=1), DEV,
                             DEFAULT_MOUNTS, true_distance=distance)
            cal = fit.calibration()
            m, g = BUILT[0], gains[0]
            x, _ = cal.apply(DEV[0], np.array([g[0] * math.sin(m.yaw)]),
                             np.array([g[1] * math.cos(m.yaw)]))
            errs.append(float(x[0]) / cal[DEV[0]].x)  # exact's heading per metre
            advice = advice or fit_advice(fit, "exact")
        return float(np.sqrt(np.mean(np.square(errs)))), advice

    short, advice = drift(0.5)
    long, _ = drift(2.0)
    assert 1.3 < short / long < 3.0, (short, long)
    assert "Your straights total 1.0 m" in advice
    assert "record straights of 2.0 m (four times as long) to halve it" in advice
