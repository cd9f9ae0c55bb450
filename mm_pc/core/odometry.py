"""Robot pose from mouse-sensor displacements: four methods, one interface (:data:`METHODS`).

Poses are odom -> base_link (REP 103/105), yaw kept continuous; each sample is the
displacement every sensor counted in its own frame (X right, Y forward), in metres, as
reported. ``exact`` is the default; the seed's two approaches are kept to compare.

Derivations and measurements: docs/pose-math.md,
section "mm_pc.core.odometry in detail".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mm_pc.core.angles import wrap_pi
from mm_pc.core.geometry import SensorMount

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "Odometry",
    "Pose2D",
    "Sample",
    "arc_poses",
    "compose",
    "inverse",
]

DEFAULT_METHOD = "exact"


@dataclass(frozen=True)
class Pose2D:
    """Planar pose of base_link in odom: x, y in metres, yaw in rad (CCW+, continuous)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    @property
    def yaw_wrapped(self) -> float:
        """Yaw wrapped into (-pi, pi] (rad), the convention of :mod:`mm_pc.core.angles`."""
        return wrap_pi(self.yaw)

    def as_array(self) -> np.ndarray:
        """``np.array([x, y, yaw])``."""
        return np.array([self.x, self.y, self.yaw], dtype=float)


def compose(a: Pose2D, b: Pose2D) -> Pose2D:
    """``a * b``: pose ``b`` (given in ``a``'s child frame) expressed in ``a``'s parent frame.

    E.g. map_T_odom * odom_T_base = map_T_base (metres, rad; yaws add, not wrapped).
    """
    c, s = math.cos(a.yaw), math.sin(a.yaw)
    return Pose2D(a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y, a.yaw + b.yaw)


def inverse(p: Pose2D) -> Pose2D:
    """The inverse transform: parent in child (``compose(p, inverse(p))`` is the identity)."""
    c, s = math.cos(p.yaw), math.sin(p.yaw)
    return Pose2D(-c * p.x - s * p.y, s * p.x - c * p.y, -p.yaw)


@dataclass(frozen=True)
class Sample:
    """One request interval: what the Beagle node served for it.

    ``dt``: length of the interval in seconds (> 0).
    ``d``: per sensor, in mount order, the sensor-frame displacement
    (dX right, dY forward) in metres counted during the interval.
    ``lifted``: per sensor, True if it was lifted during the interval (its
    ``d`` is then not a measurement: what it counted, or a gap-filled estimate);
    None = nobody lifted.
    """

    dt: float
    d: tuple[tuple[float, float], ...]
    lifted: tuple[bool, ...] | None = None

    @classmethod
    def of(
        cls, dt: float, *displacements: Sequence[float], lifted: Sequence[bool] | None = None
    ) -> Sample:
        """``Sample.of(0.01, (dx1, dy1), (dx2, dy2))``, optionally ``lifted=(False, True)``."""
        return cls(
            float(dt),
            tuple((float(p[0]), float(p[1])) for p in displacements),
            None if lifted is None else tuple(bool(v) for v in lifted),
        )


# --- shared kinematics ---------------------------------------------------------------


def _cumsum_from(start: float, steps: np.ndarray) -> np.ndarray:
    """start + running sum of ``steps``, summed in the same order as a loop would."""
    buf = np.empty(steps.size + 1)
    buf[0] = start
    buf[1:] = steps
    np.cumsum(buf, out=buf)
    return buf[1:]


def arc_poses(
    start: Sequence[float], a: np.ndarray, b: np.ndarray | None, c: np.ndarray
) -> np.ndarray:
    """Poses after each body increment (a fwd m, b left m, c rad), constant twist each.

    The displacement of a constant twist over one interval, seen in odom, is
    the body vector (a, b) shortened by sinc(c/2) = sin(c/2)/(c/2) and turned
    to the mid-interval heading yaw + c/2. ``b`` None means no lateral part.
    Returns an (N, 3) array of (x, y, yaw) after each step.
    """
    x0, y0, yaw0 = (float(v) for v in start)
    out = np.empty((c.size, 3))
    yaw_end = _cumsum_from(yaw0, c)
    out[:, 2] = yaw_end
    h = c * 0.5
    heading = yaw_end - h
    k = np.sin(h)
    np.divide(k, h, out=k, where=h != 0)
    k[h == 0] = 1.0
    ca, sa = np.cos(heading), np.sin(heading)
    ka = k * a
    if b is None:
        dx, dy = ka * ca, ka * sa
    else:
        kb = k * b
        dx, dy = ka * ca - kb * sa, ka * sa + kb * ca
    out[:, 0] = _cumsum_from(x0, dx)
    out[:, 1] = _cumsum_from(y0, dy)
    return out


def _arc_step(pose, a: float, b: float, c: float) -> tuple[float, float, float]:
    """One :func:`arc_poses` step in plain floats."""
    x, y, yaw = pose
    yaw_end = yaw + c
    h = c / 2
    heading = yaw_end - h
    k = math.sin(h) / h if h != 0.0 else 1.0  # h, not c: a subnormal c halves to 0
    ca, sa = math.cos(heading), math.sin(heading)
    return x + k * (a * ca - b * sa), y + k * (a * sa + b * ca), yaw_end


def _euler_poses(
    start: Sequence[float], fwd: np.ndarray, c: np.ndarray, heading_after_turn: bool
) -> np.ndarray:
    """Poses for straight-line steps: turn by c and move ``fwd`` along one heading.

    ``heading_after_turn``: move along the heading after the turn (the seed's
    rotate() then forward()); otherwise along the heading before it (Euler).
    """
    x0, y0, yaw0 = (float(v) for v in start)
    out = np.empty((c.size, 3))
    yaw_end = _cumsum_from(yaw0, c)
    out[:, 2] = yaw_end
    heading = yaw_end if heading_after_turn else yaw_end - c
    out[:, 0] = _cumsum_from(x0, fwd * np.cos(heading))
    out[:, 1] = _cumsum_from(y0, fwd * np.sin(heading))
    return out


# --- methods -----------------------------------------------------------------------------
#
# A method turns ideal-frame displacements d (N, n_sensors, 2) and dt (N,) into
# poses (N, 3) from a start pose, plus a per-sample residual (N,) or None.


class _Method:
    name = ""
    uses_all_sensors = False

    def __init__(self, mounts: tuple[SensorMount, ...], sensor: int) -> None:
        self.mounts = mounts
        self.sensor = sensor

    def poses(self, start, dt: np.ndarray, d: np.ndarray):  # pragma: no cover - abstract
        """Vectorised: (N, 3) poses and (N,) residuals or None."""
        raise NotImplementedError

    def step(self, pose, dt: float, d: list[tuple[float, float]]):  # pragma: no cover
        """One sample in plain floats: (x, y, yaw, residual or None)."""
        raise NotImplementedError

    def body_map(self, lifted=None) -> np.ndarray:  # pragma: no cover - abstract
        """(3, 2n) linear map of one sample's counts (m) to (a, b, c); see Odometry.body_map."""
        raise NotImplementedError


def _no_slip_map(mounts, i: int) -> np.ndarray:
    """(3, 2n): equation (2) of sensor ``i`` as a linear map from all counts
    (dX1, dY1, ...) to (a, b, c): a = dY + (sx/sy)*dX, b = 0, c = -dX/sy."""
    sx, sy = mounts[i].right, mounts[i].forward
    out = np.zeros((3, 2 * len(mounts)))
    out[0, 2 * i], out[0, 2 * i + 1] = sx / sy, 1.0
    out[2, 2 * i] = -1.0 / sy
    return out


class _OneSensor(_Method):
    """Shared set-up of the one-sensor methods: the seed's sx, sy, yaw observable."""

    def __init__(self, mounts, sensor):
        super().__init__(mounts, sensor)
        m = mounts[sensor]
        self.sx, self.sy = m.right, m.forward
        if self.sy == 0:
            raise ValueError(
                f"sensor {sensor} at base_link ({m.x} m, {m.y} m) lies on the axle line "
                "(0 m forward of the axle centre): a turn moves it only forward, so one "
                "sensor cannot tell turning from driving and yaw is unobservable; "
                "mount it forward or behind the axle, or use method 'two-sensor'"
            )

    def split(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact no-slip split: forward a (m) and dtheta c (rad) per interval."""
        dx, dy = d[:, self.sensor, 0], d[:, self.sensor, 1]
        c = -dx / self.sy
        a = dy + (self.sx / self.sy) * dx
        return a, c

    def body_map(self, lifted=None) -> np.ndarray:
        """(3, 2n): :func:`_no_slip_map` of the sensor (a lift changes nothing: the
        seed's methods use their sensor's data as given; ``exact`` overrides this)."""
        return _no_slip_map(self.mounts, self.sensor)

    def split1(self, d) -> tuple[float, float]:
        """:meth:`split` for one sample of plain floats."""
        dx, dy = d[self.sensor]
        return dy + (self.sx / self.sy) * dx, -dx / self.sy


class _Exact(_OneSensor):
    """No-slip split of one sensor; while that sensor is lifted, of another one.

    A lifted sensor's counts are nothing or a gap-filled guess, so for a sample in
    which its own sensor is lifted ``exact`` takes the first sensor (in mount order)
    that is not lifted and not on the axle line, with that sensor's own split, and
    goes back to its own sensor with the first sample it sees again. With every
    sensor lifted it uses its own sensor's data as given (fill the gaps first).
    """

    name = "exact"

    def __init__(self, mounts, sensor):
        super().__init__(mounts, sensor)
        self._sx = np.array([m.right for m in mounts])
        self._sy = np.array([m.forward for m in mounts])
        #: samples integrated with another sensor than ``sensor`` (its own was lifted)
        self.switched = 0

    def pick(self, lifted: tuple[bool, ...]) -> int:
        """The sensor whose split a sample with these lift flags uses."""
        if not lifted[self.sensor]:
            return self.sensor
        for i, flag in enumerate(lifted):
            if not flag and self.mounts[i].forward != 0:
                return i
        return self.sensor

    def body_map(self, lifted=None) -> np.ndarray:
        """(3, 2n): :func:`_no_slip_map` of the sensor :meth:`pick` chooses."""
        i = self.sensor if lifted is None else self.pick(tuple(lifted))
        return _no_slip_map(self.mounts, i)

    def poses(self, start, dt, d):
        a, c = self.split(d)
        return arc_poses(start, a, None, c), None

    def poses_lifted(self, start, dt, d, lifted: np.ndarray):
        """:meth:`poses` with each sample's sensor chosen by :meth:`pick`."""
        use = np.full(len(d), self.sensor)
        for pattern in np.unique(lifted[lifted[:, self.sensor]], axis=0):
            rows = np.all(lifted == pattern, axis=1)
            use[rows] = self.pick(tuple(bool(v) for v in pattern))
        self.switched += int(np.count_nonzero(use != self.sensor))
        rows = np.arange(len(d))
        dx, dy = d[rows, use, 0], d[rows, use, 1]
        c = -dx / self._sy[use]
        a = dy + (self._sx[use] / self._sy[use]) * dx  # the same floats as split()'s
        return arc_poses(start, a, None, c), None

    def step(self, pose, dt, d):
        a, c = self.split1(d)
        return (*_arc_step(pose, a, 0.0, c), None)

    def step_lifted(self, pose, dt, d, lifted: tuple[bool, ...]):
        """:meth:`step` with the sensor chosen by :meth:`pick`."""
        i = self.pick(lifted)
        if i == self.sensor:
            return self.step(pose, dt, d)
        self.switched += 1
        m = self.mounts[i]
        dx, dy = d[i]
        return (*_arc_step(pose, dy + (m.right / m.forward) * dx, 0.0, -dx / m.forward), None)


class _SeedApproach2(_OneSensor):
    name = "seed-approach2"

    def poses(self, start, dt, d):
        a, c = self.split(d)
        v, omega = a / dt, c / dt  # the seed's speeds from its time stamps
        return _euler_poses(start, v * dt, omega * dt, heading_after_turn=False), None

    def step(self, pose, dt, d):
        a, c = self.split1(d)
        v, omega = a / dt, c / dt
        x, y, yaw = pose
        f = v * dt
        return x + f * math.cos(yaw), y + f * math.sin(yaw), yaw + omega * dt, None


class _SeedApproach1(_OneSensor):
    """The original move(), read with rotate(+) = CCW (REP 103)."""

    name = "seed-approach1"

    def __init__(self, mounts, sensor):
        super().__init__(mounts, sensor)
        m = mounts[sensor]
        self.m = m.slope  # -sx/sy
        self.radius = m.radius
        self.hyp_m = math.hypot(1.0, self.m)

    def poses(self, start, dt, d):
        dx, dy = d[:, self.sensor, 0], d[:, self.sensor, 1]
        # Vx_r = dX, Vy_r = dX*m, Vdist_r = hypot(Vx_r, Vy_r) = |dX|*hypot(1, m)
        vdist_r = np.abs(dx) * self.hyp_m
        rotate_angle = vdist_r / self.radius
        c = np.where(dx >= 0, rotate_angle, -rotate_angle)  # the seed's turn sign
        vdist_f = np.hypot(dx, dy) - vdist_r  # Vdist_rf - Vdist_r: lengths subtracted
        fwd = np.where(dy < 0, -vdist_f, vdist_f)
        return _euler_poses(start, fwd, c, heading_after_turn=True), None

    def step(self, pose, dt, d):
        dx, dy = d[self.sensor]
        vdist_r = abs(dx) * self.hyp_m
        c = vdist_r / self.radius if dx >= 0 else -vdist_r / self.radius
        fwd = math.hypot(dx, dy) - vdist_r
        if dy < 0:
            fwd = -fwd
        x, y, yaw = pose
        yaw_end = yaw + c
        return x + fwd * math.cos(yaw_end), y + fwd * math.sin(yaw_end), yaw_end, None


class _TwoSensor(_Method):
    name = "two-sensor"
    uses_all_sensors = True

    def __init__(self, mounts, sensor):
        super().__init__(mounts, sensor)
        if len(mounts) < 2:
            raise ValueError(
                f"method 'two-sensor' needs at least 2 sensor mounts, got {len(mounts)}"
            )
        rows = []
        for m in mounts:
            rows.append([0.0, -1.0, -m.x])  # dX = -(b + c*px)
            rows.append([1.0, 0.0, -m.y])  # dY = a - c*py
        a_mat = np.array(rows)
        if np.linalg.matrix_rank(a_mat) < 3:
            raise ValueError(
                "method 'two-sensor': the sensors sit at the same point "
                f"({[(m.x, m.y) for m in mounts]}), so (vx, vy, omega) is not determined"
            )
        self.a_mat = a_mat
        self.pinv = np.linalg.pinv(a_mat)  # (3, 2n)
        self._pinv_l = self.pinv.tolist()
        self._a_l = a_mat.tolist()
        self._lift_maps: dict[tuple[bool, ...], np.ndarray | None] = {}

    def solve(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Least-squares body increments (N, 3) = (a, b, c) and residual norms (N,) in m."""
        meas = d.reshape(d.shape[0], -1)  # (N, 2n): dX1, dY1, dX2, dY2, ...
        abc = meas @ self.pinv.T
        resid = np.linalg.norm(abc @ self.a_mat.T - meas, axis=1)
        return abc, resid

    def poses(self, start, dt, d):
        abc, resid = self.solve(d)
        return arc_poses(start, abc[:, 0], abc[:, 1], abc[:, 2]), resid

    def body_map(self, lifted=None) -> np.ndarray:
        """(3, 2n): the least-squares map, without the lifted sensors' equations."""
        m = None if lifted is None else self.lifted_map(tuple(lifted))
        return self.pinv if m is None else m

    def lifted_map(self, lifted: tuple[bool, ...]) -> np.ndarray | None:
        """(3, 2n) map measurements -> (a, b, c) without the lifted sensors' equations.

        Two or more sensors left: least squares over them (if they still determine
        the twist); one left: its no-slip split (``exact``: b = 0, c = -dX/sy,
        a = dY + (sx/sy)*dX); none (or a sensor on the axle line left alone):
        None, the caller keeps the full map on the data as given.
        """
        key = tuple(lifted)
        if key in self._lift_maps:
            return self._lift_maps[key]
        keep = [i for i, f in enumerate(key) if not f]
        out = None
        if len(keep) >= 2:
            rows = [r for i in keep for r in (2 * i, 2 * i + 1)]
            a_red = self.a_mat[rows]
            if np.linalg.matrix_rank(a_red) == 3:
                out = np.zeros((3, self.a_mat.shape[0]))
                out[:, rows] = np.linalg.pinv(a_red)
        if len(keep) == 1 and self.mounts[keep[0]].forward != 0:
            out = _no_slip_map(self.mounts, keep[0])
        self._lift_maps[key] = out
        return out

    def poses_lifted(self, start, dt, d, lifted: np.ndarray):
        """:meth:`poses` with the lifted sensors' equations dropped per sample."""
        meas = d.reshape(d.shape[0], -1)
        abc, resid = self.solve(d)
        any_lift = lifted.any(axis=1)
        for pattern in np.unique(lifted[any_lift], axis=0):
            rows = np.all(lifted == pattern, axis=1)
            m = self.lifted_map(tuple(bool(v) for v in pattern))
            if m is not None:
                abc[rows] = meas[rows] @ m.T
        resid = resid.copy()
        resid[any_lift] = np.nan  # no redundancy left to check
        return arc_poses(start, abc[:, 0], abc[:, 1], abc[:, 2]), resid

    def step_lifted(self, pose, dt, d, lifted: tuple[bool, ...]):
        """:meth:`step` with the lifted sensors' equations dropped."""
        m = self.lifted_map(lifted)
        if m is None:
            x, y, yaw, _ = self.step(pose, dt, d)
            return x, y, yaw, math.nan
        meas = [v for pair in d for v in pair]
        a, b, c = (sum(p * v for p, v in zip(row, meas, strict=True)) for row in m.tolist())
        return (*_arc_step(pose, a, b, c), math.nan)

    def step(self, pose, dt, d):
        meas = [v for pair in d for v in pair]
        a, b, c = (sum(p * m for p, m in zip(row, meas, strict=True)) for row in self._pinv_l)
        r2 = 0.0
        for row, m in zip(self._a_l, meas, strict=True):
            e = row[0] * a + row[1] * b + row[2] * c - m
            r2 += e * e
        return (*_arc_step(pose, a, b, c), math.sqrt(r2))


METHODS: dict[str, type[_Method]] = {
    cls.name: cls for cls in (_Exact, _SeedApproach1, _SeedApproach2, _TwoSensor)
}


# --- the integrator ----------------------------------------------------------------------


class Odometry:
    """Integrates per-request sensor displacements into an odom -> base_link pose.

    ``mounts``: the sensor mounts in sample order (base_link metres, yaw = the
    mounting error still present in the input; 0 for calibrated input).
    ``method``: a key of :data:`METHODS`. ``sensor``: which mount the
    one-sensor methods use (default 0, the first). ``pose``: start pose.
    """

    def __init__(
        self,
        mounts: Sequence[SensorMount],
        method: str = DEFAULT_METHOD,
        sensor: int = 0,
        pose: Pose2D | None = None,
    ) -> None:
        mounts = tuple(mounts)
        if not mounts:
            raise ValueError("Odometry needs at least one sensor mount")
        for i, m in enumerate(mounts):
            if not all(math.isfinite(v) for v in (m.x, m.y, m.yaw)):
                raise ValueError(f"sensor mount {i} ({m}) has a non-finite value")
        if method not in METHODS:
            raise ValueError(f"unknown odometry method {method!r}; known: {sorted(METHODS)}")
        if not (isinstance(sensor, int) and 0 <= sensor < len(mounts)):
            raise ValueError(
                f"sensor index must be an integer in 0..{len(mounts) - 1}, got {sensor!r}"
            )
        self.mounts = mounts
        self.method = method
        self._impl = METHODS[method](mounts, sensor)
        yaws = np.array([m.yaw for m in mounts])
        self._cos, self._sin = np.cos(yaws), np.sin(yaws)
        self._has_yaw = bool(np.any(yaws != 0))
        self._cos_l, self._sin_l = [float(v) for v in self._cos], [float(v) for v in self._sin]
        self._pose = np.zeros(3)
        #: residual norm (m) of the last update; None for one-sensor methods, NaN when
        #: a lifted sensor was dropped (nothing left to check the others against).
        self.residual: float | None = None
        #: samples so far in which some / every sensor was lifted (for the last
        #: group, every method could only use the data as given: a gap-filled
        #: estimate, or nothing, so the pose held)
        self.lifted_samples = 0
        self.blind_samples = 0
        self.reset(pose)

    @property
    def switched_samples(self) -> int:
        """Samples ``exact`` integrated with another sensor because its own was lifted
        (0 for the other methods)."""
        return getattr(self._impl, "switched", 0)

    def body_map(self, lifted: Sequence[bool] | None = None) -> np.ndarray:
        """(3, 2 * n_sensors): how the method turns one sample's ideal-frame counts
        (dX1, dY1, dX2, dY2, ...) in metres into the body increment (a m, b m, c rad),
        linearised (exact for ``exact`` and ``two-sensor``; the seed's approaches are
        given ``exact``'s). ``lifted``: per sensor; ``two-sensor`` drops the lifted ones,
        ``exact`` gives the map of the sensor it switched to.
        For :class:`mm_pc.core.uncertainty.PoseUncertainty`.
        """
        flags = None if lifted is None or not any(lifted) else tuple(bool(v) for v in lifted)
        return self._impl.body_map(flags)

    @property
    def n_sensors(self) -> int:
        return len(self.mounts)

    @property
    def pose(self) -> Pose2D:
        """The current pose (odom -> base_link)."""
        return Pose2D(*(float(v) for v in self._pose))

    def reset(self, pose: Pose2D | None = None) -> None:
        """Back to ``pose`` (default: the origin), residual and lift counters cleared."""
        p = np.zeros(3) if pose is None else np.array([pose.x, pose.y, pose.yaw], dtype=float)
        if not np.all(np.isfinite(p)):
            raise ValueError(f"reset pose must be finite, got {pose}")
        self._pose = p
        self.residual = None
        self.lifted_samples = self.blind_samples = 0
        if isinstance(self._impl, _Exact):
            self._impl.switched = 0

    # -- input checks and the mount-yaw undo ------------------------------------------

    def _check(self, dt: np.ndarray, d: np.ndarray) -> None:
        n = self.n_sensors
        if d.ndim != 3 or d.shape[1:] != (n, 2):
            raise ValueError(
                f"expected displacements of shape (N, {n}, 2) (one (dX, dY) per sensor, "
                f"{n} sensor(s) in mount order), got shape {d.shape}"
            )
        if dt.shape != (d.shape[0],):
            raise ValueError(f"expected {d.shape[0]} interval lengths dt, got shape {dt.shape}")
        if not np.all(np.isfinite(dt)) or not np.all(dt > 0):
            bad = dt[~(np.isfinite(dt) & (dt > 0))][0]
            raise ValueError(f"dt must be a finite number of seconds > 0, got {bad}")
        if not np.all(np.isfinite(d)):
            idx = np.argwhere(~np.isfinite(d))[0]
            raise ValueError(
                f"displacement of sensor {idx[1]} ({'dX' if idx[2] == 0 else 'dY'}) in "
                f"sample {idx[0]} is {d[tuple(idx)]}; it must be a finite number of metres"
            )

    def _unturn(self, d: np.ndarray) -> np.ndarray:
        """Undo each mount's yaw: reported = R(-yaw)·ideal, so ideal = R(yaw)·reported."""
        if not self._has_yaw:
            return d
        x, y = d[..., 0], d[..., 1]
        return np.stack([self._cos * x - self._sin * y, self._sin * x + self._cos * y], axis=-1)

    # -- public API ---------------------------------------------------------------------

    def update(self, sample: Sample) -> Pose2D:
        """Advance by one request interval; returns the new pose.

        Plain-float code (no numpy per call: about 10x faster for one sample,
        which matters at 1 kHz on a BeagleBone); the same formulas as
        :meth:`integrate`, which the tests hold it to.

        Raises ValueError (state unchanged) for dt <= 0, a non-finite value or
        the wrong number of sensors.
        """
        dt, d = self._check_one(sample)
        lifted = self._check_lifted_one(getattr(sample, "lifted", None))
        if self._has_yaw:
            d = [
                (c * x - s * y, s * x + c * y)
                for (x, y), c, s in zip(d, self._cos_l, self._sin_l, strict=True)
            ]
        if lifted is None:
            x, y, yaw, resid = self._impl.step(self._pose_t, dt, d)
        else:
            self.lifted_samples += 1
            self.blind_samples += all(lifted)
            if isinstance(self._impl, (_TwoSensor, _Exact)):
                x, y, yaw, resid = self._impl.step_lifted(self._pose_t, dt, d, lifted)
            else:
                x, y, yaw, resid = self._impl.step(self._pose_t, dt, d)
        self._pose = np.array([x, y, yaw])
        self.residual = resid
        return Pose2D(x, y, yaw)

    @property
    def _pose_t(self) -> tuple[float, float, float]:
        p = self._pose
        return float(p[0]), float(p[1]), float(p[2])

    def _check_one(self, sample: Sample) -> tuple[float, list[tuple[float, float]]]:
        try:
            dt = float(sample.dt)
            pairs = list(sample.d)
        except (TypeError, ValueError) as e:
            raise ValueError(
                f"a sample needs dt (s) and one (dX, dY) pair (m) per sensor: {e}"
            ) from None
        n = self.n_sensors
        if len(pairs) != n:
            raise ValueError(
                f"sample has {len(pairs)} sensor displacement(s), this odometry has "
                f"{n} mount(s); give one (dX, dY) pair per sensor in mount order"
            )
        d = []
        for i, p in enumerate(pairs):
            try:
                if len(p) != 2:
                    raise ValueError
                fx, fy = float(p[0]), float(p[1])
            except (TypeError, ValueError):
                raise ValueError(
                    f"sensor {i}'s displacement {p!r} has the wrong shape: expected one "
                    f"(dX, dY) pair in metres, shape (N, {n}, 2) over all samples"
                ) from None
            d.append((fx, fy))
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a finite number of seconds > 0, got {dt}")
        for i, (fx, fy) in enumerate(d):
            for axis, val in (("dX", fx), ("dY", fy)):
                if not math.isfinite(val):
                    raise ValueError(
                        f"displacement of sensor {i} ({axis}) in sample 0 is {val}; "
                        "it must be a finite number of metres"
                    )
        return dt, d

    def _check_lifted_one(self, lifted) -> tuple[bool, ...] | None:
        """A sample's lift flags as a tuple, None when nobody was lifted."""
        if lifted is None:
            return None
        try:
            flags = tuple(bool(v) for v in lifted)
        except TypeError:
            flags = ()
        if len(flags) != self.n_sensors:
            raise ValueError(
                f"a sample's lifted flags must be one bool per sensor ({self.n_sensors}), "
                f"got {lifted!r}"
            )
        return flags if any(flags) else None

    def _check_lifted(self, lifted, n: int) -> np.ndarray | None:
        if lifted is None:
            return None
        m = np.asarray(lifted)
        if m.dtype != bool or m.shape != (n, self.n_sensors):
            raise ValueError(
                f"lifted must be a bool array of shape ({n}, {self.n_sensors}) (one flag per "
                f"sample and sensor), got {m.dtype} of shape {m.shape}"
            )
        return m if m.any() else None

    def integrate(self, dt, d, return_residual: bool = False, *, lifted=None):
        """Vectorised :meth:`update` over N intervals; advances the state the same way.

        ``dt``: seconds, scalar or shape (N,). ``d``: metres, shape
        (N, n_sensors, 2), sensor frame as reported. Returns the (N, 3) poses
        (x m, y m, yaw rad) after each interval; with ``return_residual`` also
        the (N,) residual norms in metres (NaN for one-sensor methods, and for
        samples in which a sensor was lifted).

        ``lifted``: optional bool (N, n_sensors), True where a sensor was lifted
        in that interval (its ``d`` is then what it counted, or a gap-filled
        estimate). ``two-sensor`` drops those sensors' equations (one sensor left:
        its no-slip split, as ``exact``); ``exact`` takes another sensor's split
        while its own is lifted (:attr:`switched_samples`); the seed's methods use
        ``d`` as given, so fill the gaps first (:func:`mm_pc.core.filters.fill_lift_gaps`).
        Every sensor lifted: the data as given, and :attr:`blind_samples` counts it.
        """
        d = np.asarray(d, dtype=float)
        if d.ndim != 3:
            raise ValueError(
                f"expected displacements of shape (N, {self.n_sensors}, 2), got shape {d.shape}"
            )
        dt = (
            np.broadcast_to(np.asarray(dt, dtype=float), (d.shape[0],))
            if np.ndim(dt) == 0
            else np.asarray(dt, dtype=float)
        )
        self._check(dt, d)
        mask = self._check_lifted(lifted, d.shape[0])
        if d.shape[0] == 0:
            poses, resid = np.empty((0, 3)), np.empty(0)
        else:
            if mask is not None:
                self.lifted_samples += int(np.count_nonzero(mask.any(axis=1)))
                self.blind_samples += int(np.count_nonzero(mask.all(axis=1)))
            if mask is not None and isinstance(self._impl, (_TwoSensor, _Exact)):
                poses, resid = self._impl.poses_lifted(self._pose, dt, self._unturn(d), mask)
            else:
                poses, resid = self._impl.poses(self._pose, dt, self._unturn(d))
            self._pose = poses[-1].copy()
            self.residual = None if resid is None else float(resid[-1])
        if return_residual:
            return poses, (np.full(len(poses), np.nan) if resid is None else resid)
        return poses
