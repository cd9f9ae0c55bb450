"""Per-poll vs per-request pose at a request rate: the figures of docs/pose-math.md,
section "Per-poll integration".

    python -m mm_pc.bench.per_poll [--path s_curves] [--hz 15] [--json]
    python -m mm_pc.bench.per_poll --session-cost     # the monitor session's time per reply

The run's 1 kHz polls (default robot, method ``exact``) are requested at ``hz``:
*per request* integrates each request's summed counts as one constant twist (the
old pose); *per poll* turns the same replies into single polls with
:class:`mm_pc.core.polls.PollTracker` and integrates each poll (the new pose).
Both against the simulator's exact pose at the end of the run, twice: in exact
metres (no quantisation: the integration error alone) and quantised at 1600 CPI
like the emulator (floor of the cumulative counts). Errors are also given per 10 m
travelled. :func:`per_poll_errors` returns the dict (``mm-bench pose`` may embed it).

``--session-cost``: :func:`session_cost`, the time ``MonitorSession.process`` takes per
reply with and without the single polls (30 s of s_curves at 1600 CPI, best of 3), and at
500 Hz ``process_batch`` in the bridge's batches.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.core.polls import PollBatch, PollSteps, PollTracker, SensorTotals
from mm_pc.sim import robot as sim
from pln2033 import INCH_M

__all__ = ["per_poll_errors", "session_cost"]

CPI = 1600


def _counts(v, w, mounts, cpi: float | None) -> np.ndarray:
    """Per-poll displacements (n, k, 2): metres (cpi None) or whole counts (floor)."""
    step = np.stack([np.stack(sim.sensor_displacements(v, w, sim.DT, m), -1) for m in mounts], 1)
    if cpi is None:
        return step
    cum = np.floor(np.cumsum(step * (cpi / INCH_M), axis=0))
    return np.diff(np.concatenate([np.zeros((1, *cum.shape[1:])), cum]), axis=0)


def _through_tracker(counts: np.ndarray, ends: np.ndarray, cpi: int) -> PollSteps:
    """The replies a client at the boundaries ``ends`` gets, through the poll tracker."""
    n, k, _ = counts.shape
    c = counts.astype(np.int64)
    cum = np.concatenate([np.zeros((1, k, 2), np.int64), np.cumsum(c, axis=0)])
    scale = INCH_M / cpi
    stamps = (np.arange(n, dtype=np.int64) + 1) * 1_000_000

    def totals(j: int) -> list[SensorTotals]:
        return [SensorTotals(j, j * 1_000_000, int(cum[j, i, 0]), int(cum[j, i, 1]),
                             float(cum[j, i, 0]) * scale, float(cum[j, i, 1]) * scale)
                for i in range(k)]  # fmt: skip

    tr = PollTracker(k)
    tr.baseline(totals(0))
    parts, prev = [], 0
    for e in ends:
        batches = [
            PollBatch(prev, int(e), 0, cpi, stamps[prev:e], c[prev:e, i, 0], c[prev:e, i, 1],
                      np.full(e - prev, 2))
            for i in range(k)
        ]  # fmt: skip
        parts.append(tr.step(totals(int(e)), batches))
        prev = int(e)
    return PollSteps.concat(parts, k)


def per_poll_errors(path: str = "s_curves", request_hz: float = 15.0) -> dict:
    """Final position error (m) of per-poll and per-request integration at ``request_hz``."""
    v, w = sim.trajectory(path)
    mounts = DEFAULT_MOUNTS
    truth = sim.integrate_pose(v, w, sim.DT)[-1]
    length = float(np.sum(np.abs(v)) * sim.DT)
    ends = sim.request_boundaries(len(v), request_hz)
    starts = np.concatenate([[0], ends[:-1]])
    out: dict = {"path": path, "length_m": length, "request_hz": request_hz, "cpi": CPI}
    for label, cpi in (("exact_m", None), (f"{CPI}cpi", CPI)):
        d = _counts(v, w, mounts, cpi)
        scale = 1.0 if cpi is None else INCH_M / cpi
        cum = np.concatenate([np.zeros((1, *d.shape[1:])), np.cumsum(d, axis=0)])
        per_request = Odometry(mounts)
        per_request.integrate((ends - starts) * sim.DT, (cum[ends] - cum[starts]) * scale)
        if cpi is None:
            per_poll = Odometry(mounts)
            per_poll.integrate(sim.DT, d)
        else:
            steps = _through_tracker(d, ends, cpi)
            assert len(steps) == len(v) and not steps.gap.any()
            per_poll = Odometry(mounts)
            per_poll.integrate(steps.dt, steps.d)
        for name, odo in (("per_poll", per_poll), ("per_request", per_request)):
            p = odo.pose.as_array()
            err = float(math.hypot(p[0] - truth[0], p[1] - truth[1]))
            out[f"{name}_error_m_{label}"] = err
            out[f"{name}_error_m_per_10m_{label}"] = err * 10.0 / length
    return out


def _replies(counts: np.ndarray, ends: np.ndarray, cpi: int, devices) -> list:
    """Monitor replies (Reading totals + the polls since the previous reply) at ``ends``."""
    from types import SimpleNamespace

    from mm_pc.core.sensor_data import Reading, Reply

    n, k, _ = counts.shape
    c = counts.astype(np.int64)
    cum = np.concatenate([np.zeros((1, k, 2), np.int64), np.cumsum(c, axis=0)])
    scale = INCH_M / cpi
    stamps = (np.arange(n + 1, dtype=np.int64)) * 1_000_000 + 1_700_000_000_000_000_000
    out, prev = [], 0
    for e in (0, *(int(x) for x in ends)):
        readings = tuple(
            Reading(id=d, stamp_ns=int(stamps[e]), seq=e, x_total=float(cum[e, i, 0]) * scale,
                    y_total=float(cum[e, i, 1]) * scale, x_total_counts=int(cum[e, i, 0]),
                    y_total_counts=int(cum[e, i, 1]), cpi=cpi)
            for i, d in enumerate(devices)
        )  # fmt: skip
        polls = {
            d: SimpleNamespace(first_seq=prev, next_seq=e, dropped=0, cpi=cpi,
                               stamp_ns=stamps[prev + 1 : e + 1], dx=c[prev:e, i, 0],
                               dy=c[prev:e, i, 1], status=np.zeros(e - prev),
                               flags=np.full(e - prev, 2))
            for i, d in enumerate(devices)
        }  # fmt: skip
        out.append(Reply(readings, polls=polls))
        prev = e
    return out


#: replies per delivery at 500 Hz (RosBridge hands the GUI thread what 1/60 s brought)
BATCH_500HZ = 8


def session_cost(rates=(15.0, 100.0, 500.0), seconds: float = 30.0) -> dict:
    """Microseconds ``MonitorSession.process`` takes per reply, per poll and per reply;
    at 500 Hz also ``process_batch`` with the polls, in batches of :data:`BATCH_500HZ`."""
    import time

    from mm_pc.core.sensor_data import Reply
    from mm_pc.monitor.model.session import MonitorSession

    v, w = sim.trajectory("s_curves")
    n = round(seconds / sim.DT)
    devices = ("/dev/spidev1.0", "/dev/spidev1.1")
    counts = _counts(v[:n], w[:n], DEFAULT_MOUNTS, CPI)
    out = {}

    def best_us(feed, run) -> float:
        """Best of 3 of ``run(session)`` over a new session, per reply of ``feed`` (µs)."""
        best = math.inf
        for _ in range(3):
            s = MonitorSession(devices=devices)
            t0 = time.perf_counter()
            run(s)
            best = min(best, (time.perf_counter() - t0) / len(feed))
        return round(best * 1e6, 1)

    for hz in rates:
        replies = _replies(counts, sim.request_boundaries(n, hz), CPI, devices)
        plain = [Reply(r.readings) for r in replies]
        for label, feed in (("per_poll", replies), ("per_reply", plain)):
            out[f"{label}_us_per_reply_{hz:g}hz"] = best_us(
                feed, lambda s, feed=feed: [s.process(r) for r in feed]
            )
    if 500.0 in rates:  # as the bridge delivers 500 Hz: ~8 replies per 1/60 s
        replies = _replies(counts, sim.request_boundaries(n, 500.0), CPI, devices)
        batches = [replies[i : i + BATCH_500HZ] for i in range(0, len(replies), BATCH_500HZ)]
        out["per_poll_batched_us_per_reply_500hz"] = best_us(
            replies, lambda s: [s.process_batch(b) for b in batches]
        )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mm_pc.bench.per_poll", description=__doc__)
    ap.add_argument("--path", default="s_curves", choices=sorted(sim.TRAJECTORIES))
    ap.add_argument("--hz", type=float, default=15.0, help="request rate (Hz)")
    ap.add_argument("--json", action="store_true", help="print the dict as JSON")
    ap.add_argument("--session-cost", action="store_true",
                    help="time MonitorSession.process per reply instead")
    args = ap.parse_args(argv)
    res = session_cost() if args.session_cost else per_poll_errors(args.path, args.hz)
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        for k, val in res.items():
            print(f"{k}: {val:.3g}" if isinstance(val, float) else f"{k}: {val}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
