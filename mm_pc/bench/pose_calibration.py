"""The full calibration pipeline, benchmarked: calibrate from a simulated noisy
guided run, then drive the 12 m mixed tour with the fitted calibration.

Behind the keys ``calibrated_tour_ratio_exact`` and
``calibrated_tour_ratio_two_sensor`` of ``mm-bench pose --json``: the tour's
final position error with the calibration fitted from the guided run
(:func:`mm_pc.core.calibration_fit.fit_mounts`) divided by the same tour with
the true mounts known, with the same count noise. The robot's sensors sit
a few degrees turned and over/under-count per axis (:data:`TRUE_MOUNTS`,
:data:`TRUE_GAINS`); counts are quantised at 1600 CPI with
:data:`mm_pc.bench.pose.NOISE_COUNTS` of noise per poll and axis. The ratio
is the RMS over :data:`SEEDS` seeds of each (one seed's ratio is noisy).
"""

from __future__ import annotations

import math

import numpy as np

from mm_pc.bench.pose import NOISE_COUNTS, NOISY_CPI
from mm_pc.core.calibration_fit import CalibrationStep, fit_mounts
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.odometry import Odometry
from mm_pc.sim import robot as sim

__all__ = ["GUIDED_RUN", "SEEDS", "TRUE_GAINS", "TRUE_MOUNTS", "bench_pose_calibration"]

DEVICES = ("/dev/spidev1.0", "/dev/spidev1.1")
#: The robot as built: positions 1-2 mm off the nominal ones, yaw +3 / -2 deg.
TRUE_MOUNTS = (
    SensorMount(0.0505, -0.0385, math.radians(3.0)),
    SensorMount(0.0480, 0.0400, math.radians(-2.0)),
)
#: Count gains (X, Y) per sensor: the sensors over/under-count by up to 3 %.
TRUE_GAINS = np.array([[1.02, 1.03], [0.98, 0.99]])
#: The simulated guided run (arguments of sim.guided_calibration_run).
GUIDED_RUN = {
    "speed": 0.2, "distance": 1.0, "spins": 2, "turn_rate": 1.0, "pause": 0.5, "straights": 2
}
#: The straights' measured length the simulated user enters (m).
MEASURED_DISTANCE = 1.0
SEEDS = tuple(range(20240603, 20240611))
REQUEST_HZ = 1000.0  # per poll: the calibration pipeline, not the request rate, is measured


def guided_steps(seed: int, run: dict | None = None) -> list[CalibrationStep]:
    """The recorded steps of one noisy guided run (raw counts in metres, per poll)."""
    run = dict(GUIDED_RUN if run is None else run)
    v, w = sim.guided_calibration_run(**run)
    r = sim.request_samples(
        v, w, TRUE_MOUNTS, REQUEST_HZ, cpi=NOISY_CPI, noise_counts=NOISE_COUNTS,
        rng=seed, gains=TRUE_GAINS,
    )
    return [CalibrationStep(k, r.d[a:b]) for k, a, b in sim.guided_calibration_steps(**run)]


def _tour_error(mounts, d: np.ndarray, dt: np.ndarray, truth: np.ndarray, method: str) -> float:
    poses = Odometry(mounts, method).integrate(dt, d)
    return float(math.hypot(*(poses[-1, :2] - truth[-1, :2])))


def bench_pose_calibration(
    seeds=SEEDS, run: dict | None = None, true_distance: float | None = MEASURED_DISTANCE
) -> dict:
    """Ratios (RMS over seeds) and the fitted parameters' errors; JSON-ready.

    ``true_distance``: the straights' measured length given to the fit (m;
    None: not measured, the fit keeps the mean Y scale at 1, and the tour's
    distances are off by the sensors' mean scale error).
    """
    v, w = sim.trajectory("mixed_tour")
    err = {m: {"fitted": [], "true": []} for m in ("exact", "two-sensor")}
    yaw_err, sx_err, sy_err, pos_err, drift_pred = [], [], [], [], []
    for seed in seeds:
        steps = guided_steps(seed, run)
        fit = fit_mounts(steps, DEVICES, DEFAULT_MOUNTS, true_distance=true_distance)
        cal = fit.calibration(date="")
        r = sim.request_samples(
            v, w, TRUE_MOUNTS, REQUEST_HZ, cpi=NOISY_CPI, noise_counts=NOISE_COUNTS,
            rng=seed + 1000, gains=TRUE_GAINS,
        )
        d_cal = np.empty_like(r.d)
        for i, dev in enumerate(DEVICES):
            d_cal[:, i, 0], d_cal[:, i, 1] = cal.apply(dev, r.d[:, i, 0], r.d[:, i, 1])
        d_true = r.d / TRUE_GAINS[None, :, :]
        cal_mounts = cal.mounts(DEVICES, DEFAULT_MOUNTS)
        for m in err:
            err[m]["fitted"].append(_tour_error(cal_mounts, d_cal, r.dt, r.truth, m))
            err[m]["true"].append(_tour_error(TRUE_MOUNTS, d_true, r.dt, r.truth, m))
        for s, tm, g in zip(fit.sensors, TRUE_MOUNTS, TRUE_GAINS, strict=True):
            yaw_err.append(math.degrees(s.angle_offset - tm.yaw))
            sx_err.append(s.scale_x * g[0] - 1)
            sy_err.append(s.scale_y * g[1] - 1)
            pos_err.append(math.hypot(s.x - tm.x, s.y - tm.y))
        drift_pred.append(fit.drift_per_m)

    def rms(a) -> float:
        return float(np.sqrt(np.mean(np.square(a))))

    out = {}
    for m, key in (("exact", "exact"), ("two-sensor", "two_sensor")):
        out[f"calibrated_tour_ratio_{key}"] = rms(err[m]["fitted"]) / rms(err[m]["true"])
        out[f"calibrated_tour_error_m_{key}"] = rms(err[m]["fitted"])
        out[f"true_mounts_tour_error_m_{key}"] = rms(err[m]["true"])
    out.update(
        {
            "calibration_yaw_error_deg_rms": rms(yaw_err),
            "calibration_scale_x_error_rms": rms(sx_err),
            "calibration_scale_y_error_rms": rms(sy_err),
            "calibration_position_error_m_rms": rms(pos_err),
            "calibration_predicted_drift_rad_per_m": {
                m: rms([p[m] for p in drift_pred]) for m in drift_pred[0]
            },
            "calibration_setup": (
                f"guided run {GUIDED_RUN if run is None else run} (straights forward and back, "
                "full spins each way), mounts yaw +3/-2 deg and 1-2 mm off, count gains "
                f"{TRUE_GAINS.tolist()}, {NOISY_CPI:g} CPI with {NOISE_COUNTS} counts/ms/axis "
                f"noise, per-poll integration; then mixed_tour; RMS over {len(seeds)} seeds; "
                f"measured distance: {true_distance}"
            ),
        }
    )
    return out
