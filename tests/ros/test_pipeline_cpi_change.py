"""A CPI change while driving, through the real processes (issue 28 item 2): mm-beagle (sim,
a CSV s-curves path) and one mm-odometry per method at 15 Hz; set_resolution
1600 -> 800 -> 3200 on both sensors mid-run. Each poll carries its CPI (GetSamples'
poll_cpi), so no interval becomes a gap and the final pose is as exact as without the
changes. Before, every change inside a request interval was a gap step from the totals."""

from __future__ import annotations

import math
import time

import pytest

pytest.importorskip("rclpy")

from mm_pc.bench.pipeline import (
    ONBOARD,
    FinalPoses,
    _row,
    _Stack,
    _truth,
    in_process,
    pose_of,
    start_pipeline,
    write_path,
)
from mm_pc.sim import robot as sim

pytestmark = pytest.mark.ros

DEVICES = ("/dev/spidev1.0", "/dev/spidev1.1")
START_DELAY_S = 8.0
#: seconds into the motion -> the CPI then set on both sensors
CHANGES = ((5.0, 800), (11.0, 3200))
#: seconds between the two sensors' set_resolution calls (the sensors at two CPIs meanwhile)
BETWEEN_S = 0.5
#: two-sensor against the path with the changes (mm per 10 m), mm-odometry's and the
#: onboard's: the issue's goal through the processes. Measured at load 8-11 (h28drain):
#: 0.015-0.026 (mm-odometry), 0.015-0.018 (onboard, paired by tick); the margin is for
#: load. Before the drain moved into the CPI write's transfer: 0.45-2.7 at load 6-10 (the
#: counts of the drain-to-write window read at the new CPI: a lasting yaw step), the bound
#: then 4.0; the onboard paired by ring position: 0.08 where mm-odometry had 0.026.
TWO_SENSOR_WITH_CHANGES_MAX = 0.2


def _run(path, log_dir):
    """mm-beagle + mm-odometry exact and two-sensor at 15 Hz, the CPI changes made while
    the robot drives: per key the final pose's error row, gaps and polls integrated."""
    from mm_beagle.tools.harness import use_isolated_ros_env

    v, _w, truth, length = _truth(path)
    motion_s = len(v) * sim.DT
    env = use_isolated_ros_env()
    nodes = {"exact@15Hz": "exact", "two-sensor@15Hz": "two-sensor"}
    ns = {k: "/cpi_" + k.replace("-", "_").replace("@", "_") for k in nodes}
    beagle = {
        "backend": "sim", "sim_trajectory": f"file:{path}", "sim_loop": False,
        "sim_start_delay": START_DELAY_S, "cpi": 1600,
        "odometry_rate": 15.0, "odometry_method": "two-sensor",
    }  # fmt: skip
    odometry = {
        k: (ns[k], {"beagle": "/mm_beagle", "rate": 15.0, "method": m, "publish_tf": False})
        for k, m in nodes.items()
    }
    set_at: list[tuple[float, int, list[int]]] = []
    with _Stack() as stack:
        client, t_start = start_pipeline(
            stack, odometry, beagle, env, log_dir, "test_pipeline_cpi_change"
        )  # t_start: mm-beagle's start, the changes' times count from it as its start delay
        watch = FinalPoses(client, {**{k: f"{ns[k]}/mm_odometry/odom" for k in nodes},
                                    ONBOARD: "/mm_beagle/odom"})  # fmt: skip
        todo = list(CHANGES)
        deadline = t_start + START_DELAY_S + motion_s + 60.0
        while time.monotonic() < deadline and not watch.done:
            time.sleep(0.05)
            now = time.monotonic() - t_start - START_DELAY_S
            if todo and now >= todo[0][0]:
                _, cpi = todo.pop(0)
                back = []
                for d in DEVICES:
                    back.append(client.call("set_resolution", id=d, cpi=cpi, timeout=10.0).cpi)
                    time.sleep(BETWEEN_S)
                set_at.append((round(now, 2), cpi, back))
            if now >= motion_s:
                watch.note_finals()
        time.sleep(1.5)  # one more /diagnostics round after the last polls
        rings = [client.call("get_samples", id=d, since_seq=0, max_samples=0, timeout=10.0,
                             retries=2) for d in DEVICES]  # fmt: skip
    out: dict = {"set": set_at, "length_m": length, "motion_s": motion_s, "rings": rings,
                 "ring_cpis": sorted(set(rings[0].poll_cpi))}  # fmt: skip
    for k in watch.topics:
        msg = watch.finals.get(k)
        if msg is None:
            out[k] = {"error": f"no final pose in time (logs: {log_dir})"}
            continue
        row = _row(pose_of(msg), truth, length)
        row["pose"] = pose_of(msg)
        if k in ns:
            d = watch.diagnostics(ns[k])
            row["gaps"] = int(d.get("gaps", -1))
            row["last_gap"] = d.get("last_gap", "")
            row["polls_integrated"] = int(d.get("polls_integrated", -1))
        out[k] = row
    return out


def _ring_pose(rings, method: str):
    """The final pose of ``method`` from the whole rings (every poll from seq 0) through one
    PollTracker step: what the node should publish, whatever its request boundaries."""
    import numpy as np

    from mm_pc.core.geometry import DEFAULT_MOUNTS
    from mm_pc.core.odometry import Odometry
    from mm_pc.core.polls import PollBatch, PollTracker, SensorTotals
    from pln2033 import INCH_M

    batches = [PollBatch.from_reply(r) for r in rings]
    totals = []
    for b in batches:
        assert b.first_seq == 0 and b.poll_cpi is not None
        m = INCH_M / b.cpis
        stamp = int(b.stamp_ns[-1])
        totals.append((
            SensorTotals(0, int(b.stamp_ns[0]) - 1, 0, 0, 0.0, 0.0),
            SensorTotals(b.next_seq, stamp, int(b.dx.sum()), int(b.dy.sum()),
                         float(np.cumsum(b.dx * m)[-1]), float(np.cumsum(b.dy * m)[-1])),
        ))  # fmt: skip
    tr = PollTracker(len(rings))
    tr.baseline([t[0] for t in totals])
    steps = tr.step([t[1] for t in totals], batches)
    assert tr.gaps == 0, tr.gap_reasons
    odo = Odometry(DEFAULT_MOUNTS, method)
    odo.integrate(steps.dt, steps.d)
    return odo.pose.as_array()


def test_cpi_changes_while_driving_are_no_gap_and_keep_the_pose_exact(tmp_path):
    path = tmp_path / "s_curves.csv"
    write_path(path, speed=0.5, duration=16.0)
    got = _run(path, tmp_path)
    # both changes made while the robot drove, on both sensors
    assert [(c, b) for _, c, b in got["set"]] == [(800, [800, 800]), (3200, [3200, 3200])], got
    assert all(t + BETWEEN_S < got["motion_s"] for t, _, _ in got["set"]), got["set"]
    # mm-beagle's get_samples says each poll's CPI (its ring holds the whole run)
    assert got["ring_cpis"] == [800, 1600, 3200], got
    # the in-process per-poll figure at each of the CPIs used: the pose through the
    # processes with the changes is within 1.2x the worst of them (what remains is the
    # count quantisation of the CPI in force, as without a change)
    ref = {cpi: in_process(path, (15.0,), cpi) for cpi in (800, 1600, 3200)}
    for k, m in (("exact@15Hz", "exact"), ("two-sensor@15Hz", "two-sensor")):
        row = got[k]
        assert "error" not in row, got
        # was one gap step per change (two per sensor pair), named "the CPI changed"; one
        # gap of another cause (a reply lost on a loaded machine, once in 7 runs at load 12,
        # while the robot stood still) is allowed: the pose checks below still hold
        assert row["gaps"] == 0 or (row["gaps"] == 1 and "CPI" not in row["last_gap"]), got
        assert row["polls_integrated"] > 2 * 15_000, got
        # the node integrated every poll of its ring at its own CPI: its pose is the one
        # of the whole rings in one go (within the float noise of the request boundaries)
        want = _ring_pose(got["rings"], m)
        assert abs(math.remainder(row["pose"][2] - want[2], 2 * math.pi)) < 1e-9, (k, want, row)
        assert math.hypot(row["pose"][0] - want[0], row["pose"][1] - want[1]) < 1e-9, (k, want)
    worst = max(r["exact@15Hz"]["error_mm_per_10m"] for r in ref.values())
    assert got["exact@15Hz"]["error_mm_per_10m"] <= 1.2 * worst, (got, ref)
    # two-sensor against the path: every count at the CPI it was counted at (the drain in
    # the CPI write's transfer), so the changes leave no yaw step
    assert got["two-sensor@15Hz"]["error_mm_per_10m"] <= TWO_SENSOR_WITH_CHANGES_MAX, got
    onboard = got[ONBOARD]
    assert "error" not in onboard, got
    # the onboard odometry pairs the polls by tick as mm-odometry does: the drain reads
    # (one ring an entry longer between the two sensors' changes) offset nothing
    assert onboard["error_mm_per_10m"] <= TWO_SENSOR_WITH_CHANGES_MAX, got
