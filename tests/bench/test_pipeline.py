"""mm-bench pipeline's in-process side and the read-delay correction it measures
(mm_pc.core.polls: each sensor's poll stamped at its own read, deskewed onto sensor 0's)."""

from __future__ import annotations

import numpy as np
import pytest

from mm_pc.bench.cli import main as bench_main
from mm_pc.bench.pipeline import in_process, read_delay_in_process, write_path
from mm_pc.core.polls import (
    FLAG_COMMAND_READ,
    MAX_READ_SKEW_NS,
    PollBatch,
    PollTracker,
    SensorTotals,
    deskew,
    snap_to_ticks,
)
from pln2033 import INCH_M


@pytest.fixture(scope="module")
def path(tmp_path_factory):
    p = tmp_path_factory.mktemp("pipeline") / "s_curves.csv"
    write_path(p, speed=0.5, duration=20.0)
    return p


def test_in_process_figures_are_the_per_poll_floor(path):
    """The file's 1 kHz steps floored at 1600 CPI: exact keeps its half-count floor,
    two-sensor is two orders below (docs/pose-math.md)."""
    r = in_process(path, (15.0, 100.0), 1600)
    for hz in ("15", "100"):
        assert r[f"exact@{hz}Hz"]["error_mm_per_10m"] == pytest.approx(1.24, abs=0.03)
        assert r[f"two-sensor@{hz}Hz"]["error_mm_per_10m"] < 0.03


def test_sensor_1_read_20_us_later_is_deskewed_to_the_in_process_figure(path):
    """The poller reads sensor 1 ~10-40 us after sensor 0. With one stamp per tick
    two-sensor took that as simultaneous: 1.1 mm per 10 m at 0.5 m/s (the figure the
    real processes showed); with each poll's own stamp the tracker moves it back."""
    base = in_process(path, (15.0,), 1600)["two-sensor@15Hz"]["error_mm_per_10m"]
    old = read_delay_in_process(path, 20.0, 1600, equal_stamps=True)
    new = read_delay_in_process(path, 20.0, 1600, jitter_us=20.0)
    assert old["two-sensor"]["error_mm_per_10m"] > 0.8
    assert new["two-sensor"]["error_mm_per_10m"] < base + 0.01
    assert new["gaps"] == old["gaps"] == 0
    # exact reads one sensor: the delay never mattered to it
    assert new["exact"] == old["exact"]


def test_a_preempted_read_2_ms_late_is_still_its_tick(path):
    r = read_delay_in_process(path, 2000.0, 1600)
    assert r["two-sensor"]["error_mm_per_10m"] < 0.03


def test_snap_to_ticks_pairs_one_poll_per_tick_and_leaves_the_rest():
    ticks = np.array([1_000_000, 2_000_000, 4_000_000], np.int64)
    stamps = np.array([1_020_000, 2_015_000, 2_900_000, 4_010_000, 4_020_000,
                       4_000_000 + MAX_READ_SKEW_NS + 5_000_000], np.int64)  # fmt: skip
    flags = np.array([2, 2, 2, FLAG_COMMAND_READ, 2, 2])
    got = snap_to_ticks(ticks, stamps, flags)
    # the second poll after tick 2 ms is one of a tick sensor 0 missed (3 ms): its own;
    # a command read keeps its stamp; one too late keeps its own
    assert got.tolist() == [1_000_000, 2_000_000, 2_900_000, 4_010_000, 4_000_000,
                            int(stamps[-1])]  # fmt: skip


def test_deskew_moves_displacement_without_losing_any():
    rng = np.random.default_rng(3)
    d = rng.normal(1e-4, 2e-5, (50, 2, 2))
    delay = np.zeros((50, 2), np.int64)
    delay[:, 1] = rng.integers(5_000, 40_000, 50)
    carry, prev = np.zeros((2, 2)), np.zeros(2)
    parts = [deskew(d[a:b].copy(), delay[a:b], np.full(b - a, 1e-3), carry, prev)
             for a, b in ((0, 17), (17, 18), (18, 50))]  # fmt: skip
    out = np.concatenate(parts)
    np.testing.assert_allclose(out.sum(0) + carry, d.sum(0), atol=1e-15)
    np.testing.assert_array_equal(out[:, 0], d[:, 0])  # sensor 0 is the tick's time
    assert carry[1] == pytest.approx(d[-1, 1] * delay[-1, 1] / (1e6 + delay[-1, 1] - delay[-2, 1]))


def test_a_gap_after_deskewed_steps_gives_the_held_back_share_back():
    """Steps with sensor 1 read late, then a gap (polls missing): the steps' sum is the
    totals' displacement exactly, per sensor (nothing lost to the carry)."""
    cpi, k = 1600, 2
    scale = INCH_M / cpi
    rng = np.random.default_rng(5)
    n = 300
    counts = rng.integers(0, 6, (n, k, 2))
    cum = np.concatenate([np.zeros((1, k, 2), np.int64), np.cumsum(counts, 0)])
    tick = (np.arange(1, n + 1) * 1_000_000 + 10**18).astype(np.int64)
    stamps = [tick, tick + 25_000]

    def totals(j):
        return [SensorTotals(j, int(stamps[i][j - 1]) if j else 10**18, int(cum[j, i, 0]),
                             int(cum[j, i, 1]), float(cum[j, i, 0]) * scale,
                             float(cum[j, i, 1]) * scale) for i in range(k)]  # fmt: skip

    tr = PollTracker(k)
    tr.baseline(totals(0))
    parts = []
    for a, b, missing in ((0, 100, False), (100, 200, True), (200, 300, False)):
        batches = [None if missing and i == 1 else
                   PollBatch(a, b, 0, cpi, stamps[i][a:b], counts[a:b, i, 0], counts[a:b, i, 1],
                             np.full(b - a, 2)) for i in range(k)]  # fmt: skip
        parts.append(tr.step(totals(b), batches))
    assert tr.gaps == 1
    total = sum(p.d.sum(0) for p in parts) + tr._carry
    np.testing.assert_allclose(total, cum[-1] * scale, atol=1e-12)
    assert np.abs(tr._carry).max() > 0  # the last steps hold a share back, bounded
    assert np.abs(tr._carry).max() < 6 * scale


@pytest.mark.parametrize(
    "args, message",
    [
        (["--rates", "x"], "--rates 'x' is not a list of numbers (Hz)"),
        (["--rates", "15,0"], "--rates '15,0': each in (0, 500] Hz"),
        (["--cpi", "5"], "--cpi 5: the sim's CPI, 100..25600"),
        (["--speed", "0"], "--speed and --duration must be > 0"),
        (["--lifts", "-1"], "--lifts -1: lifts per second per sensor, 0..100"),
        (["--path-file", "/nonexistent/p.csv"], "trajectory file /nonexistent/p.csv: cannot"),
    ],
)
def test_bad_options_are_one_line_and_exit_2(args, message, capsys):
    with pytest.raises(SystemExit) as e:
        bench_main(["pipeline", "--in-process-only", *args])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"mm-bench: error: {message}" in err
    assert "Traceback" not in err


def test_in_process_only_prints_both_tables(capsys, path):
    import json

    assert bench_main(["pipeline", "--in-process-only", "--path-file", str(path), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert set(r["in_process"]) == {"exact@15Hz", "two-sensor@15Hz", "exact@100Hz",
                                    "two-sensor@100Hz"}  # fmt: skip
    assert "processes" not in r
    assert r["setup"]["length_m"] == pytest.approx(11.02, abs=0.01)
    assert "load_trajectory_file" in r["setup"]["ground_truth"]
