"""mm-bench soak: agent + remote node + one 100 Hz client for minutes; is memory flat?

The whole board chain on this machine: an mm-beagle-agent on emulated sensors (the robot
moves for the run, then stands still), an mm-beagle in ``backend:=remote`` on its link and
one client process calling get_sensor_data at 100 Hz with its own read-and-clear cursor
(:func:`mm_pc.bench.cli._client`). Every ``sample_s`` seconds the RSS of the agent and of the
node (with its children) is sampled; the slope is a least-squares line (numpy.polyfit)
through the samples after the warm-up, in MB/min (1 MB = 2**20 bytes). "Flat" means
|slope| < :data:`FLAT_MB_PER_MIN` for both. Counts: what the client's last reply says the
totals are against what the emulators generated (the node's final /diagnostics), and the
sum of its read-and-clear replies against the same.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import platform
import time

import numpy as np
import psutil

from mm_beagle.tools.harness import (
    agent_process,
    beagle_process,
    free_port,
    use_isolated_ros_env,
)

FLAT_MB_PER_MIN = 0.05  # |RSS slope| after the warm-up below this: flat
WARMUP_S = 60.0  # samples before this are left out of the slope (runs shorter: the first third)
MB = float(1 << 20)


def tree_rss(proc: psutil.Process) -> int:
    """RSS of ``proc`` and its children (bytes; processes gone meanwhile count 0)."""
    total = 0
    for p in [proc, *proc.children(recursive=True)]:
        with contextlib.suppress(psutil.Error):
            total += p.memory_info().rss
    return total


def slope_mb_per_min(t_s: list[float], rss: list[int], warmup_s: float) -> float | None:
    """Least-squares slope of ``rss`` (bytes) over ``t_s`` (s) after ``warmup_s``, MB/min."""
    t, r = np.asarray(t_s), np.asarray(rss, dtype=float)
    keep = t >= warmup_s
    if keep.sum() < 2:
        return None
    return float(np.polyfit(t[keep] / 60.0, r[keep] / MB, 1)[0])


def bench_soak(minutes: float = 30.0, sample_s: float = 10.0, rate: float = 100.0) -> dict:
    """Run the soak for ``minutes`` and return its report (see the module docstring)."""
    from mm_pc.bench.cli import _client, _client_side

    seconds = minutes * 60.0
    warmup = WARMUP_S if seconds >= 3 * WARMUP_S else seconds / 3
    env = use_isolated_ros_env()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    agent_opts = {
        "backend": "sim",
        "sim_trajectory": "figure_eight",
        "sim_duration": seconds + 5.0,  # moving through the run (bring-up included), then still
        "listen": [endpoint],
    }
    ctx = mp.get_context("spawn")
    samples: list[tuple[float, int, int]] = []  # (s since start, agent RSS, node RSS)
    with (
        agent_process(agent_opts) as agent,
        beagle_process({"backend": "remote", "agent": endpoint}, env=dict(env)) as node,
        _client_side() as (client, procs),
    ):
        if not client.wait(60):
            raise RuntimeError("mm_beagle (backend remote) did not come up")
        a, b = ctx.Pipe()
        p = ctx.Process(target=_client, args=("mm_bench_soak", seconds, rate, "ack", b))
        p.start()
        procs.append(p)
        a.recv()  # ready
        pa, pn = psutil.Process(agent.pid), psutil.Process(node.pid)
        t0 = time.monotonic()
        a.send("go")
        while True:
            now = time.monotonic() - t0
            samples.append((now, tree_rss(pa), tree_rss(pn)))
            if a.poll(max(0.0, min(sample_s, seconds + 1.0 - now))) or now > seconds + 30:
                break
        a.recv()  # done
        time.sleep(max(0.0, 6.5 - (time.monotonic() - t0 - seconds)))  # the robot stands still
        a.send("final")
        result = a.recv()
        p.join(10)
        final = client.diagnostics(newer_than=time.monotonic())
        exits = {"agent": agent.poll(), "node": node.poll()}
    devices = sorted(final)
    generated = {
        d: (int(final[d]["sim_generated_x_counts"]), int(final[d]["sim_generated_y_counts"]))
        for d in devices
    }
    served = {d: tuple(result["totals"].get(d, (0, 0))) for d in devices}
    summed = {d: tuple(result["sums"].get(d, (0, 0))) for d in devices}

    def lost(got: dict) -> int:
        return sum(abs(generated[d][k] - got[d][k]) for d in devices for k in (0, 1))

    ts = [s[0] for s in samples]
    report: dict[str, object] = {"benchmark": "soak"}
    for k, name in ((1, "agent"), (2, "node")):
        rss = [s[k] for s in samples]
        slope = slope_mb_per_min(ts, rss, warmup)
        report[f"{name}_rss_mb_first"] = round(rss[0] / MB, 1)
        report[f"{name}_rss_mb_after_warmup"] = round(
            next((r for t, r in zip(ts, rss, strict=True) if t >= warmup), rss[-1]) / MB, 1
        )
        report[f"{name}_rss_mb_last"] = round(rss[-1] / MB, 1)
        report[f"{name}_rss_slope_mb_per_min"] = None if slope is None else round(slope, 4)
    slopes = [report["agent_rss_slope_mb_per_min"], report["node_rss_slope_mb_per_min"]]
    counts_lost = lost(served)
    report.update(
        {
            "flat_threshold_mb_per_min": FLAT_MB_PER_MIN,
            "flat": all(s is not None and abs(s) < FLAT_MB_PER_MIN for s in slopes),  # type: ignore[arg-type]
            "minutes": minutes,
            "warmup_s": round(warmup, 1),
            "sample_s": sample_s,
            "samples": len(samples),
            "client_rate_hz": rate,
            "counts_generated": sum(abs(v) for g in generated.values() for v in g),
            "counts_served": sum(abs(v) for s in served.values() for v in s),
            "counts_lost": counts_lost,
            "counts_lost_read_and_clear": lost(summed),
            "requests_failed": result["failures"],
            "replies_lost": result["replies_lost"],
            "exits_during_run": {k: v for k, v in exits.items() if v is not None},
            "rss_samples": [
                [round(t, 1), round(ra / MB, 2), round(rn / MB, 2)] for t, ra, rn in samples
            ],
            "machine": {
                "cpus": os.cpu_count(),
                "python": platform.python_version(),
                "load_avg_1min": round(os.getloadavg()[0], 2),
            },
        }
    )
    report["pass"] = bool(report["flat"]) and counts_lost == 0 and not report["exits_during_run"]
    return report
