"""``mm-bench maps``: the maps and position fixes of the seeds 001, 003 and 004, measured.

One JSON object merging three parts (each also usable alone):

* :func:`mm_pc.bench.maps_grid.bench_grid` -- coverage grid update (µs, p50/p99 on the seed's
  81x71 map and on 1000x1000) and init (ms);
* :func:`mm_pc.bench.maps_trilateration.bench_trilateration` -- fixes/s and RMS error vs range
  noise, least squares and the seed's method;
* :func:`mm_pc.bench.maps_fusion.bench_fusion` -- raw mouse-odometry drift vs the fused (EKF)
  estimate after a simulated ~200 m mowing run.

Pure math: no ROS, no Qt. Timings are wall-clock on a shared machine; compare within one run.
"""

from __future__ import annotations

import platform
import time

__all__ = ["bench_maps"]


def bench_maps(seconds_budget: float = 2.0, seed: int = 1) -> dict:
    """Run the three parts and merge their keys (plus host facts and the wall time)."""
    from mm_pc.bench.maps_fusion import bench_fusion
    from mm_pc.bench.maps_grid import bench_grid
    from mm_pc.bench.maps_trilateration import bench_trilateration

    t0 = time.perf_counter()
    result: dict = {}
    result.update(bench_grid(seconds_budget))
    result.update(bench_trilateration(seconds_budget))
    result.update(bench_fusion(seed))
    result["host"] = {"machine": platform.machine(), "python": platform.python_version()}
    result["bench_seconds"] = round(time.perf_counter() - t0, 2)
    return result
