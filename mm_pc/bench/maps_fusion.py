"""Fusion benchmark: how far raw mouse odometry drifts on the ~205 m mowing run, and the EKF.

One simulated run (:func:`mm_pc.sim.field_run.simulate_field_run`, seeded) is
replayed through :func:`mm_pc.sim.field_run.run_fusion` with the default inputs
(GPS, beacon ranges, compass, perimeter wire). Errors are plot-frame position
errors against the simulator's truth at every 20 Hz odometry request: the
final one ("drift") and the largest one over the run. Other input sets and
wheel odometry as the motion model are reported under ``variants`` for
comparison.

Throughput: predicts plus update records (applied or gated; one per beacon range) per
second of replay wall time, best of three replays, including building the records
(compass convention, lat/lon to metres) and FusionCore's ordering and wire lookup.
"""

from __future__ import annotations

import math
import time

from mm_pc.sim.field_run import ODOM_HZ, errors, run_fusion, simulate_field_run

__all__ = ["VARIANTS", "bench_fusion"]

#: (name, use, motion) of the comparison runs.
VARIANTS = (
    ("gps+compass+perimeter", ("gps", "compass", "perimeter"), "mouse"),
    ("gps+compass", ("gps", "compass"), "mouse"),
    ("compass", ("compass",), "mouse"),
    ("perimeter+compass", ("perimeter", "compass"), "mouse"),
    (
        "gps+trilateration+compass+perimeter",
        ("gps", "trilateration", "compass", "perimeter"),
        "mouse",
    ),
    ("wheels: gps+beacons+compass+perimeter", ("gps", "beacons", "compass", "perimeter"), "wheels"),
    ("wheels: gps+compass+perimeter", ("gps", "compass", "perimeter"), "wheels"),
)


def bench_fusion(seed: int = 1) -> dict:
    """Raw vs fused drift and EKF throughput on the simulated run, as one JSON-ready dict."""
    sim = simulate_field_run(seed)
    best = math.inf
    stats: dict = {}
    fused = None
    for _ in range(3):
        stats = {}
        t0 = time.perf_counter()
        fused = run_fusion(sim, stats=stats)
        best = min(best, time.perf_counter() - t0)
    ops = stats["predicts"] + stats.get("applied", 0) + stats.get("rejected", 0)
    raw_e, fused_e, wheel_e = errors(sim, sim.raw), errors(sim, fused), errors(sim, sim.raw_wheels)
    variants = {}
    for name, use, motion in VARIANTS:
        e = errors(sim, run_fusion(sim, use, motion))
        variants[name] = {"final_m": e["final_m"], "max_m": e["max_m"], "rms_m": e["rms_m"]}
    return {
        "raw_drift_m": raw_e["final_m"],
        "fused_drift_m": fused_e["final_m"],
        "raw_max_error_m": raw_e["max_m"],
        "fused_max_error_m": fused_e["max_m"],
        "run_length_m": sim.run_length_m,
        "fusion_updates_per_s": ops / best,
        "fused_rms_error_m": fused_e["rms_m"],
        "raw_wheel_drift_m": wheel_e["final_m"],
        "raw_wheel_max_error_m": wheel_e["max_m"],
        "variants": variants,
        "setup": {
            "seed": seed,
            "duration_s": float(sim.t[-1]),
            "odometry_hz": ODOM_HZ,
            "inputs": "gps, beacons (one range record per beacon), compass, perimeter",
            "counts": stats,
            "measurements": {
                "gps": len(sim.gps),
                "beacon_epochs": len(sim.ranges),
                "compass": len(sim.compass),
                "wire_contacts": len(sim.contacts),
            },
        },
    }
