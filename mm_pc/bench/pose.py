"""Pose benchmark behind ``mm-bench pose --json``: accuracy and speed of every method.

Every odometry method sees the same simulated runs (a ~10 m figure eight and
the ~20 m meander, each at 1 kHz and 15 Hz request rate, noise-free and
noisy). Noise-free = exact metres (no quantisation); noisy = counts quantised
at ``NOISY_CPI`` like the emulator plus Gaussian noise of ``NOISE_COUNTS``
counts per 1 ms poll and axis (seeded, so every method gets the same counts).
Errors are against the simulator's closed-form pose at each request.

Speed: ``update`` is the per-sample loop of the default method (prebuilt
``Sample`` objects), ``integrate`` the vectorised call on 1 M samples; best of
a few repeats, per method in ``speed_by_method``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import DEFAULT_METHOD, METHODS, Odometry, Sample
from mm_pc.sim import robot as sim

NOISY_CPI = 1600.0
NOISE_COUNTS = 0.2  # counts per 1 ms poll and axis, 1 sigma
SEED = 20240603
REQUEST_RATES = (1000.0, 15.0)
CAL_YAW_DEG = 5.0


def runs() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The benchmark paths: twist sequences at 1 kHz (v m/s, omega rad/s)."""
    return {
        "figure_eight_10m": sim.figure_eight(speed=0.2, radius=0.8),
        "meander_20m": sim.meander(speed=0.2),
    }


def _errors(poses: np.ndarray, truth: np.ndarray) -> tuple[float, float, float]:
    pos = np.hypot(poses[:, 0] - truth[:, 0], poses[:, 1] - truth[:, 1])
    final = float(pos[-1])
    heading = float(abs(poses[-1, 2] - truth[-1, 2]))
    rms = float(np.sqrt(np.mean(pos**2)))
    return final, heading, rms


def accuracy() -> list[dict]:
    """One row per (method, run, request rate, noise)."""
    rows = []
    for run_name, (v, w) in runs().items():
        for hz in REQUEST_RATES:
            for noisy in (False, True):
                kw = {"cpi": NOISY_CPI, "noise_counts": NOISE_COUNTS, "rng": SEED} if noisy else {}
                r = sim.request_samples(v, w, DEFAULT_MOUNTS, hz, **kw)
                for method in METHODS:
                    poses = Odometry(DEFAULT_MOUNTS, method).integrate(r.dt, r.d)
                    final, heading, rms = _errors(poses, r.truth)
                    rows.append(
                        {
                            "method": method,
                            "run": run_name,
                            "request_hz": hz,
                            "noise": noisy,
                            "final_error_m": final,
                            "heading_error_rad": heading,
                            "rms_error_m": rms,
                        }
                    )
    return rows


def calibration_error_deg() -> tuple[float | None, str]:
    """|recovered - 5 deg| for a simulated 1 m straight run (noisy counts), worst sensor."""
    try:
        from mm_pc.core.calibration import calibrate_straight_run
    except ImportError as e:  # pragma: no cover - calibration.py is written in parallel
        return None, f"mm_pc.core.calibration not available: {e}"
    v, w = sim.straight(speed=0.2, distance=1.0)
    mounts = sim.with_mount_yaw(DEFAULT_MOUNTS, math.radians(CAL_YAW_DEG))
    r = sim.request_samples(v, w, mounts, 15.0, cpi=NOISY_CPI, noise_counts=NOISE_COUNTS, rng=SEED)
    total = r.d.sum(axis=0)
    errs = [
        abs(math.degrees(calibrate_straight_run(x, y).angle_offset) - CAL_YAW_DEG) for x, y in total
    ]
    return max(errs), (
        f"1 m straight run at 0.2 m/s, both sensors mounted {CAL_YAW_DEG} deg off, counts at "
        f"{NOISY_CPI:g} CPI with {NOISE_COUNTS} counts/ms noise, 15 Hz requests; worst sensor"
    )


def two_sensor_noise_gain(seeds: int = 100) -> dict:
    """How much better ``two-sensor`` is than ``exact`` under noise, over ``seeds`` seeds.

    Per run: the RMS over seeds of the final position error of ``exact`` divided by
    that of ``two-sensor`` (the noisy setting of :func:`accuracy`, 15 Hz requests).
    ``theory``: the ratio of their heading noise per count, sqrt(sum of the squared
    yaw row of each method's counts -> (a, b, c) map), which is what dominates.
    """
    out: dict = {}
    for run_name, (v, w) in runs().items():
        sq = {"exact": 0.0, "two-sensor": 0.0}
        for seed in range(seeds):
            r = sim.request_samples(
                v, w, DEFAULT_MOUNTS, 15.0, cpi=NOISY_CPI, noise_counts=NOISE_COUNTS, rng=seed
            )
            for method in sq:
                p = Odometry(DEFAULT_MOUNTS, method).integrate(r.dt, r.d)[-1]
                sq[method] += float(np.hypot(*(p[:2] - r.truth[-1, :2]))) ** 2
        out[run_name] = math.sqrt(sq["exact"] / sq["two-sensor"])
    yaw = {m: Odometry(DEFAULT_MOUNTS, m).body_map()[2] for m in ("exact", "two-sensor")}
    out["theory"] = float(np.sqrt(np.sum(yaw["exact"] ** 2) / np.sum(yaw["two-sensor"] ** 2)))
    out["seeds"] = seeds
    return out


def _best_rate(fn, n: int, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n / best


def speed(method: str, n_update: int = 20_000, n_integrate: int = 1_000_000) -> dict:
    """Samples per second of the update loop and of integrate for ``method``."""
    v, w = sim.meander(speed=0.2)
    r = sim.request_samples(v, w, DEFAULT_MOUNTS, 1000.0)
    reps = -(-n_integrate // len(r.dt))
    d_big = np.tile(r.d, (reps, 1, 1))[:n_integrate]
    dt_big = np.full(n_integrate, sim.DT)
    samples = [Sample(sim.DT, tuple(map(tuple, r.d[i]))) for i in range(n_update)]
    odo = Odometry(DEFAULT_MOUNTS, method)

    def loop():
        odo.reset()
        for s in samples:
            odo.update(s)

    def vec():
        odo.reset()
        odo.integrate(dt_big, d_big)

    upd = _best_rate(loop, n_update, 3)
    integ = _best_rate(vec, n_integrate, 3)
    return {"update": upd, "integrate": integ, "ratio": integ / upd}


def bench_pose() -> dict:
    """The whole benchmark as one JSON-ready dict."""
    from mm_pc.bench.pose_calibration import bench_pose_calibration
    from mm_pc.bench.pose_polls import bench_polls_and_lifts

    cal, cal_note = calibration_error_deg()
    by_method = {m: speed(m) for m in METHODS}
    return {
        **bench_polls_and_lifts(),
        **bench_pose_calibration(),
        "runs": accuracy(),
        "two_sensor_noise_gain": two_sensor_noise_gain(),
        "calibration_error_deg": cal,
        "update_samples_per_s": by_method[DEFAULT_METHOD]["update"],
        "integrate_samples_per_s": by_method[DEFAULT_METHOD]["integrate"],
        "speed_by_method": by_method,
        "setup": {
            "mounts": [[m.x, m.y, m.yaw] for m in DEFAULT_MOUNTS],
            "run_length_m": {k: float(np.sum(v) * sim.DT) for k, (v, _) in runs().items()},
            "noisy": f"{NOISY_CPI:g} CPI quantisation + {NOISE_COUNTS} counts/ms/axis Gaussian",
            "calibration": cal_note,
        },
    }
