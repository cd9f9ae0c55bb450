"""The pose the nodes publish, as exact as the in-process integration: mm-beagle (sim,
a CSV s-curves path, 1600 CPI) and one mm-odometry per method at 15 and 100 Hz
(``mm-bench pipeline``'s run, ~35 s), and mm-beagle's own two-sensor odometry."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")

from mm_pc.bench.pipeline import ONBOARD, in_process, through_processes, write_path

pytestmark = pytest.mark.ros

#: The goal, 0.2 mm per 10 m: measured 0.057-0.059 with each sensor stamped right before
#: its own transfer (load 6-18 on 2 cores); 0.23-0.26 with the stamp before the read path
#: (the 0.4 this bound was then), 1.29 with one stamp per tick.
TWO_SENSOR_MAX_MM_PER_10M = 0.2


def test_both_methods_through_the_processes_at_1600_cpi(tmp_path):
    path = tmp_path / "s_curves.csv"
    write_path(path, speed=0.5, duration=20.0)
    rates = (15.0, 100.0)
    ref = in_process(path, rates, 1600)
    got = through_processes(path, rates, 1600, start_delay=8.0, timeout=40.0,
                            log_dir=tmp_path)  # fmt: skip
    onboard = got[ONBOARD]
    assert "error" not in onboard, got
    assert onboard["error_mm_per_10m"] <= TWO_SENSOR_MAX_MM_PER_10M, got
    for hz in ("15", "100"):
        ex, ts = got[f"exact@{hz}Hz"], got[f"two-sensor@{hz}Hz"]
        assert "error" not in ex and "error" not in ts, got
        assert ts["error_mm_per_10m"] <= TWO_SENSOR_MAX_MM_PER_10M, got
        assert ex["error_mm_per_10m"] <= 1.2 * ref[f"exact@{hz}Hz"]["error_mm_per_10m"], got
        # the final heading is the counts' own (linear in them): as in-process
        for m in ("exact", "two-sensor"):
            want = ref[f"{m}@{hz}Hz"]["yaw_error_rad"]
            assert got[f"{m}@{hz}Hz"]["yaw_error_rad"] == pytest.approx(want, abs=2e-5), got
            assert got[f"{m}@{hz}Hz"]["polls_integrated"] > 2 * 18_000, got
