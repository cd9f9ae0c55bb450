"""mm-bench gui: the real window, a short simulated history, a live sim node (no timing asserts)."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from mm_pc.bench.cli import main as bench_main
from mm_pc.bench.gui import DATA_TAB_S, bench_gui

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
    r = bench_gui(hours=0.01, frames=20, live_seconds=2.0)
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
    # the live CPU measurement at 100 and 500 Hz against the node in another process
    assert set(r["live"]) == {"100", "500"} and r["goal_live_cpu_percent"] == 50.0
    # the polls came inside the data replies: not one get_samples call
    assert r["live_polls"] == "reply" and r["live_poll_fetches"] == 0
    assert r["live_executor"] == "events"
    for hz, live in r["live"].items():
        assert 0 < live["achieved_hz"] <= float(hz) * 1.2, (hz, live)
        assert live["replies"] > 0 and 0 < live["cpu_percent_one_core"] < 200.0 + 1, live
        threads = [live[f"cpu_percent_{t}"] for t in ("gui_thread", "ros_thread", "other_threads")]
        assert threads[0] > 0 and threads[1] > 0 and min(threads) >= 0, live
        # the threads' shares add up to the process's (both from the kernel's counters)
        assert sum(threads) == pytest.approx(live["cpu_percent_one_core"], abs=3.0), live
        # every reply became a row (a slot that raised would leave them unprocessed)
        # (less the batch still waiting for the GUI thread at the end, ~8 at 500 Hz, and a
        # reply now and then that found no new poll: no row)
        assert 0.98 * live["replies"] - 10 <= live["rows"] <= live["replies"] + 10, live
        per_reply_ms = 10.0 * live["cpu_percent_one_core"] / live["achieved_hz"]
        assert math.isclose(live["cpu_ms_per_reply"], per_reply_ms, rel_tol=0.05), live
    # the heartbeat during the heavy actions (issue 29 item 6): figures, not a timing gate
    st = r["stalls"]
    assert st["heartbeat_ms"] == 10 and st["stall_ms"] == 100.0
    assert set(st["by_action"]) == {
        "tabs_500hz", "data_tab_500hz", "simulate_mowing_run", "csv_export", "png_export",
        "replay", "replay_seek",
    }  # fmt: skip
    assert st["by_action"]["data_tab_500hz"]["seconds"] >= DATA_TAB_S
    # the seek back to 17 s of the 30 s recording at 100 Hz: from the keyframe at 15 s
    assert st["seek_keyframes"] == 4 and st["seek_back_replies"] == 200
    assert 0 < st["seek_back_s"] < 30.0
    for name, a in st["by_action"].items():
        assert "error" not in a, (name, a)
        assert a["ticks"] > 0 and a["longest_ms"] >= 10.0 * 0.5 and a["count_over_100ms"] >= 0
    assert st["longest_ms"] == max(a["longest_ms"] for a in st["by_action"].values())
    assert st["count_over_100ms"] == sum(a["count_over_100ms"] for a in st["by_action"].values())
    assert st["tab_switches"] == 14 and st["sim_build_s"] > 0
    assert st["csv_rows"] > r["rows_after_history"]  # the history and the live rows, all


def test_bench_gui_refuses_bad_arguments(capsys):
    for bad in (
        {"hours": 0}, {"hours": -1.0}, {"rate_hz": 0}, {"frames": 0}, {"max_catch_up": -1},
        {"live_seconds": -1.0}, {"live_seconds": "x"}, {"polls": "both"},
        {"executor": "asyncio"}, {"stalls": ("csv_export", "nope")},
        {"stalls": ("csv_export", "csv_export")},
    ):
        with pytest.raises(ValueError, match="must be"):
            bench_gui(**bad)
    with pytest.raises(SystemExit):
        bench_main(["gui", "--frames", "0"])
    assert "frames must be an integer >= 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        bench_main(["gui", "--live-seconds", "-2"])
    assert "live_seconds must be in [0, 600]" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        bench_main(["gui", "--executor", "multi"])
    assert e.value.code == 2 and "invalid choice: 'multi'" in capsys.readouterr().err
    for bad in ("nope", "csv_export,", ""):
        with pytest.raises(SystemExit) as e:
            bench_main(["gui", "--stalls", bad])
        err = capsys.readouterr().err
        assert e.value.code == 2 and "give 'all', 'none' or a comma list of" in err, err
        assert "csv_export" in err.splitlines()[-1] and "Traceback" not in err


def test_bench_gui_without_a_node_measures_the_chosen_stalls_alone(qapp):
    """--no-node --stalls csv_export: the export's own cost, no live data beside it."""
    r = bench_gui(hours=0.01, frames=3, node=False, stalls=("csv_export",))
    st = r["stalls"]
    assert set(st["by_action"]) == {"csv_export"} and st["live_node"] is False
    assert "live" not in r and r["replies"] == 0
    assert st["csv_rows"] == r["rows_after_history"] == 3600  # the history only, all of it
    a = st["by_action"]["csv_export"]
    assert "error" not in a and a["ticks"] > 0
