"""Pose fusion: an extended Kalman filter with odometry as motion model and fixes as corrections.

Pure numpy, no ROS, no Qt. The filter knows nothing about GPS, beacons or
compasses as devices; it takes generic measurements (a position with its 2x2
covariance, a heading, one coordinate, ranges to points of known position).
Turning NMEA or beacon replies into these is the caller's job
(:mod:`mm_pc.core.fixes`, :mod:`mm_pc.core.maps.trilateration`).

Derivations and measurements: docs/maps-and-fixes.md,
section "mm_pc.core.fusion.ekf in detail".
"""

from __future__ import annotations

import math

import numpy as np

from mm_pc.core.angles import wrap_pi
from mm_pc.core.checks import finite as _finite
from mm_pc.core.odometry import Pose2D
from mm_pc.core.uncertainty import Q_POS, Q_YAW_DIST, Q_YAW_TURN

__all__ = [
    "DEFAULT_P0",
    "GATE_1D",
    "GATE_2D",
    "PoseEKF",
    "increments_from_poses",
    "pose_increment",
]

#: chi-square 99 % quantiles for 1 and 2 degrees of freedom.
GATE_1D = 6.63
GATE_2D = 9.21

#: Default start covariance: start pose known to 1 cm and 0.01 rad (seed 004: odometry
#: needs a known start).
DEFAULT_P0 = np.diag([1e-4, 1e-4, 1e-4])

_AXES = {"x": 0, "y": 1}
_EYE3 = np.eye(3)
_AXIS_ROWS = {"x": np.array([[1.0, 0.0, 0.0]]), "y": np.array([[0.0, 1.0, 0.0]])}
_HEADING_ROW = np.array([[0.0, 0.0, 1.0]])
_POSITION_ROWS = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _sinc_half(c: float) -> tuple[float, float]:
    """k(c) = sin(c/2)/(c/2) and its derivative dk/dc."""
    h = 0.5 * c
    if abs(h) < 1e-4:
        return 1.0 - h * h / 6.0, -h / 6.0
    s, co = math.sin(h), math.cos(h)
    return s / h, (h * co - s) / (2.0 * h * h)


def pose_increment(before: Pose2D, after: Pose2D) -> tuple[float, float, float]:
    """Body increment (fwd m, left m, dtheta rad) that takes ``before`` to ``after``.

    The inverse of the arc model of :meth:`PoseEKF.predict`: predicting with
    the result from ``before`` gives ``after`` (to rounding). dtheta is the
    yaw change wrapped to (-pi, pi], so wrapped yaws (as decoded from a
    nav_msgs/Odometry quaternion) work too, as long as the robot turns less
    than pi between two poses.
    """
    try:
        vals = [float(v) for v in (before.x, before.y, before.yaw, after.x, after.y, after.yaw)]
    except (AttributeError, TypeError, ValueError):
        raise ValueError(
            f"poses must be Pose2D with numbers, got {before!r} -> {after!r}"
        ) from None
    if not all(math.isfinite(v) for v in vals):
        raise ValueError(f"poses must be finite, got {before} -> {after}")
    x0, y0, yaw0, x1, y1, yaw1 = vals
    c = wrap_pi(yaw1 - yaw0)
    k, _ = _sinc_half(c)
    m = yaw0 + 0.5 * c
    cm, sm = math.cos(m), math.sin(m)
    dx, dy = x1 - x0, y1 - y0
    return (cm * dx + sm * dy) / k, (-sm * dx + cm * dy) / k, c


def increments_from_poses(poses) -> np.ndarray:
    """(N-1, 3) body increments (fwd, left, dtheta) between consecutive rows of (N, 3) poses.

    Vectorised :func:`pose_increment`; rows are (x m, y m, yaw rad) as in a
    stream of odometry poses (continuous or wrapped yaw).
    """
    p = np.asarray(poses, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"poses must have shape (N, 3) (x, y, yaw per row), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("poses must be finite")
    d = np.diff(p, axis=0)
    c = wrap_pi(d[:, 2])
    h = 0.5 * c
    k = np.ones_like(h)
    np.divide(np.sin(h), h, out=k, where=h != 0)
    m = p[:-1, 2] + h
    cm, sm = np.cos(m), np.sin(m)
    fwd = (cm * d[:, 0] + sm * d[:, 1]) / k
    left = (-sm * d[:, 0] + cm * d[:, 1]) / k
    return np.stack([fwd, left, c], axis=1)


def _spd(name: str, value, n: int, allow_semi: bool = False) -> np.ndarray:
    """``value`` as a symmetric positive definite (or semi-definite) n x n array."""
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a {n}x{n} matrix of numbers, got {value!r}") from None
    if a.shape != (n, n):
        raise ValueError(f"{name} must have shape ({n}, {n}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {a.tolist()}")
    scale = max(float(np.max(np.abs(a))), 1e-300)
    if not np.allclose(a, a.T, rtol=0.0, atol=1e-9 * scale):
        raise ValueError(f"{name} must be symmetric, got {a.tolist()}")
    a = 0.5 * (a + a.T)
    eig = np.linalg.eigvalsh(a)
    if eig[0] < 0 or (eig[0] <= 0 and not allow_semi):
        what = "positive semi-definite" if allow_semi else "positive definite"
        raise ValueError(
            f"{name} must be {what} (variances > 0, |correlation| < 1); "
            f"smallest eigenvalue {eig[0]:.3g}, matrix {a.tolist()}"
        )
    return a


def _all_finite(*arrays: np.ndarray) -> bool:
    """True if every element is finite (a sum is NaN or inf if any element is)."""
    return all(math.isfinite(float(a.sum())) for a in arrays)


def _gate(gate: float | None) -> float | None:
    if gate is None:
        return None
    g = _finite("gate", gate)
    if g <= 0:
        raise ValueError(f"gate must be > 0 (a chi-square threshold) or None, got {g}")
    return g


def _beacon_rows(beacons) -> np.ndarray:
    """(n, 3) array of (x, y, height) from Beacon-like objects or (x, y[, h]) tuples."""
    rows = []
    for i, b in enumerate(beacons):
        vals: tuple[object, ...]
        if hasattr(b, "x") and hasattr(b, "y"):
            vals = (b.x, b.y, getattr(b, "height", 0.0))
        else:
            try:
                vals = tuple(b)
            except TypeError:
                vals = ()
            if len(vals) == 2:
                vals = (*vals, 0.0)
            if len(vals) != 3:
                raise ValueError(
                    f"beacon {i} ({b!r}) must have x, y and height (an object with those "
                    "attributes, or an (x, y) or (x, y, height) tuple in metres)"
                )
        rows.append([_finite(f"beacon {i} {n}", v) for n, v in zip("xyh", vals, strict=True)])
    return np.array(rows, dtype=float).reshape(-1, 3)


class PoseEKF:
    """Extended Kalman filter over (x, y, yaw); see the module docstring for the models.

    ``pose``: start pose (default the origin). ``P``: start covariance, 3x3
    symmetric positive definite (default :data:`DEFAULT_P0`). ``q_pos``
    (m^2/m), ``q_yaw_dist`` (rad^2/m), ``q_yaw_turn`` (rad^2/rad): the
    odometry noise model used when :meth:`predict` gets no ``q``.
    """

    def __init__(
        self,
        pose: Pose2D | None = None,
        P=None,  # noqa: N803 - the filter literature's name, as in reset()
        q_pos: float = Q_POS,
        q_yaw_dist: float = Q_YAW_DIST,
        q_yaw_turn: float = Q_YAW_TURN,
    ) -> None:
        for name, v in (("q_pos", q_pos), ("q_yaw_dist", q_yaw_dist), ("q_yaw_turn", q_yaw_turn)):
            if _finite(name, v) < 0:
                raise ValueError(f"{name} must be >= 0, got {v}")
        self.q_pos = float(q_pos)
        self.q_yaw_dist = float(q_yaw_dist)
        self.q_yaw_turn = float(q_yaw_turn)
        self._s = np.zeros(3)
        self._P = DEFAULT_P0.copy()
        #: squared Mahalanobis distance of the last update attempt (None before any).
        self.last_distance2: float | None = None
        self.reset(pose, P)

    # -- state ------------------------------------------------------------------------------

    @property
    def pose(self) -> Pose2D:
        """The estimate as a Pose2D (x, y m in the local frame; yaw rad, continuous)."""
        return Pose2D(float(self._s[0]), float(self._s[1]), float(self._s[2]))

    @property
    def state(self) -> np.ndarray:
        """A copy of the state vector (x, y, yaw)."""
        return self._s.copy()

    @property
    def covariance(self) -> np.ndarray:
        """A copy of the 3x3 covariance P of (x, y, yaw)."""
        return self._P.copy()

    def reset(self, pose: Pose2D | None = None, P=None) -> None:  # noqa: N803
        """Start over at ``pose`` (default origin) with covariance ``P`` (default DEFAULT_P0)."""
        if pose is None:
            s = np.zeros(3)
        else:
            try:
                vals = (pose.x, pose.y, pose.yaw)
            except AttributeError:
                raise ValueError(f"pose must be a Pose2D, got {pose!r}") from None
            s = np.array(
                [_finite(f"pose {n}", v) for n, v in zip(("x", "y", "yaw"), vals, strict=True)]
            )
        p = DEFAULT_P0.copy() if P is None else _spd("P", P, 3)
        self._s, self._P = s, p
        self.last_distance2 = None

    # -- predict -----------------------------------------------------------------------------

    def predict(self, fwd: float, left: float, dtheta: float, q: np.ndarray | None = None) -> None:
        """Advance by one odometry increment (fwd m, left m, dtheta rad), base_link at its start.

        ``q``: the increment's 3x3 error covariance in (fwd, left, dtheta)
        (m^2, m*rad, rad^2), symmetric positive semi-definite; None = the
        distance- and turn-proportional default model.
        """
        a = _finite("fwd", fwd)
        b = _finite("left", left)
        c = _finite("dtheta", dtheta)
        if q is None:
            d = math.hypot(a, b)
            m_cov = np.diag(
                [self.q_pos * d, self.q_pos * d, self.q_yaw_dist * d + self.q_yaw_turn * abs(c)]
            )
        else:
            m_cov = _spd("q", q, 3, allow_semi=True)
        x, y, yaw = (float(v) for v in self._s)
        # Same operation order as mm_pc.core.odometry's arc step, so noise-free runs agree exactly.
        yaw_end = yaw + c
        h = c / 2
        heading = yaw_end - h
        k = math.sin(h) / h if h != 0.0 else 1.0  # h, not c: a subnormal c halves to 0
        _, dk = _sinc_half(c)
        cm, sm = math.cos(heading), math.sin(heading)
        ex, ey = a * cm - b * sm, a * sm + b * cm
        dx, dy = k * ex, k * ey
        f = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
        g = np.array(
            [
                [k * cm, -k * sm, dk * ex - 0.5 * dy],
                [k * sm, k * cm, dk * ey + 0.5 * dx],
                [0.0, 0.0, 1.0],
            ]
        )
        p = f @ self._P @ f.T + g @ m_cov @ g.T
        p = 0.5 * (p + p.T)
        s = np.array([x + dx, y + dy, yaw_end])
        if not _all_finite(s, p):
            raise ValueError(f"increment ({a}, {b}, {c}) gives a non-finite state")
        self._s, self._P = s, p

    # -- updates -----------------------------------------------------------------------------

    def _update(
        self,
        nu: np.ndarray,
        h: np.ndarray,
        r: np.ndarray,
        gate: float | None,
        r_gate: np.ndarray | None = None,
    ) -> bool:
        """Gated Joseph-form update with innovation nu (m,), H (m, 3), R (m, m).

        ``r_gate``: the R the gate tests against, if not ``r``.
        """
        p = self._P
        hph = h @ p @ h.T
        s_mat = hph + r
        s_inv = 1.0 / s_mat if s_mat.shape == (1, 1) else np.linalg.inv(s_mat)
        gate_inv = s_inv if r_gate is None else np.linalg.inv(hph + r_gate)
        d2 = float(nu @ gate_inv @ nu)
        self.last_distance2 = d2
        if gate is not None and not d2 <= gate:
            return False
        k = p @ h.T @ s_inv
        i_kh = _EYE3 - k @ h
        p_new = i_kh @ p @ i_kh.T + k @ r @ k.T
        p_new = 0.5 * (p_new + p_new.T)
        s_new = self._s + k @ nu
        if not _all_finite(s_new, p_new):
            raise ValueError("update gives a non-finite state; measurement or covariance too large")
        self._s, self._P = s_new, p_new
        return True

    def update_position(self, xy, cov2x2, gate: float | None = GATE_2D, gate_cov=None) -> bool:
        """Position fix (x, y) m in the local frame with its 2x2 covariance (m^2).

        ``gate_cov``: optional 2x2 covariance (m^2) to gate with instead of
        ``cov2x2``. For fixes with time-correlated errors (GPS), whose
        ``cov2x2`` is inflated so that a stream of them is not taken for
        independent information, gate with the single fix's own accuracy.
        Returns True if applied, False if the fix failed the gate (state unchanged).
        """
        try:
            pair = [float(v) for v in xy]
        except (TypeError, ValueError):
            raise ValueError(f"xy must be two numbers (x, y) in metres, got {xy!r}") from None
        if len(pair) != 2:
            raise ValueError(f"xy must be two numbers (x, y) in metres, got {xy!r}")
        z = np.array([_finite("fix x", pair[0]), _finite("fix y", pair[1])])
        r = _spd("cov2x2", cov2x2, 2)
        r_gate = None if gate_cov is None else _spd("gate_cov", gate_cov, 2)
        g = _gate(gate)
        return self._update(z - self._s[:2], _POSITION_ROWS, r, g, r_gate)

    def update_heading(self, yaw: float, var: float, gate: float | None = GATE_1D) -> bool:
        """Absolute heading ``yaw`` (rad, REP 103, any wrap) with variance ``var`` (rad^2)."""
        z = _finite("yaw", yaw)
        v = _finite("var", var)
        if v <= 0:
            raise ValueError(f"heading variance must be > 0 rad^2, got {v}")
        g = _gate(gate)
        nu = np.array([wrap_pi(z - float(self._s[2]))])
        return self._update(nu, _HEADING_ROW, np.array([[v]]), g)

    def update_axis(self, axis: str, value: float, var: float, gate: float | None = None) -> bool:
        """One absolute coordinate: ``axis`` 'x' or 'y' is ``value`` m, variance ``var`` m^2.

        For a perimeter-wire contact on a wire along x = const or y = const
        (seed 004). Ungated by default: a wire contact is trusted even when
        odometry has drifted far; pass ``gate`` (e.g. GATE_1D) to gate it.
        """
        if axis not in _AXES:
            raise ValueError(f"axis must be 'x' or 'y', got {axis!r}")
        z = _finite("value", value)
        v = _finite("var", var)
        if v <= 0:
            raise ValueError(f"axis variance must be > 0 m^2, got {v}")
        g = _gate(gate)
        i = _AXES[axis]
        return self._update(np.array([z - float(self._s[i])]), _AXIS_ROWS[axis], np.array([[v]]), g)

    def update_ranges(self, beacons, ranges, sigma, gate: float | None = GATE_1D) -> bool:
        """Ranges (m) to beacons of known position, used directly (tightly coupled).

        ``beacons``: objects with ``x``, ``y``, ``height`` (m, local frame;
        height above the robot's range antenna) such as
        ``mm_pc.core.maps.trilateration.Beacon``, or (x, y[, height]) tuples.
        ``ranges``: measured 3-D distances (m), one per beacon. ``sigma``: the
        range noise (m), one for all or one per beacon. Each range is gated
        on its own (``gate`` is a 1-dof threshold); the ones that pass are
        applied together. Returns True if at least one range was applied.
        """
        bx = _beacon_rows(beacons)
        n = bx.shape[0]
        if n == 0:
            raise ValueError("update_ranges needs at least one beacon")
        try:
            z = np.array(ranges, dtype=float).reshape(-1)
            sig = np.broadcast_to(np.array(sigma, dtype=float), (n,)).copy()
        except (TypeError, ValueError):
            raise ValueError(
                f"ranges must be {n} numbers (m) and sigma one number or {n} numbers (m), "
                f"got {ranges!r}, {sigma!r}"
            ) from None
        if z.shape != (n,):
            raise ValueError(f"got {z.size} range(s) for {n} beacon(s); give one range per beacon")
        if not (np.all(np.isfinite(z)) and np.all(z >= 0)):
            raise ValueError(f"ranges must be finite and >= 0 m, got {z.tolist()}")
        if not (np.all(np.isfinite(sig)) and np.all(sig > 0)):
            raise ValueError(f"sigma must be finite and > 0 m, got {sig.tolist()}")
        g = _gate(gate)
        ddx = self._s[0] - bx[:, 0]
        ddy = self._s[1] - bx[:, 1]
        pred = np.sqrt(ddx * ddx + ddy * ddy + bx[:, 2] ** 2)
        ok = pred > 1e-9  # on top of a beacon of height 0 the range has no gradient
        h = np.zeros((n, 3))
        h[ok, 0] = ddx[ok] / pred[ok]
        h[ok, 1] = ddy[ok] / pred[ok]
        nu = z - pred
        var = sig * sig
        s_diag = np.einsum("ij,jk,ik->i", h, self._P, h) + var
        d2 = nu * nu / s_diag
        if g is not None:
            ok &= d2 <= g
        if not np.any(ok):
            self.last_distance2 = float(np.min(d2))
            return False
        return self._update(nu[ok], h[ok], np.diag(var[ok]), None)
