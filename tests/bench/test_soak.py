"""mm-bench soak: a short run emits its JSON report; the slope is a least-squares line."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from mm_pc.bench.cli import main as bench_main
from mm_pc.bench.soak import FLAT_MB_PER_MIN, MB, slope_mb_per_min

KEYS = {
    "agent_rss_slope_mb_per_min",
    "node_rss_slope_mb_per_min",
    "flat_threshold_mb_per_min",
    "flat",
    "warmup_s",
    "counts_generated",
    "counts_served",
    "counts_lost",
    "counts_lost_read_and_clear",
    "rss_samples",
    "pass",
}


def test_slope_leaves_out_the_warm_up():
    t = [0, 10, 20, 30, 40, 50, 60]
    rss = [10 * MB, 50 * MB, 50 * MB, 50.5 * MB, 51 * MB, 51.5 * MB, 52 * MB]  # +3 MB/min
    assert slope_mb_per_min(t, rss, 15.0) == pytest.approx(3.0)
    assert slope_mb_per_min(t, rss, 60.0) is None  # one sample left: no line


def test_soak_refuses_bad_arguments(capsys):
    for bad in (["--minutes", "0"], ["--minutes", "nan"], ["--sample-seconds", "0.1"]):
        with pytest.raises(SystemExit) as e:
            bench_main(["soak", *bad])
        assert e.value.code == 2
        assert "need 0.1 <= --minutes <= 1440" in capsys.readouterr().err


@pytest.mark.ros
def test_short_soak_emits_valid_json():
    out = subprocess.run(
        [sys.executable, "-m", "mm_pc.bench.cli", "soak", "--minutes", "0.2",
         "--sample-seconds", "1", "--json"],
        capture_output=True, text=True, timeout=120, check=True,
    )  # fmt: skip
    report = json.loads(out.stdout)
    assert set(report) >= KEYS
    assert report["flat_threshold_mb_per_min"] == FLAT_MB_PER_MIN
    assert report["samples"] >= 8 and len(report["rss_samples"]) == report["samples"]
    assert report["counts_generated"] > 10_000  # the robot moved
    assert report["counts_lost"] == 0 and report["counts_lost_read_and_clear"] == 0
    assert report["counts_served"] == report["counts_generated"]
    for name in ("agent", "node"):
        assert isinstance(report[f"{name}_rss_slope_mb_per_min"], float)
        assert 20 < report[f"{name}_rss_mb_last"] < 1000
