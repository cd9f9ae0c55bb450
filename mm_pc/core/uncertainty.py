"""How uncertain the mouse odometry is: the pose covariance, propagated step by step.

Pure math, no ROS. The model (derivation: docs/pose-math.md, "Covariance"):

    P_reported = P_noise + J · C_cal · Jᵀ + P_floor

* ``P_noise``: random noise, propagated like an EKF's prediction. Per step of body
  increment (a forward m, b left m, c rad) a noise Q_body is added through the
  step's Jacobian G, and the earlier covariance is carried through the pose
  Jacobian F (a heading error moves the position sideways by the step length):
  ``P <- F P Fᵀ + G Q Gᵀ``. Q_body comes either from the stated random walk
  (``q_pos`` m²/m on along and lateral, ``q_yaw_dist`` rad²/m, ``q_yaw_turn``
  rad²/rad: the seed's 1-2 cm spread per metre) or, with :meth:`for_odometry`, from
  a per-sensor noise ``sensor_noise`` (m² per metre the sensor itself travelled,
  per axis) mapped through the method's linear map from counts to (a, b, c), so
  that turning on the spot (the sensors travel on their circles) counts too and a
  lifted sensor's dropped equations or filled counts show up.
* ``J · C_cal · Jᵀ``: the calibration's uncertainty. A wrong mounting yaw or scale
  is not noise but a bias, the same in every step, so its effect is carried as the
  sensitivity J of the pose to each calibration parameter (``J <- F J + G δ``) and
  only multiplied by the standard errors (``cal_yaw_se`` rad, ``cal_scale_se``
  relative; per sensor, independent) when the covariance is read.
* ``P_floor``: count quantisation at the CPI in force. A total is off by less than
  one count and does not accumulate (the remainder is carried), so it is a floor,
  not a random walk: variance u²/6 per axis (the difference of two uniform
  remainders, u = 0.0254 / cpi m) and u²/(6·lever²) on yaw. Never 0, also at rest.

Lifts: ``add(..., fill_var_m2=...)`` adds a filled sensor's estimate variance
(:mod:`pln2033.lift_fill`) to that step; with :meth:`for_odometry` a ``lifted`` mask
makes ``two-sensor`` lose the lifted sensor's equations as the odometry does.

The defaults are stated, not measured on real hardware: a user with a test drive
should set their own (parameters of mm-odometry).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import KW_ONLY, dataclass, field

import numpy as np

from pln2033 import INCH_M

#: Variance (m^2, rad^2) put on z, roll and pitch, which a planar robot does not observe
#: (the usual convention for 2-D odometry).
UNOBSERVED_VARIANCE = 1e6

Q_POS = 0.015**2  # m^2 per m travelled
Q_YAW_DIST = 0.01**2  # rad^2 per m travelled
Q_YAW_TURN = 0.01**2  # rad^2 per rad turned
DEFAULT_CPI = 1600.0
DEFAULT_LEVER_M = 0.049  # the default robot's sensors: 4.9 cm forward of the axle


def _check(name: str, v: float, positive: bool = False) -> None:
    if not (isinstance(v, (int, float)) and math.isfinite(v) and (v > 0 if positive else v >= 0)):
        raise ValueError(f"{name} must be a finite number {'> 0' if positive else '>= 0'}, got {v}")


@dataclass
class PoseUncertainty:
    """Accumulated pose covariance (x, y in m in odom; yaw in rad).

    ``q_pos``, ``q_yaw_dist``, ``q_yaw_turn``: the body random walk (see the module).
    Keyword-only: ``cpi`` (the quantisation floor), ``lever_m`` (m: the arm that turns
    one count of X into yaw, the sensor's forward offset for ``exact``),
    ``cal_yaw_se`` (rad) and ``cal_scale_se`` (relative): standard errors of the
    calibration in force. ``var_along`` / ``var_yaw`` are the plain random-walk sums
    (m², rad²) kept for callers that read them.
    """

    q_pos: float = Q_POS
    q_yaw_dist: float = Q_YAW_DIST
    q_yaw_turn: float = Q_YAW_TURN
    _: KW_ONLY
    cpi: float = DEFAULT_CPI
    lever_m: float = DEFAULT_LEVER_M
    cal_yaw_se: float = 0.0
    cal_scale_se: float = 0.0
    var_along: float = field(default=0.0, init=False)
    var_yaw: float = field(default=0.0, init=False)

    def __post_init__(self) -> None:
        for name in ("q_pos", "q_yaw_dist", "q_yaw_turn", "cal_yaw_se", "cal_scale_se"):
            _check(name, getattr(self, name))
        _check("cpi", self.cpi, positive=True)
        _check("lever_m", self.lever_m, positive=True)
        self._sensor_noise: float | None = None
        self._mounts: np.ndarray | None = None  # (n, 2) base_link x, y
        #: lifted flags or None -> (3, 2n) counts-to-(a, b, c) map (set with _mounts)
        self._body_map: Callable[[tuple[bool, ...] | None], np.ndarray] | None = None
        self.reset()

    @classmethod
    def for_odometry(
        cls,
        odometry,
        *,
        sensor_noise: float,
        cpi: float = DEFAULT_CPI,
        cal_yaw_se: float = 0.0,
        cal_scale_se: float = 0.0,
    ) -> PoseUncertainty:
        """The sensor-level model for an :class:`~mm_pc.core.odometry.Odometry`.

        ``sensor_noise``: m² of noise per metre a sensor travels, per axis. The lever
        of the quantisation floor is the shortest yaw lever of the method (the used
        sensor's forward offset; for ``two-sensor`` the sensors' spacing).
        """
        _check("sensor_noise", sensor_noise)
        m = odometry.body_map()
        lever = 1.0 / float(np.max(np.abs(m[2])))  # rad per metre of the yaw row's largest entry
        u = cls(cpi=cpi, lever_m=lever, cal_yaw_se=cal_yaw_se, cal_scale_se=cal_scale_se)
        u._sensor_noise = float(sensor_noise)
        u._mounts = np.array([[mt.x, mt.y] for mt in odometry.mounts])
        u._body_map = odometry.body_map
        u.reset()
        return u

    def reset(self, yaw: float = 0.0) -> None:
        """Back to no uncertainty but the floor; ``yaw`` (rad) is the heading it starts at."""
        self.var_along = self.var_yaw = 0.0
        self._yaw = float(yaw)
        self._p = np.zeros((3, 3))
        n_cal = 2 if self._mounts is None else 2 * len(self._mounts)
        self._j = np.zeros((3, n_cal))

    # -- steps ------------------------------------------------------------------------------

    def add(
        self,
        distance: float,
        turned: float,
        *,
        lateral: float = 0.0,
        heading: float | None = None,
        fill_var_m2: float | Sequence[float] = 0.0,
        lifted: Sequence[bool] | None = None,
    ) -> None:
        """One interval: ``distance`` m forward (a sign is kept where given), ``turned`` rad.

        ``lateral``: m to the left (two-sensor's slip). ``heading``: the yaw (rad) at
        the start of the step; default the yaw this object tracked from its turns.
        ``fill_var_m2``: variance (m², per axis) of a lift-gap estimate in this step's
        counts, one value or one per sensor (for :meth:`for_odometry`). ``lifted``: per sensor,
        True if it was lifted in the step (:meth:`for_odometry`: two-sensor drops it).
        """
        a, b, c = float(distance), float(lateral), float(turned)
        for name, v in (("distance", a), ("lateral", b), ("turned", c)):
            if not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {v}")
        yaw0 = self._yaw if heading is None else float(heading)
        mounts, body_map = self._mounts, self._body_map
        if mounts is None or body_map is None:
            q, delta = self._legacy_step(a, b, c, fill_var_m2)
        else:
            q, delta = self._sensor_step(mounts, body_map, a, b, c, fill_var_m2, lifted)
        self.var_along += self.q_pos * abs(a)
        self.var_yaw += self.q_yaw_dist * abs(a) + self.q_yaw_turn * abs(c)
        phi = yaw0 + c / 2
        cp, sp = math.cos(phi), math.sin(phi)
        dx, dy = cp * a - sp * b, sp * a + cp * b
        f = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
        g = np.array([[cp, -sp, -dy / 2], [sp, cp, dx / 2], [0.0, 0.0, 1.0]])
        self._p = f @ self._p @ f.T + g @ q @ g.T
        self._j = f @ self._j + g @ delta
        self._yaw = yaw0 + c

    def _legacy_step(self, a, b, c, fill_var) -> tuple[np.ndarray, np.ndarray]:
        """Body random walk; calibration as a heading drift of yaw/lever per metre."""
        fill = float(np.sum(fill_var))
        if not (math.isfinite(fill) and fill >= 0):
            raise ValueError(f"fill_var_m2 must be finite numbers >= 0, got {fill_var!r}")
        s = abs(a) + abs(b)
        q = np.diag(
            [
                self.q_pos * s + fill,
                self.q_pos * s + fill,
                self.q_yaw_dist * s + self.q_yaw_turn * abs(c) + fill / self.lever_m**2,
            ]
        )
        # columns: mounting yaw (turns the forward motion into X: heading drift), scale
        delta = np.array([[0.0, a], [0.0, b], [a / self.lever_m, c]])
        return q, delta

    def _sensor_step(
        self,
        mounts: np.ndarray,
        body_map: Callable[[tuple[bool, ...] | None], np.ndarray],
        a,
        b,
        c,
        fill_var,
        lifted,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Sensor noise per metre travelled, through the method's counts -> (a, b, c) map
        (``mounts``: (n, 2) base_link x, y of the sensors, m)."""
        n = len(mounts)
        flags = None if lifted is None or not any(lifted) else tuple(bool(v) for v in lifted)
        m_map = body_map(flags)
        # each sensor's ideal displacement in its frame: dX = -(b + c*px), dY = a - c*py
        meas = np.empty((n, 2))
        meas[:, 0] = -(b + c * mounts[:, 0])
        meas[:, 1] = a - c * mounts[:, 1]
        travel = np.hypot(meas[:, 0], meas[:, 1])
        fill = np.broadcast_to(np.asarray(fill_var, dtype=float), (n,))
        if not np.all(np.isfinite(fill) & (fill >= 0)):
            raise ValueError(f"fill_var_m2 must be finite numbers >= 0, got {fill_var!r}")
        var = np.repeat(self._sensor_noise * travel + fill, 2)  # per axis
        q = (m_map * var) @ m_map.T
        delta = np.empty((3, 2 * n))
        for i in range(n):
            block = m_map[:, 2 * i : 2 * i + 2]
            delta[:, i] = block @ np.array([meas[i, 1], -meas[i, 0]])  # mounting yaw
            delta[:, n + i] = block @ meas[i]  # scale
        return q, delta

    # -- read-out ---------------------------------------------------------------------------

    def covariance(self) -> np.ndarray:
        """The 3x3 covariance of (x m, y m, yaw rad) in odom: noise + calibration + floor."""
        n_cal = self._j.shape[1] // 2
        c_cal = np.diag([self.cal_yaw_se**2] * n_cal + [self.cal_scale_se**2] * n_cal)
        u2 = (INCH_M / self.cpi) ** 2 / 6.0
        floor = np.diag([u2, u2, u2 / self.lever_m**2])
        return self._p + self._j @ c_cal @ self._j.T + floor

    def pose_covariance(self) -> list[float]:
        """Row-major 6x6 (x, y, z, roll, pitch, yaw) for nav_msgs/Odometry.

        z, roll and pitch are not observed by a planar robot: a large variance
        (1e6) says so, the usual convention for 2-D odometry.
        """
        return planar_covariance_6x6(self.covariance())


def twist_covariance(cpi: float, dt: float) -> list[float]:
    """Row-major 6x6 for the twist: one count of quantisation per interval.

    A count is 0.0254/cpi m; over an interval dt its velocity uncertainty is
    about that / dt (uniform quantisation: std = step/sqrt(12)).
    """
    if not (cpi > 0 and dt > 0):
        raise ValueError(f"cpi and dt must be > 0, got cpi={cpi}, dt={dt}")
    step = 0.0254 / cpi / dt
    var_v = step * step / 12.0
    # omega from a sensor about 5 cm off the axle
    return planar_covariance_6x6(np.diag([var_v, var_v, var_v / 0.05**2]))


def planar_covariance_6x6(p3) -> list[float]:
    """Row-major 6x6 (x, y, z, roll, pitch, yaw) of ROS messages from the 3x3 of (x, y, yaw).

    The one place that knows the layout: z, roll and pitch get :data:`UNOBSERVED_VARIANCE`.
    """
    p = np.asarray(p3, dtype=float)
    if p.shape != (3, 3):
        raise ValueError(f"a planar covariance is 3x3 (x, y, yaw), got shape {p.shape}")
    c = np.zeros((6, 6))
    idx = [0, 1, 5]
    c[np.ix_(idx, idx)] = p
    c[2, 2] = c[3, 3] = c[4, 4] = UNOBSERVED_VARIANCE
    return c.reshape(-1).tolist()


def calibration_se(calibration, devices: Sequence[str]) -> dict[str, float]:
    """``cal_yaw_se`` (rad) and ``cal_scale_se`` (relative) for :class:`PoseUncertainty`
    from a loaded :class:`~mm_pc.core.calibration.Calibration`: the largest standard
    error of the mounting angle and of the X/Y scales over the sensors ``devices`` the
    pose uses (conservative: the random-walk model carries one of each); 0 where the
    file has none (a version-1 file, a straight-run calibration)."""
    yaw, scale = [0.0], [0.0]
    for dev in devices:
        c = calibration.get(dev)
        yaw.append(c.angle_offset_se or 0.0)
        scale += [c.scale_x_se or 0.0, c.scale_y_se or 0.0]
    return {"cal_yaw_se": max(yaw), "cal_scale_se": max(scale)}
