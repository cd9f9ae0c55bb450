"""Trilateration benchmark: speed and accuracy of least squares and the seed's method.

Field: 30 m x 30 m, four beacons 1 m high at its corners (REP 103 local
frame, metres). Robot positions uniform over the whole field (seeded), slant
ranges with Gaussian noise of sigma. Least squares gets the true sigma; the
seed's method its default S_phi = 0.5 m. RMS errors are over the fixes a
method returned; ``seed_rejected`` / ``ls_failed`` are the fractions of
positions where it raised :class:`~mm_pc.core.maps.trilateration.TrilaterationError`
(S_phi rejections, circles missing by more than S_phi, or a range shorter
than a beacon's height near a corner at large sigma).
"""

from __future__ import annotations

import math
import time

import numpy as np

from mm_pc.core.maps.trilateration import (
    Beacon,
    TrilaterationError,
    least_squares_fix,
    seed_fix,
    simulate_ranges,
)

FIELD_M = 30.0
BEACON_HEIGHT_M = 1.0
SIGMAS_M = (0.01, 0.05, 0.1, 0.2)
HEADLINE_SIGMA_M = 0.05
SEED = 20240603
BEACONS = tuple(
    Beacon(x, y, BEACON_HEIGHT_M, name)
    for x, y, name in ((0.0, 0.0, "SW"), (FIELD_M, 0.0, "SE"), (FIELD_M, FIELD_M, "NE"),
                       (0.0, FIELD_M, "NW"))
)  # fmt: skip


def _rms_and_failures(fixer, cases, **kw) -> tuple[float, float]:
    """RMS position error (m) over returned fixes, and the fraction that raised."""
    sq, failed = [], 0
    for (x, y), r in cases:
        try:
            f = fixer(BEACONS, r, **kw)
        except TrilaterationError:
            failed += 1
            continue
        sq.append((f.x - x) ** 2 + (f.y - y) ** 2)
    rms = math.sqrt(float(np.mean(sq))) if sq else math.nan
    return rms, failed / len(cases)


def _cases(sigma: float, n: int, rng: np.random.Generator):
    points = rng.uniform(0.0, FIELD_M, size=(n, 2))
    return [((x, y), simulate_ranges(BEACONS, x, y, sigma, rng)) for x, y in points]


def _fixes_per_s(fixer, cases, seconds: float, **kw) -> float:
    """Fixes per second over repeated passes through ``cases`` for about ``seconds``."""
    done, t0 = 0, time.perf_counter()
    while True:
        for _, r in cases:
            fixer(BEACONS, r, **kw)
        done += len(cases)
        elapsed = time.perf_counter() - t0
        if elapsed >= seconds:
            return done / elapsed


def bench_trilateration(seconds_budget: float = 2.0) -> dict:
    """The benchmark as one JSON-ready dict; takes roughly ``seconds_budget`` seconds.

    About half the budget goes to the accuracy table (positions per sigma
    scale with the budget, at least 50), a quarter to timing each method.
    """
    if not (math.isfinite(seconds_budget) and seconds_budget > 0):
        raise ValueError(f"seconds_budget must be a finite number > 0 s, got {seconds_budget!r}")
    n = max(50, int(250 * seconds_budget))
    rng = np.random.default_rng(SEED)
    table = []
    for sigma in SIGMAS_M:
        cases = _cases(sigma, n, rng)
        ls_rms, ls_failed = _rms_and_failures(least_squares_fix, cases, sigma=sigma)
        seed_rms, seed_rejected = _rms_and_failures(seed_fix, cases)
        table.append(
            {
                "sigma_m": sigma,
                "ls_rms_m": ls_rms,
                "seed_rms_m": seed_rms,
                "seed_rejected": seed_rejected,
                "ls_failed": ls_failed,
                "fixes": n,
            }
        )
    headline = next(row for row in table if row["sigma_m"] == HEADLINE_SIGMA_M)
    # speed on positions 1 m inside the field, so no fix raises mid-timing
    timing_rng = np.random.default_rng(SEED + 1)
    points = timing_rng.uniform(1.0, FIELD_M - 1.0, size=(200, 2))
    timing = [
        ((x, y), simulate_ranges(BEACONS, x, y, HEADLINE_SIGMA_M, timing_rng)) for x, y in points
    ]
    return {
        "trilateration_fixes_per_s": _fixes_per_s(
            least_squares_fix, timing, seconds_budget / 4, sigma=HEADLINE_SIGMA_M
        ),
        "trilateration_fixes_per_s_seed": _fixes_per_s(
            seed_fix, timing, seconds_budget / 4, s_phi=math.inf
        ),
        "trilateration_error_m": headline["ls_rms_m"],
        "trilateration_error_m_seed": headline["seed_rms_m"],
        "trilateration_error_vs_noise": table,
        "trilateration_setup": (
            f"{FIELD_M:g} m x {FIELD_M:g} m field, 4 beacons {BEACON_HEIGHT_M:g} m high at the "
            f"corners, {n} uniform positions per sigma (seed {SEED}), least squares with the "
            "true sigma, seed's method with S_phi = 0.5 m and the best three of four beacons"
        ),
    }
