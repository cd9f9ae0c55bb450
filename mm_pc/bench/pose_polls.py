"""Per-poll integration and lifted sensors: the issue-11 figures of ``mm-bench pose``.

* ``per_poll_15hz_error_m_per_10m``: the s-curves path (speed and curvature change
  continuously), counts noise-free but whole at :data:`CPI` per 1 ms poll with the
  remainder carried (the emulator's floor of the cumulative count), every poll
  integrated, the pose read at 15 Hz requests; final position error per 10 m of
  path. Beside it the same counts summed per 15 Hz request and integrated per request.
* ``lift_tour_error_m_exact`` / ``..._two_sensor``: the 12 m mixed tour, same
  counts, sensor 0 (the one ``exact`` uses) lifted for :data:`LIFTS`; each lifted
  stretch filled from windows of polls (:func:`mm_pc.core.filters.fill_lift_gaps`),
  every poll integrated; ``two-sensor`` gets the lift mask and drops the lifted
  sensor. Final position error in metres. Beside it the one-poll rule and no filling.
"""

from __future__ import annotations

import numpy as np

from mm_pc.core.filters import fill_lift_gaps
from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.sim import robot as sim
from pln2033 import INCH_M, lift_fill

CPI = 1600.0
REQUEST_HZ = 15.0
#: (start s, duration s) of the lifts of sensor 0 on the mixed tour: on the first
#: straight, in the S-curves, in the spin, while reversing, on the arc, on the fast straight
LIFTS = [(4.0, 0.3), (17.0, 0.5), (33.0, 0.4), (38.5, 0.3), (45.0, 0.4), (52.0, 0.5)]


def _final_error(poses: np.ndarray, truth: np.ndarray) -> float:
    return float(np.hypot(poses[-1, 0] - truth[-1, 0], poses[-1, 1] - truth[-1, 1]))


def per_poll_error() -> dict:
    """Final error per 10 m on s_curves: per-poll vs per-request integration, 15 Hz."""
    v, w = sim.trajectory("s_curves")
    length = float(np.sum(np.abs(v)) * sim.DT)
    polls = sim.request_samples(v, w, DEFAULT_MOUNTS, 1000.0, cpi=CPI)
    requests = sim.request_samples(v, w, DEFAULT_MOUNTS, REQUEST_HZ, cpi=CPI)
    ends = requests.end_step - 1  # the pose shown at each request: after its last poll
    # the same counts rounded to the nearest count instead of floored: isolates the
    # emulator's floor, whose half-count bias in dX turns exact's heading by 0.5 count / sy
    exact_m = sim.request_samples(v, w, DEFAULT_MOUNTS, 1000.0)
    cum = np.cumsum(exact_m.d, axis=0) * (CPI / INCH_M)
    rounded = np.diff(np.floor(cum + 0.5), axis=0, prepend=0.0) * (INCH_M / CPI)
    per_poll_rounded = Odometry(DEFAULT_MOUNTS, "exact").integrate(polls.dt, rounded)[ends]
    # and without any quantisation: what per-poll integration alone removes
    exact_req = sim.request_samples(v, w, DEFAULT_MOUNTS, REQUEST_HZ)
    unq_req = Odometry(DEFAULT_MOUNTS, "exact").integrate(exact_req.dt, exact_req.d)
    unq_poll = Odometry(DEFAULT_MOUNTS, "exact").integrate(exact_m.dt, exact_m.d)[ends]
    out = {}
    for method in ("exact", "two-sensor"):
        per_poll = Odometry(DEFAULT_MOUNTS, method).integrate(polls.dt, polls.d)[ends]
        per_req = Odometry(DEFAULT_MOUNTS, method).integrate(requests.dt, requests.d)
        out[method] = {
            "per_poll_m_per_10m": _final_error(per_poll, requests.truth) * 10.0 / length,
            "per_request_m_per_10m": _final_error(per_req, requests.truth) * 10.0 / length,
        }
    return {
        "per_poll_15hz_error_m_per_10m": out["exact"]["per_poll_m_per_10m"],
        "per_request_15hz_error_m_per_10m": out["exact"]["per_request_m_per_10m"],
        "per_poll_15hz_by_method": out,
        "per_poll_15hz_error_m_per_10m_rounded_counts": (
            _final_error(per_poll_rounded, requests.truth) * 10.0 / length
        ),
        "per_poll_15hz_unquantised_m_per_10m": {
            "per_poll": _final_error(unq_poll, requests.truth) * 10.0 / length,
            "per_request": _final_error(unq_req, requests.truth) * 10.0 / length,
        },
        "per_poll_setup": (
            f"s_curves ({length:.2f} m), counts whole at {CPI:g} CPI per 1 ms poll with the "
            f"remainder carried, no noise; pose read at {REQUEST_HZ:g} Hz requests; "
            "final error scaled per 10 m"
        ),
    }


def _one_poll_fill(d: np.ndarray, lifted: np.ndarray) -> np.ndarray:
    """The old rule (one poll each side), for comparison."""
    out = d.copy()
    flags = lifted.tolist()
    for j in range(d.shape[1]):
        out[:, j] = lift_fill.fill_sequence(d[:, j].tolist(), flags, window=1)[0]
    return out


def lift_tour_errors() -> dict:
    """Final error on the mixed tour with sensor 0 lifted for :data:`LIFTS`."""
    v, w = sim.trajectory("mixed_tour")
    n = v.size
    lift = np.zeros((n, len(DEFAULT_MOUNTS)), dtype=bool)
    lift[:, 0] = sim.lift_mask(n, LIFTS)
    r = sim.request_samples(v, w, DEFAULT_MOUNTS, 1000.0, cpi=CPI, lifted=lift)
    clean = sim.request_samples(v, w, DEFAULT_MOUNTS, 1000.0, cpi=CPI)
    unit = INCH_M / CPI
    filled = r.d.copy()
    filled[:, 0], gaps = fill_lift_gaps(r.d[:, 0], lift[:, 0], unit=unit)
    one_poll = r.d.copy()
    one_poll[:, 0] = _one_poll_fill(r.d[:, 0], lift[:, 0])

    def err(method: str, d: np.ndarray, mask=None) -> float:
        return _final_error(
            Odometry(DEFAULT_MOUNTS, method).integrate(r.dt, d, lifted=mask), r.truth
        )

    lost = float(np.sum(lift[:, 0]) * sim.DT)
    return {
        "lift_tour_error_m_exact": err("exact", filled),
        "lift_tour_error_m_two_sensor": err("two-sensor", filled, lift),
        "lift_tour_by_rule": {
            "no_lift": {m: err(m, clean.d) for m in ("exact", "two-sensor")},
            "window_fill": {"exact": err("exact", filled), "two-sensor": err("two-sensor", filled)},
            "one_poll_fill": {m: err(m, one_poll) for m in ("exact", "two-sensor")},
            "no_fill": {m: err(m, r.d) for m in ("exact", "two-sensor")},
            "window_fill_two_sensor_masked": err("two-sensor", filled, lift),
        },
        "lift_tour_fill_sigma_m": [float(np.hypot(*s)) for _, _, s in gaps],
        "lift_tour_setup": (
            f"mixed_tour ({np.sum(np.abs(v)) * sim.DT:.2f} m), counts whole at {CPI:g} CPI per "
            f"1 ms poll, no noise; sensor 0 lifted {len(LIFTS)} times ({lost:.1f} s in all); "
            f"gaps filled from {lift_fill.WINDOW} polls each side, every poll integrated; "
            "two-sensor given the lift mask"
        ),
    }


def bench_polls_and_lifts() -> dict:
    """Both groups of figures as one JSON-ready dict (merged into ``bench_pose``)."""
    return {**per_poll_error(), **lift_tour_errors()}
