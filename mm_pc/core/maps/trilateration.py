"""Position fix from measured ranges to navigation beacons (trilateration).

Units and frames: metres and radians throughout. Beacon and robot positions
are (x, y) in one fixed local plane frame per REP 103 (x east/forward, y
north/left, angles counter-clockwise from +x). A beacon's ``height`` is how
far it sits above the robot's sensor plane (m). Ranges are the measured
slant distances (m) from the robot's sensor to each beacon, e.g. by time of
flight.

Derivations and measurements: docs/maps-and-fixes.md,
section "mm_pc.core.maps.trilateration in detail".
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MAX_RESIDUAL_SIGMAS",
    "Beacon",
    "Fix",
    "TrilaterationError",
    "best_three",
    "least_squares_fix",
    "pair_candidates",
    "plane_distances",
    "seed_fix",
    "simulate_ranges",
]

MAX_RESIDUAL_SIGMAS = 10.0
"""Least squares rejects a fix whose RMS range residual exceeds this many sigma."""

_COLLINEAR_TOL = 1e-9  # smallest/largest singular value of centred beacon positions
_GN_MAX_ITER = 30
_GN_STEP_TOL = 1e-10  # m, relative to the field scale (plus 1 m)
_GN_MAX_HALVINGS = 30


@dataclass(frozen=True)
class Beacon:
    """A navigation beacon: plane position (m, REP 103 local frame) and height (m).

    ``height`` is measured from the robot's sensor plane (negative = below it;
    only |height| matters). ``name`` is for messages only.
    """

    x: float
    y: float
    height: float = 0.0
    name: str = ""

    def __post_init__(self) -> None:
        for field in ("x", "y", "height"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
                raise TrilaterationError(f"Beacon {field} must be a real number (m), got {value!r}")
            if not math.isfinite(value):
                raise TrilaterationError(f"Beacon {field} must be finite (m), got {value}")


@dataclass(frozen=True)
class Fix:
    """A position fix (m, REP 103 local frame).

    ``quality``: for ``method == "seed"`` the seed's |z|_min (m, agreement of
    the two beacon pairs); for ``"least_squares"`` the RMS slant-range
    residual (m). Smaller is better for both. ``covariance``: 2x2 of (x, y)
    in m^2, or None (the seed's method has none). ``used``: indices of the
    beacons that made the fix.
    """

    x: float
    y: float
    quality: float
    covariance: tuple[tuple[float, float], tuple[float, float]] | None
    used: tuple[int, ...]
    method: str


class TrilaterationError(ValueError):
    """Input that admits no position fix, or a fix rejected as too poor."""


# ---------------------------------------------------------------- angles


# ---------------------------------------------------------------- validation


def _beacon_arrays(beacons: Sequence[Beacon]) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) positions and (N,) |heights| (m) of validated beacons."""
    try:
        items = list(beacons)
    except TypeError:
        raise TrilaterationError(
            f"beacons must be a sequence of Beacon, got {type(beacons).__name__}"
        ) from None
    for i, b in enumerate(items):
        if not isinstance(b, Beacon):
            raise TrilaterationError(f"beacons[{i}] must be a Beacon, got {type(b).__name__}")
    xy = np.array([(b.x, b.y) for b in items], dtype=float).reshape(-1, 2)
    h = np.abs(np.array([b.height for b in items], dtype=float))
    return xy, h


def _range_array(ranges, n: int) -> np.ndarray:
    """Validated slant ranges (m) as a fresh float array of length ``n``."""
    try:
        r = np.array(ranges, dtype=float)
    except (TypeError, ValueError):
        raise TrilaterationError(f"ranges must be numbers (m), got {ranges!r}") from None
    if r.ndim != 1:
        raise TrilaterationError(f"ranges must be a 1-D sequence (m), got shape {r.shape}")
    if len(r) != n:
        raise TrilaterationError(
            f"got {len(r)} ranges for {n} beacons; need exactly one range per beacon"
        )
    bad = np.flatnonzero(~np.isfinite(r))
    if bad.size:
        raise TrilaterationError(f"ranges must be finite (m); ranges[{bad[0]}] = {r[bad[0]]}")
    neg = np.flatnonzero(r < 0)
    if neg.size:
        raise TrilaterationError(f"ranges must be >= 0 m; ranges[{neg[0]}] = {r[neg[0]]}")
    return r


def _point(p, what: str) -> np.ndarray:
    try:
        a = np.array(p, dtype=float)
    except (TypeError, ValueError):
        raise TrilaterationError(f"{what} must be (x, y) in m, got {p!r}") from None
    if a.shape != (2,) or not np.all(np.isfinite(a)):
        raise TrilaterationError(f"{what} must be two finite numbers (x, y) in m, got {p!r}")
    return a


def _need_three(n: int) -> None:
    if n < 3:
        raise TrilaterationError(f"need at least 3 beacons for a 2-D fix, got {n}")


def _collinear(xy: np.ndarray) -> np.ndarray | bool:
    """True if the points (..., N, 2) span less than a plane (relative tolerance).

    Stacks of point sets give one answer per set.
    """
    s = np.linalg.svd(xy - xy.mean(axis=-2, keepdims=True), compute_uv=False)
    flat = (s[..., 0] == 0.0) | (s[..., -1] <= _COLLINEAR_TOL * s[..., 0])
    return bool(flat) if flat.ndim == 0 else flat


def _require_not_collinear(xy: np.ndarray, which: str) -> None:
    if _collinear(xy):
        raise TrilaterationError(
            f"{which} are collinear (or coincide): their ranges cannot tell a point from its "
            "mirror image across that line; use beacons that span a triangle"
        )


# ---------------------------------------------------------------- plane distances


def plane_distances(beacons: Sequence[Beacon], ranges) -> np.ndarray:
    """Slant ranges (m) -> distances in the robot's plane, ``sqrt(r^2 - h^2)`` (m).

    Raises :class:`TrilaterationError` if lengths differ, a range is not
    finite or negative, or a range is shorter than its beacon's |height|.
    """
    return _validated(beacons, ranges)[3]


def _validated(beacons: Sequence[Beacon], ranges):
    """(positions (N, 2), |heights|, slant ranges, plane distances), all validated, m."""
    xy, h = _beacon_arrays(beacons)
    r = _range_array(ranges, len(xy))
    short = np.flatnonzero(r < h)
    if short.size:
        i = short[0]
        raise TrilaterationError(
            f"range {r[i]:.6g} m to beacon {_label(beacons, i)} is shorter than its height "
            f"{h[i]:.6g} m; a slant range must be >= |height|"
        )
    return xy, h, r, np.sqrt((r - h) * (r + h))


def _label(beacons: Sequence[Beacon], i: int) -> str:
    name = list(beacons)[i].name
    return f"{i} ({name})" if name else str(i)


# ---------------------------------------------------------------- the seed's method


def pair_candidates(a, b, l_a: float, l_b: float) -> tuple[np.ndarray, float]:
    """The two candidate robot positions from one beacon pair (law of cosines).

    ``a``, ``b``: beacon plane positions (x, y) in m; ``l_a``, ``l_b``: plane
    distances (m). Returns ``(candidates, gap)``: a (2, 2) array, row 0 left
    of the direction a->b (theta_AB + delta), row 1 right of it, and by how
    many metres the two circles miss each other (0 if they meet). When they
    miss, both rows are the point of circle a on the line ab nearest circle b.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    ab = b - a
    d = math.hypot(ab[0], ab[1])
    if d == 0.0:
        raise TrilaterationError(f"beacons at {tuple(a)} and {tuple(b)} coincide")
    gap = max(0.0, d - (l_a + l_b), abs(l_a - l_b) - d)
    if l_a == 0.0:
        return np.array([a, a]), gap
    cos_delta = (l_a * l_a + d * d - l_b * l_b) / (2.0 * l_a * d)
    delta = math.acos(min(1.0, max(-1.0, cos_delta)))
    theta_ab = math.atan2(ab[1], ab[0])
    angles = np.array([theta_ab + delta, theta_ab - delta])
    return a + l_a * np.column_stack((np.cos(angles), np.sin(angles))), gap


def seed_fix(beacons: Sequence[Beacon], ranges, s_phi: float = 0.5) -> Fix:
    """The seed's fix: candidate pairs over beacons (a, b) and (b, c), the closest wins.

    ``ranges``: slant ranges (m), one per beacon. With N > 3 beacons the
    three of :func:`best_three` are used (``near`` = the linear least-squares
    estimate). ``s_phi`` (m): the seed's threshold S_phi; the fix is rejected
    if its quality |z|_min or a circle pair's miss distance exceeds it.
    Returns a :class:`Fix` with ``method="seed"``, ``covariance=None`` and
    ``used`` = the three indices (a, b, c).
    """
    if isinstance(s_phi, bool) or not isinstance(s_phi, (int, float)) or not s_phi >= 0:
        raise TrilaterationError(f"s_phi must be a number >= 0 m (inf disables), got {s_phi!r}")
    xy, _, _, dist = _validated(beacons, ranges)
    _need_three(len(xy))
    if len(xy) == 3:
        _require_not_collinear(xy, "the 3 beacons")
        used = (0, 1, 2)
    else:
        _require_not_collinear(xy, f"all {len(xy)} beacons")
        used = best_three(beacons, near=_linear_estimate(xy, dist))
    ia, ib, ic = used
    first, gap1 = pair_candidates(xy[ia], xy[ib], dist[ia], dist[ib])
    second, gap2 = pair_candidates(xy[ib], xy[ic], dist[ib], dist[ic])
    for (i, j), gap in (((ia, ib), gap1), ((ib, ic), gap2)):
        if gap > s_phi:
            raise TrilaterationError(
                f"ranges to beacons {_label(beacons, i)} and {_label(beacons, j)} do not "
                f"intersect: their plane circles miss by {gap:.6g} m > s_phi = {s_phi:g} m"
            )
    z = np.linalg.norm(first[:, None, :] - second[None, :, :], axis=2)
    m, _ = np.unravel_index(np.argmin(z), z.shape)
    quality = float(z.min())
    if quality > s_phi:
        raise TrilaterationError(
            f"fix rejected: quality |z|_min = {quality:.6g} m > s_phi = {s_phi:g} m "
            f"(beacons {used}); the two beacon pairs disagree"
        )
    return Fix(float(first[m, 0]), float(first[m, 1]), quality, None, used, "seed")


# ---------------------------------------------------------------- choice of three


def best_three(beacons: Sequence[Beacon], near=None) -> tuple[int, int, int]:
    """Indices (ascending) of the best three beacons by geometry.

    With ``near`` = (x, y) in m: smallest 2-D GDOP of the slant ranges at
    ``near``. Without: largest smallest interior angle of the beacon
    triangle. Collinear triples are never chosen; if all are collinear, or
    there are fewer than 3 beacons, :class:`TrilaterationError`.
    """
    xy, h = _beacon_arrays(beacons)
    _need_three(len(xy))
    p = None if near is None else _point(near, "near")
    triples = np.array(list(itertools.combinations(range(len(xy)), 3)))
    min_angle = _min_interior_angles(xy[triples])
    ok = ~np.asarray(_collinear(xy[triples]))  # one flag per triple
    if not ok.any():
        raise TrilaterationError(
            f"all {len(xy)} beacons are collinear (or coincide); need three that span a triangle"
        )
    score = -min_angle
    if p is not None:
        gdop = _gdop(xy, h, triples, p)
        if np.isfinite(gdop[ok]).any():
            score = gdop
    score = np.where(ok & np.isfinite(score), score, np.inf)
    best = triples[int(np.argmin(score))]
    return int(best[0]), int(best[1]), int(best[2])


def _min_interior_angles(tri: np.ndarray) -> np.ndarray:
    """Smallest interior angle (rad) of each triangle in a (T, 3, 2) array."""
    angles = []
    for k in range(3):
        u = tri[:, (k + 1) % 3] - tri[:, k]
        v = tri[:, (k + 2) % 3] - tri[:, k]
        cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        angles.append(np.arctan2(cross, np.einsum("ij,ij->i", u, v)))
    return np.min(angles, axis=0)


def _gdop(xy: np.ndarray, h: np.ndarray, triples: np.ndarray, p: np.ndarray) -> np.ndarray:
    """2-D GDOP of slant ranges at ``p`` for each triple (inf where singular)."""
    diff = p - xy
    r = np.sqrt(np.einsum("ij,ij->i", diff, diff) + h * h)
    g = np.divide(diff, r[:, None], out=np.zeros_like(diff), where=r[:, None] > 0)
    gt = g[triples]  # (T, 3, 2)
    m = np.einsum("tki,tkj->tij", gt, gt)
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] ** 2
    trace = m[:, 0, 0] + m[:, 1, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        gdop = np.sqrt(trace / det)
    return np.where(det > 1e-12 * np.maximum(trace, 1e-300) ** 2, gdop, np.inf)


# ---------------------------------------------------------------- least squares


def _linear_estimate(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Position (m) from differenced squared plane distances (see module docstring, 5)."""
    c = xy.mean(axis=0)
    b = xy - c
    bb = np.einsum("ij,ij->i", b, b)
    ll = dist * dist
    rhs = bb - bb.mean() - ll + ll.mean()
    q, *_ = np.linalg.lstsq(2.0 * b, rhs, rcond=None)
    return q + c


def _slant(xy: np.ndarray, h: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted slant ranges (m) at ``p`` and their Jacobian rows d r / d(x, y)."""
    diff = p - xy
    r = np.sqrt(np.einsum("ij,ij->i", diff, diff) + h * h)
    jac = np.divide(diff, r[:, None], out=np.zeros_like(diff), where=r[:, None] > 0)
    return r, jac


def _normal_solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least-squares solution of the (N, 2) system a x = b via the 2x2 normal equations."""
    (p, q), (_, r) = a.T @ a
    u, v = a.T @ b
    det = p * r - q * q
    if not det > 1e-12 * (p + r) ** 2:
        return np.linalg.lstsq(a, b, rcond=None)[0]
    return np.array([(r * u - q * v) / det, (p * v - q * u) / det])


def _gauss_newton(xy: np.ndarray, h: np.ndarray, r_meas: np.ndarray, p: np.ndarray):
    """Least-squares position on the slant ranges; returns (p, residuals, Jacobian)."""
    tol = _GN_STEP_TOL * (1.0 + float(np.ptp(xy, axis=0).max()))
    r, jac = _slant(xy, h, p)
    res = r_meas - r
    cost = float(res @ res)
    for _ in range(_GN_MAX_ITER):
        step = _normal_solve(jac, res)
        if not np.all(np.isfinite(step)):
            raise TrilaterationError("least squares diverged (non-finite step); check the input")
        for _ in range(_GN_MAX_HALVINGS):
            r_new, jac_new = _slant(xy, h, p + step)
            res_new = r_meas - r_new
            cost_new = float(res_new @ res_new)
            if cost_new <= cost:
                break
            step = step / 2
        else:  # no step lowers the cost: p is the minimum to machine precision
            return p, res, jac
        p, res, jac, cost = p + step, res_new, jac_new, cost_new
        if math.hypot(step[0], step[1]) <= tol:
            return p, res, jac
    raise TrilaterationError(
        f"least squares did not converge in {_GN_MAX_ITER} Gauss-Newton steps; the geometry "
        "is too poor for these ranges"
    )


def least_squares_fix(beacons: Sequence[Beacon], ranges, sigma: float = 0.05, initial=None) -> Fix:
    """Least-squares fix from all N >= 3 beacons, with its covariance.

    ``ranges``: slant ranges (m), one per beacon; ``sigma``: their 1-sigma
    noise (m), > 0; ``initial``: optional start (x, y) in m, else the linear
    (differenced squares) estimate. Returns a :class:`Fix` with
    ``method="least_squares"``, ``quality`` = RMS range residual (m),
    ``covariance`` = sigma^2 (J^T J)^-1 (m^2) and ``used`` = all indices.
    """
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float)):
        raise TrilaterationError(f"sigma must be a number > 0 m, got {sigma!r}")
    if not (math.isfinite(sigma) and sigma > 0):
        raise TrilaterationError(f"sigma must be finite and > 0 m, got {sigma!r}")
    xy, h, r_meas, dist = _validated(beacons, ranges)
    _need_three(len(xy))
    _require_not_collinear(xy, f"all {len(xy)} beacons" if len(xy) > 3 else "the 3 beacons")
    p0 = _linear_estimate(xy, dist) if initial is None else _point(initial, "initial")
    p, res, jac = _gauss_newton(xy, h, r_meas, p0)
    rms = float(np.sqrt(np.mean(res * res)))
    if rms > MAX_RESIDUAL_SIGMAS * sigma:
        raise TrilaterationError(
            f"ranges do not intersect: the best point ({p[0]:.4g}, {p[1]:.4g}) m leaves an RMS "
            f"range residual of {rms:.6g} m > {MAX_RESIDUAL_SIGMAS:g} * sigma = "
            f"{MAX_RESIDUAL_SIGMAS * sigma:.6g} m; is a range or a beacon position wrong?"
        )
    info = jac.T @ jac
    if np.linalg.cond(info) > 1e12:
        raise TrilaterationError(
            "the fix is at a point where the ranges do not constrain both x and y "
            "(singular geometry); no covariance"
        )
    cov = sigma * sigma * np.linalg.inv(info)
    cov = 0.5 * (cov + cov.T)
    covariance = ((float(cov[0, 0]), float(cov[0, 1])), (float(cov[1, 0]), float(cov[1, 1])))
    return Fix(float(p[0]), float(p[1]), rms, covariance, tuple(range(len(xy))), "least_squares")


# ---------------------------------------------------------------- simulation


def simulate_ranges(beacons: Sequence[Beacon], x: float, y: float, sigma: float, rng) -> np.ndarray:
    """Slant ranges (m) from the robot at (x, y) (m) to each beacon, plus N(0, sigma^2) noise.

    ``rng``: a ``numpy.random.Generator`` or a seed for one. The noise is not
    clipped, so a large ``sigma`` can give a range shorter than a height.
    """
    xy, h = _beacon_arrays(beacons)
    p = _point((x, y), "robot position")
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) or not sigma >= 0:
        raise TrilaterationError(f"sigma must be a number >= 0 m, got {sigma!r}")
    if not math.isfinite(sigma):
        raise TrilaterationError(f"sigma must be finite, got {sigma!r}")
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    r, _ = _slant(xy, h, p)
    return r + gen.normal(0.0, sigma, size=len(r))
