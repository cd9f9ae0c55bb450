"""Replies as mm_beagle would serve them, computed from the ground-truth simulator.

No ROS, no Qt: used by widget tests (real processing, no node needed), by
``mm-bench gui`` to fast-forward an hour of data, and for screenshots. The
counts come from :func:`mm_pc.sim.robot.request_samples` (CPI-quantised, so
exactly what the emulated sensors behind the real driver would total).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from mm_pc.core.frames import m_to_counts
from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.sim.robot import request_samples, trajectory

__all__ = ["DEFAULT_DEVICES", "sim_replies"]

DEFAULT_DEVICES = ("/dev/spidev1.0", "/dev/spidev1.1")


def sim_replies(
    name: str = "figure_eight",
    rate_hz: float = 100.0,
    seconds: float | None = None,
    speed: float = 0.2,
    devices: Sequence[str] = DEFAULT_DEVICES,
    mounts: Sequence[SensorMount] = DEFAULT_MOUNTS,
    cpi: int = 1600,
    start_ns: int = 1_700_000_000_000_000_000,
    rtt_s: float = 0.002,
) -> Iterator[Reply]:
    """Replies of a client asking at ``rate_hz`` while the robot drives ``name``.

    The path repeats until ``seconds`` (None = one lap). The first reply is
    the baseline at t = 0 (totals 0), as a real first request would be.
    Units: metres and seconds; stamps in ns (``start_ns`` + time).
    """
    v, w = trajectory(name, speed=speed)
    if seconds is not None:
        reps = int(np.ceil(seconds * 1000 / len(v)))
        v, w = np.tile(v, reps)[: int(seconds * 1000)], np.tile(w, reps)[: int(seconds * 1000)]
    mounts = tuple(mounts)[: len(devices)]
    rs = request_samples(v, w, mounts=mounts, request_hz=rate_hz, cpi=cpi)
    totals = np.zeros((len(devices), 2))
    prev_step = 0
    yield _reply(devices, totals, np.zeros((len(devices), 2)), 0, 0, start_ns, cpi, rtt_s)
    for _dt, d, end in zip(rs.dt, rs.d, rs.end_step, strict=True):
        totals = totals + d
        yield _reply(devices, totals, d, int(end), int(end - prev_step), start_ns, cpi, rtt_s)
        prev_step = int(end)


def _reply(devices, totals, d, seq, samples, start_ns, cpi, rtt_s) -> Reply:
    stamp = start_ns + seq * 1_000_000
    interval = samples / 1000.0
    readings = []
    for k, dev in enumerate(devices):
        dx, dy = float(d[k, 0]), float(d[k, 1])
        readings.append(
            Reading(
                id=dev,
                stamp_ns=stamp,
                seq=seq,
                x_total=float(totals[k, 0]),
                y_total=float(totals[k, 1]),
                x_speed=dx / interval if interval else 0.0,
                y_speed=dy / interval if interval else 0.0,
                x_counts=round(float(m_to_counts(dx, cpi))),
                y_counts=round(float(m_to_counts(dy, cpi))),
                cpi=cpi,
                samples=samples,
                interval=interval,
                x_disp=dx,
                y_disp=dy,
                x_total_counts=round(float(m_to_counts(totals[k, 0], cpi))),
                y_total_counts=round(float(m_to_counts(totals[k, 1], cpi))),
            )
        )
    return Reply(tuple(readings), received_s=stamp / 1e9, rtt_s=rtt_s)
