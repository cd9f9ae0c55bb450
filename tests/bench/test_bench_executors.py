"""mm-bench executors: a bare client's CPU per reply under each executor, in one run."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("rclpy")

from mm_pc.bench.cli import main as bench_main
from mm_pc.bench.executors import bench_executors


@pytest.mark.ros
def test_bench_executors_measures_both_executors_against_a_real_node():
    r = bench_executors(rate_hz=200.0, seconds=1.0, rounds=1)
    assert set(r["runs"]) == {"events", "waitset"}
    for runs in r["runs"].values():
        (run,) = runs
        assert 0 < run["achieved_hz"] <= 240.0, run
        assert 0 < run["cpu_percent_one_core"] < 201.0, run
        per_reply = 10.0 * run["cpu_percent_one_core"] / run["achieved_hz"]
        assert math.isclose(run["cpu_ms_per_reply"], per_reply, rel_tol=0.05), run
    med = r["median_cpu_ms_per_reply"]
    assert r["events_over_waitset"] == pytest.approx(med["events"] / med["waitset"], abs=1e-3)


def test_bench_executors_refuses_bad_arguments(capsys):
    for bad, message in (
        ({"rate_hz": 0}, "sample rate must be in 1..500"),
        ({"seconds": 0.5}, r"seconds must be in \[1, 600\]"),
        ({"rounds": 0}, "rounds must be an integer in 1..20"),
    ):
        with pytest.raises(ValueError, match=message):
            bench_executors(**bad)
    with pytest.raises(SystemExit) as e:
        bench_main(["executors", "--rounds", "x"])
    assert e.value.code == 2 and "invalid int value: 'x'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        bench_main(["executors", "--seconds", "0"])
    assert e.value.code == 2 and "seconds must be in [1, 600]" in capsys.readouterr().err
