"""mm-bench gui: the real window, a short simulated history, a live sim node (no timing asserts)."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from mm_beagle.bench import main as bench_main
from mm_pc.bench.gui import bench_gui

POSITIVE = (
    "frame_ms_p50",
    "frame_ms_p95",
    "refresh_ms_p50",
    "refresh_ms_p95",
    "memory_mb",
    "memory_before_mb",
    "memory_after_history_mb",
    "history_mb",
    "rows",
    "replies",
    "rtt_ms_p50",
    "live_rate_hz",
)


@pytest.mark.ros
def test_bench_gui_reports_every_figure(qapp):
    r = bench_gui(hours=0.01, frames=20)
    for key in (*POSITIVE, "dropped_requests", "memory_growth_mb_during_frames", "tab_p95_ms"):
        assert key in r, key
    for key in POSITIVE:
        assert math.isfinite(r[key]) and r[key] > 0, (key, r[key])
    assert r["dropped_requests"] >= 0 and math.isfinite(r["memory_growth_mb_during_frames"])
    assert r["errors"] == {}
    # an hour at 0.01 h: 36 s of 100 Hz replies, then live rows on top
    assert r["history_rows_fed"] == 3601 and r["rows_after_history"] == 3600
    assert r["rows"] > r["rows_after_history"] + r["replies"] // 2  # live rows on top
    assert {"Map", "Graphs"} <= set(r["tab_p95_ms"])
    assert all(math.isfinite(v) and v > 0 for v in r["tab_p95_ms"].values())
    assert set(r["tab_catch_up_frames"]) == set(r["tab_p95_ms"])
    assert all(3 <= n <= 300 for n in r["tab_catch_up_frames"].values())


def test_bench_gui_refuses_bad_arguments(capsys):
    for bad in ({"hours": 0}, {"hours": -1.0}, {"rate_hz": 0}, {"frames": 0}, {"max_catch_up": -1}):
        with pytest.raises(ValueError, match="must be"):
            bench_gui(**bad)
    with pytest.raises(SystemExit):
        bench_main(["gui", "--frames", "0"])
    assert "frames must be an integer >= 1" in capsys.readouterr().err
