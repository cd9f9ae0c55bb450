"""A calibration that fits the whole mount, from a guided run.

Pure math: numpy only, no Qt, no ROS. The user pushes the robot straight
(forward and back) and turns it on the spot (both ways); each of these is a
:class:`CalibrationStep` holding the raw sensor-frame displacements
(X right, Y forward, metres, no calibration applied) of every interval it
recorded, shape (N, n_sensors, 2). :func:`fit_mounts` fits per sensor the
mounting yaw, separate X and Y scales and the position relative to the
turning centre, with standard errors, and predicts the heading drift per
metre each odometry method keeps from the fit's uncertainty.

Model (derivation: docs/pose-math.md, section "calibration fit"). A sensor
at base_link (px, py) with mounting yaw psi and per-axis gains (kx, ky)
reports ``r = diag(kx, ky) @ R(-psi) @ ideal``; the calibration undoes it,
``ideal = R(psi) @ diag(sx, sy) @ r`` with ``sx = 1/kx``, ``sy = 1/ky``. A
straight step of signed length A (shared by all sensors) has the ideal sum
(0, A); a spin by C rad about the turning centre (base_link origin) has
(-C px, -C py). Residuals: the corrected step sums minus these, for every
step and sensor, plus pseudo-observations: |A| = the measured distance (or,
without one, the scale reference: the mean Y scale = 1, the sensors' own CPI,
or the spins against the configured mount radii), C = +-the spin angle the user turned,
and sx/sy = 1 within ``anisotropy_sd`` -- straights and spins only ever
see kx * px, so that prior splits the product (the odometry depends on the
product only, see the docs). Solved by Gauss-Newton; covariance
``inv(J^T J)`` with the data weighted by the residual scatter, each step's sum
also by sqrt(its path / the mean path) (count noise is a random walk).

Predicted heading drift per metre (rad/m, 1 sigma) on a straight: the
method's yaw increment from the corrected sums of a unit straight, whose
error is the fitted calibration's error there. ``exact`` (sensor k):
``-dX_k / px_k``, so a yaw error eps gives eps / px_k. ``two-sensor``: row c
of the least-squares pseudo-inverse applied to (dX_i, dY_i); on the original
robot (equal px) the yaw errors go into lateral slip, and the drift is the
difference of the Y-scale errors over the lateral spacing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np

from mm_pc.core.calibration import (
    Calibration,
    SensorCalibration,
    calibrate_straight_run,
)
from mm_pc.core.geometry import SensorMount
from pln2033 import INCH_M

__all__ = [
    "ANISOTROPY_SD",
    "MIN_SPIN_RAD",
    "MIN_STRAIGHT_M",
    "SCALE_RANGE",
    "SCALE_REFERENCES",
    "STEP_KINDS",
    "CalibrationRefusedError",
    "CalibrationStep",
    "MountFit",
    "StepCheck",
    "check_step",
    "fit_advice",
    "fit_mounts",
    "straight_run_calibration",
]

STEP_KINDS = ("straight", "spin")
#: Shortest straight step (m, every sensor's chord).
MIN_STRAIGHT_M = 0.10
#: Smallest spin (rad, estimated from the nominal mount radius).
MIN_SPIN_RAD = math.radians(90.0)
#: A step's path may leave its chord by at most this much (m) plus MAX_DEVIATION_FRACTION
#: of the chord: a straight that turned (or a spin that wandered) bends the
#: sensor's path, which for a pure straight or spin is a line in the sensor frame.
MAX_DEVIATION_M = 0.002
MAX_DEVIATION_FRACTION = 0.01
#: The sensors' distances on a straight may differ by at most this fraction (a turn;
#: not tighter: sensors at the same CPI differ in scale by a few per cent).
MAX_DISTANCE_SPREAD = 0.10
#: Straights must agree in direction after the fit within this (rad): sideways motion.
MAX_STRAIGHT_ANGLE = math.radians(0.5)
#: Accepted fitted scales; outside, the CPI setting or the entered distance is wrong.
SCALE_RANGE = (0.5, 2.0)
#: The entered spin angle must match the measured one within this fraction.
SPIN_ANGLE_TOLERANCE = 0.2
#: Prior on sx/sy - 1 (the axes share lens and surface distance).
ANISOTROPY_SD = 0.02
#: How well a user meets the entered spin angle and the measured distance.
SPIN_ANGLE_SD = math.radians(0.5)
DISTANCE_SD = 0.001
#: How well a user knows a sensor's position (m per coordinate, a ruler on the robot).
MOUNT_SD = 0.001
#: Without a measured distance, what fixes the scale of distances: "sensors" (the mean Y
#: scale = 1: the CPI as set) or "mounts" (the spins' known angle against the configured
#: mount radii: a spin by C moves a sensor by C * r, so with r known the spins give the
#: scale). Straights and spins alone fix only the product scale * position.
SCALE_REFERENCES = ("sensors", "mounts")
#: One count at 1600 CPI (m): the noise floor of a step sum.
DEFAULT_RESOLUTION_M = INCH_M / 1600


class CalibrationRefusedError(ValueError):
    """A run the fit will not use; the message says what is wrong and what to do."""


@dataclass(frozen=True)
class CalibrationStep:
    """One step of the guided run: ``kind`` in :data:`STEP_KINDS`, ``d`` (N, n, 2) m."""

    kind: str
    d: np.ndarray

    def __post_init__(self) -> None:
        if self.kind not in STEP_KINDS:
            raise ValueError(f"step kind must be one of {STEP_KINDS}, got {self.kind!r}")
        d = np.asarray(self.d, dtype=float)
        if d.ndim != 3 or d.shape[2] != 2 or d.shape[1] < 1:
            raise ValueError(f"step displacements must have shape (N, n_sensors, 2), got {d.shape}")
        if not np.all(np.isfinite(d)):
            raise ValueError("step displacements must be finite metres")
        object.__setattr__(self, "d", d)

    @property
    def n_sensors(self) -> int:
        return self.d.shape[1]

    @property
    def totals(self) -> np.ndarray:
        """(n, 2) summed raw displacement per sensor (m)."""
        return self.d.sum(axis=0)


@dataclass(frozen=True)
class StepCheck:
    """The live residuals of one step and whether it passes.

    ``distance`` (n,): chord length per sensor (m); ``deviation`` (n,): how far
    the sensor's path left its chord (m, the residual of a line);
    ``spread``: relative difference of the sensors' distances (straights with
    two or more sensors, else NaN); ``angle`` (n,): spin angle estimated from
    the nominal mount radius (rad, spins; NaN for straights). ``message``: ""
    when ``ok``, else what is wrong and what to do.
    """

    kind: str
    ok: bool
    message: str
    distance: np.ndarray
    deviation: np.ndarray
    spread: float
    angle: np.ndarray


def _deviation(d: np.ndarray) -> tuple[float, float]:
    """(chord length, max distance of the cumulative path from its chord line) in m."""
    cum = np.cumsum(d, axis=0)
    chord = cum[-1] if len(cum) else np.zeros(2)
    length = float(np.hypot(*chord))
    if length < 1e-12:
        return length, float(np.max(np.hypot(cum[:, 0], cum[:, 1]), initial=0.0))
    ux, uy = chord / length
    return length, float(np.max(np.abs(cum[:, 0] * uy - cum[:, 1] * ux), initial=0.0))


def check_step(
    step: CalibrationStep,
    mounts: Sequence[SensorMount],
    min_distance: float = MIN_STRAIGHT_M,
    min_spin: float = MIN_SPIN_RAD,
) -> StepCheck:
    """The step's residuals and the first reason to refuse it (see :class:`StepCheck`).

    ``mounts``: the nominal mounts in sensor order (only the spin-angle
    estimate uses them).
    """
    n = step.n_sensors
    dist, dev = np.empty(n), np.empty(n)
    for i in range(n):
        dist[i], dev[i] = _deviation(step.d[:, i])
    spread = math.nan
    angle = np.full(n, math.nan)
    msg = ""
    limit = MAX_DEVIATION_M + MAX_DEVIATION_FRACTION * dist
    worst = int(np.argmax(dev - limit))
    if step.kind == "straight":
        if n >= 2 and dist.max() > 0:
            spread = float((dist.max() - dist.min()) / dist.mean())
        if dist.min() < min_distance:
            msg = (
                f"straight too short: {dist.min() * 100:.1f} cm, at least "
                f"{min_distance * 100:.0f} cm needed; press Start and push it further"
            )
        elif dev[worst] > limit[worst]:
            msg = (
                f"not straight: sensor {worst}'s path left the line by "
                f"{dev[worst] * 1000:.1f} mm (at most {limit[worst] * 1000:.1f} mm): the robot "
                "turned or moved sideways; push it along a straight edge and record the step again"
            )
        elif spread > MAX_DISTANCE_SPREAD:
            cm = ", ".join(f"{v * 100:.1f}" for v in dist)
            msg = (
                f"not straight: the sensors' distances differ ({cm} cm, {spread * 100:.0f} % > "
                f"{MAX_DISTANCE_SPREAD * 100:.0f} %): the robot turned; push it straight along an "
                "edge and record the step again"
            )
    else:
        radius = np.array([math.hypot(m.x, m.y) for m in tuple(mounts)[:n]])
        angle = np.where(radius > 0, dist / np.where(radius > 0, radius, 1.0), math.nan)
        est = float(np.nanmean(angle)) if np.any(np.isfinite(angle)) else 0.0
        if est < min_spin:
            msg = (
                f"spin too small: about {math.degrees(est):.0f} deg, at least "
                f"{math.degrees(min_spin):.0f} deg needed; turn it on the spot a full turn"
            )
        elif dev[worst] > limit[worst]:
            msg = (
                f"not a spin on the spot: sensor {worst}'s path left the line by "
                f"{dev[worst] * 1000:.1f} mm (at most {limit[worst] * 1000:.1f} mm): the robot "
                "moved while turning; turn it about its axle centre and record the step again"
            )
    return StepCheck(step.kind, not msg, msg, dist, dev, spread, angle)


# --- the fit -----------------------------------------------------------------------------------


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def _g(p: np.ndarray) -> np.ndarray:
    """Correction matrix R(psi) @ diag(sx, sy) of one sensor's parameters."""
    return _rot(p[0]) @ np.diag([p[1], p[2]])


@dataclass
class MountFit:
    """The result of :func:`fit_mounts`.

    ``devices``: sensor ids; ``sensors``: one :class:`SensorCalibration` per
    device (yaw, scales, position, standard errors); ``straight_run``: the
    seed's straight-run formula on the same straights, to compare;
    ``drift_per_m``: method -> predicted heading drift (rad per metre
    driven straight, 1 sigma); ``step_residuals`` (n_steps, n): |corrected
    step sum - model| per sensor (m); ``sigma``: the data scatter used (m).
    ``scale_reference``: what fixed the distances' scale ("distance" when a
    length was measured, else one of :data:`SCALE_REFERENCES`);
    ``mounts_scale``: the factor on this fit's distances that the spins and
    the configured mount radii imply (1 = they agree), with ``mounts_scale_se``
    from a :data:`MOUNT_SD` ruler measurement of each mount.
    """

    devices: tuple[str, ...]
    sensors: tuple[SensorCalibration, ...]
    straight_run: Calibration
    drift_per_m: dict[str, float]
    step_residuals: np.ndarray
    sigma: float
    spin_angles: np.ndarray
    straight_lengths: np.ndarray
    covariance: np.ndarray = field(repr=False)
    scale_reference: str = "sensors"
    mounts_scale: float = 1.0
    mounts_scale_se: float = 0.0

    @property
    def straight_total_m(self) -> float:
        """The straights' summed length (m): what the drift prediction falls with."""
        return float(np.sum(np.abs(self.straight_lengths)))

    def calibration(self, date: str | None = None) -> Calibration:
        """The fitted calibration (method "fit", dated now in UTC unless ``date``)."""
        if date is None:
            date = datetime.now(UTC).isoformat(timespec="seconds")
        return Calibration(dict(zip(self.devices, self.sensors, strict=True)), "fit", date)


def _signs(steps: Sequence[CalibrationStep], nominal: Sequence[SensorMount]) -> list[float]:
    """+1/-1 per step: a straight forward (Y > 0) / back; a spin CCW / CW.

    A CCW spin (C > 0) moves a sensor at p by ideal (-C px, -C py).
    """
    out = []
    for s in steps:
        tot = s.totals
        if s.kind == "straight":
            out.append(1.0 if tot[:, 1].sum() >= 0 else -1.0)
        else:
            near = enumerate(nominal[: s.n_sensors])
            dot = sum(tot[i, 0] * m.x + tot[i, 1] * m.y for i, m in near)
            out.append(-1.0 if dot > 0 else 1.0)
    return out


def straight_run_calibration(
    steps: Sequence[CalibrationStep],
    devices: Sequence[str],
    true_distance: float | None = None,
    min_distance: float = MIN_STRAIGHT_M,
) -> Calibration:
    """The seed's straight-run formula (:func:`calibrate_straight_run`) on the straights.

    The straights are summed with their direction (back runs negated), so
    forward and back count alike; ``true_distance`` is the length of *each*
    straight (m), None for scale 1. Raises :class:`CalibrationRefusedError` naming
    the sensor (no straight, too short, sideways, scale out of range).
    """
    straights = [s for s in steps if s.kind == "straight"]
    if not straights:
        raise CalibrationRefusedError("no straight step recorded: press Start straight and push it")
    signs = _signs(straights, ())
    terms = [sg * s.totals for sg, s in zip(signs, straights, strict=True)]
    total = sum(terms[1:], terms[0])
    td = None if true_distance is None else true_distance * len(straights)
    cal = Calibration(method="straight-run", date=datetime.now(UTC).isoformat(timespec="seconds"))
    for i, dev in enumerate(devices):
        try:
            cal[dev] = calibrate_straight_run(total[i, 0], total[i, 1], td, min_distance)
        except ValueError as e:
            raise CalibrationRefusedError(f"{dev}: {e}") from None
        _check_scale(dev, "", cal[dev].scale, true_distance)
    return cal


def _check_scale(dev: str, axis: str, scale: float, true_distance: float | None) -> None:
    lo, hi = SCALE_RANGE
    if lo <= scale <= hi:
        return
    cause = (
        "the distance you entered is wrong, or the sensor runs at another CPI than the "
        "monitor converts with"
        if true_distance is not None and not axis
        else "usually the sensor runs at another CPI than the one set (check the resolution "
        "panel), or the distance you entered is wrong"
    )
    raise CalibrationRefusedError(
        f"{dev}: {axis + ' ' if axis else ''}scale {scale:.2f} is far from 1 (accepted "
        f"{lo:g}..{hi:g}): the sensor counted {1 / scale:.2g} times the true distance; {cause}. "
        "Fix it and record the run again"
    )


def fit_mounts(
    steps: Sequence[CalibrationStep],
    devices: Sequence[str],
    nominal_mounts: Sequence[SensorMount],
    true_distance: float | None = None,
    spin_angle: float = 2 * math.pi,
    sensor: int = 0,
    resolution_m: float = DEFAULT_RESOLUTION_M,
    min_distance: float = MIN_STRAIGHT_M,
    anisotropy_sd: float = ANISOTROPY_SD,
    scale_reference: str = "sensors",
) -> MountFit:
    """Least-squares fit of every sensor's mount from a guided run (model: module docstring).

    Args:
        steps: the recorded steps (at least one straight and one spin).
        devices: sensor ids in the steps' sensor order.
        nominal_mounts: the configured mounts (start values, directions).
        true_distance: measured length of each straight (m), None = unknown
            (the mean Y scale is then 1).
        spin_angle: the angle each spin turned (rad, > 0; default a full turn).
        sensor: the sensor ``exact`` uses (for its predicted drift).
        resolution_m: one count (m): the floor of the data scatter.
        scale_reference: without ``true_distance``, what fixes the scale
            (:data:`SCALE_REFERENCES`); ignored with one.

    Raises:
        CalibrationRefusedError: a step that fails :func:`check_step`, no straight
        or no spin, a spin far from ``spin_angle``, straights that disagree in
        direction (sideways motion), or a scale outside :data:`SCALE_RANGE`;
        the message names the step or sensor and says what to do.
    """
    steps = list(steps)
    devices = tuple(devices)
    nominal = tuple(nominal_mounts)
    n = len(devices)
    if len(nominal) < n:
        raise ValueError(f"{n} sensors need {n} nominal mounts, got {len(nominal)}")
    if not (math.isfinite(spin_angle) and spin_angle > 0):
        raise ValueError(f"spin angle must be a finite number of rad > 0, got {spin_angle}")
    if true_distance is not None and not (math.isfinite(true_distance) and true_distance > 0):
        raise ValueError(f"true distance must be a finite number of m > 0, got {true_distance}")
    if scale_reference not in SCALE_REFERENCES:
        raise ValueError(
            f"scale reference must be one of {SCALE_REFERENCES}, got {scale_reference!r}"
        )
    nominal_radius = float(np.mean([math.hypot(m.x, m.y) for m in nominal[:n]]))
    if scale_reference == "mounts" and not nominal_radius > 0:
        raise ValueError("the configured mounts sit at the turning centre: no radius to scale by")
    for k, s in enumerate(steps):
        if s.n_sensors != n:
            raise ValueError(f"step {k + 1} has {s.n_sensors} sensors, expected {n}")
        chk = check_step(s, nominal, min_distance)
        if not chk.ok:
            raise CalibrationRefusedError(f"step {k + 1} ({s.kind}): {chk.message}")
    kinds = [s.kind for s in steps]
    if "straight" not in kinds or "spin" not in kinds:
        raise CalibrationRefusedError(
            "the fit needs at least one straight and one spin step: record the missing one "
            "(straight forward and back, then a full turn each way)"
        )
    signs = _signs(steps, nominal)
    straight_run = straight_run_calibration(steps, devices, true_distance, min_distance)
    # straights that disagree in direction (raw, the same correction applies to all):
    # one of them went sideways or turned
    for i in range(n):
        dirs = [
            (k, math.atan2(signs[k] * s.totals[i, 0], signs[k] * s.totals[i, 1]))
            for k, s in enumerate(steps)
            if s.kind == "straight"
        ]
        for k1, a1 in dirs:
            for k2, a2 in dirs:
                off = abs(math.remainder(a1 - a2, 2 * math.pi))
                if k1 < k2 and off > MAX_STRAIGHT_ANGLE:
                    raise CalibrationRefusedError(
                        f"steps {k1 + 1} and {k2 + 1} (straights): {devices[i]} went "
                        f"{math.degrees(off):.2f} deg apart (at most "
                        f"{math.degrees(MAX_STRAIGHT_ANGLE):.1f} deg): the robot moved sideways "
                        "or turned; push it along the same straight edge and record them again"
                    )
    i_str = [k for k, s in enumerate(steps) if s.kind == "straight"]
    i_spin = [k for k, s in enumerate(steps) if s.kind == "spin"]
    sums = np.array([s.totals for s in steps])  # (S, n, 2)
    # count noise is a random walk: a step's sum scatters with the square root of its path
    # (per sensor, relative to the mean path; a count's quantisation as the floor)
    path = np.array([np.hypot(s.d[:, :, 0], s.d[:, :, 1]).sum(axis=0) for s in steps])  # (S, n)
    path = np.maximum(path, 100 * resolution_m)
    weight = np.sqrt(path.mean() / path)  # (S, n): 1 / relative scatter

    # start values: yaw from the straight-run formula, scales 1 (or from the distance)
    p0 = np.zeros(5 * n)
    for i, dev in enumerate(devices):
        c = straight_run[dev]
        p0[5 * i : 5 * i + 3] = (c.angle_offset, c.scale, c.scale)
    a0 = []
    for k in i_str:
        corr = [(_g(p0[5 * i : 5 * i + 5]) @ sums[k, i])[1] for i in range(n)]
        a0.append(float(np.mean(corr)))
    c0 = [signs[k] * spin_angle for k in i_spin]
    for i in range(n):
        g = _g(p0[5 * i : 5 * i + 5])
        pos = np.mean([-(g @ sums[k, i]) / c for k, c in zip(i_spin, c0, strict=True)], axis=0)
        p0[5 * i + 3 : 5 * i + 5] = pos
    theta0 = np.concatenate([p0, a0, c0])
    n_str = len(i_str)

    def residuals(theta: np.ndarray, sigma: float) -> tuple[np.ndarray, int]:
        a = theta[5 * n : 5 * n + n_str]
        c = theta[5 * n + n_str :]
        out = []
        for i in range(n):
            q = theta[5 * i : 5 * i + 5]
            g = _g(q)
            for j, k in enumerate(i_str):
                out.extend((g @ sums[k, i] - (0.0, a[j])) * (weight[k, i] / sigma))
            for j, k in enumerate(i_spin):
                out.extend((g @ sums[k, i] + c[j] * q[3:5]) * (weight[k, i] / sigma))
        data = len(out)
        for i in range(n):
            out.append((theta[5 * i + 1] / theta[5 * i + 2] - 1.0) / anisotropy_sd)
        if true_distance is None and scale_reference == "mounts":
            radius = np.mean([math.hypot(*theta[5 * i + 3 : 5 * i + 5]) for i in range(n)])
            out.append((radius - nominal_radius) / 1e-9)
        elif true_distance is None:
            out.append((np.mean(theta[2 : 5 * n : 5]) - 1.0) / 1e-6)
        else:
            for j, k in enumerate(i_str):
                out.append((a[j] - signs[k] * true_distance) / DISTANCE_SD)
        for j, k in enumerate(i_spin):
            out.append((c[j] - signs[k] * spin_angle) / SPIN_ANGLE_SD)
        return np.array(out), data

    def jacobian(theta: np.ndarray, sigma: float) -> np.ndarray:
        r0, _ = residuals(theta, sigma)
        jac = np.empty((r0.size, theta.size))
        for k in range(theta.size):
            h = 1e-7 * max(1.0, abs(theta[k]))
            tp = theta.copy()
            tp[k] += h
            tm = theta.copy()
            tm[k] -= h
            jac[:, k] = (residuals(tp, sigma)[0] - residuals(tm, sigma)[0]) / (2 * h)
        return jac

    def solve(theta: np.ndarray, sigma: float) -> np.ndarray:
        for _ in range(30):
            r, _ = residuals(theta, sigma)
            jac = jacobian(theta, sigma)
            step, *_ = np.linalg.lstsq(jac, -r, rcond=None)
            theta = theta + step
            if np.max(np.abs(step)) < 1e-12:
                break
        return theta

    sigma = resolution_m
    theta = solve(theta0, sigma)
    r, n_data = residuals(theta, sigma)
    rss = float(np.sum((r[:n_data] * sigma) ** 2))
    dof = n_data - theta.size + (r.size - n_data)
    sigma = max(math.sqrt(rss / dof) if dof > 0 else 0.0, resolution_m / math.sqrt(6))
    theta = solve(theta, sigma)
    jac = jacobian(theta, sigma)
    cov = np.linalg.pinv(jac.T @ jac)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))

    # per-step residuals (m) and the sideways check on the straights
    step_res = np.zeros((len(steps), n))
    for i in range(n):
        q = theta[5 * i : 5 * i + 5]
        g = _g(q)
        for j, k in enumerate(i_str):
            v = g @ sums[k, i]
            step_res[k, i] = math.hypot(v[0], v[1] - theta[5 * n + j])
        for j, k in enumerate(i_spin):
            step_res[k, i] = float(np.hypot(*(g @ sums[k, i] + theta[5 * n + n_str + j] * q[3:5])))
    # a spin far from the entered angle: the mount radius tells how far it turned
    for k in i_spin:
        est = np.mean(
            [
                np.hypot(*(_g(theta[5 * i : 5 * i + 5]) @ sums[k, i]))
                / math.hypot(*theta[5 * i + 3 : 5 * i + 5])
                for i in range(n)
            ]
        )
        nom = np.mean(
            [np.hypot(*sums[k, i]) / math.hypot(nominal[i].x, nominal[i].y) for i in range(n)]
        )
        for what, value in (("fitted", est), ("nominal", nom)):
            if abs(value / spin_angle - 1) > SPIN_ANGLE_TOLERANCE:
                raise CalibrationRefusedError(
                    f"step {k + 1} (spin): it turned about {math.degrees(value):.0f} deg (from the "
                    f"{what} mount radius), but each spin must turn {math.degrees(spin_angle):.0f} "
                    "deg; turn it exactly that far (back to the start mark) or enter the angle "
                    "you turned"
                )
    sensors = []
    for i, dev in enumerate(devices):
        q, e = theta[5 * i : 5 * i + 5], se[5 * i : 5 * i + 5]
        _check_scale(dev, "X", float(q[1]), true_distance)
        _check_scale(dev, "Y", float(q[2]), true_distance)
        yaw = math.remainder(float(q[0]), 2 * math.pi)
        sensors.append(
            SensorCalibration(
                yaw if yaw != -math.pi else math.pi,
                float(sum(np.hypot(*sums[k, i]) for k in i_str)),
                scale_x=float(q[1]),
                scale_y=float(q[2]),
                x=float(q[3]),
                y=float(q[4]),
                angle_offset_se=float(e[0]),
                scale_x_se=float(e[1]),
                scale_y_se=float(e[2]),
                x_se=float(e[3]),
                y_se=float(e[4]),
            )
        )
    drift = _predicted_drift(theta, cov, n, sensor)
    fitted_radius = float(np.mean([math.hypot(*theta[5 * i + 3 : 5 * i + 5]) for i in range(n)]))
    # with nominal_radius 0 (mounts at the centre) nothing to compare: 1, i.e. "agrees"
    return MountFit(
        devices=devices,
        sensors=tuple(sensors),
        straight_run=straight_run,
        drift_per_m=drift,
        step_residuals=step_res,
        sigma=sigma,
        spin_angles=theta[5 * n + n_str :].copy(),
        straight_lengths=theta[5 * n : 5 * n + n_str].copy(),
        covariance=cov,
        scale_reference="distance" if true_distance is not None else scale_reference,
        mounts_scale=nominal_radius / fitted_radius if nominal_radius * fitted_radius > 0 else 1.0,
        mounts_scale_se=(MOUNT_SD / nominal_radius / math.sqrt(n)) if nominal_radius > 0 else 0.0,
    )


def _yaw_rate_row(method: str, mounts: list[tuple[float, float]], sensor: int) -> np.ndarray:
    """The method's linear map from corrected sums (dX1, dY1, dX2, ...) to dtheta (rad)."""
    n = len(mounts)
    row = np.zeros(2 * n)
    if method == "exact":
        row[2 * sensor] = -1.0 / mounts[sensor][0]
        return row
    a_mat = []
    for px, py in mounts:
        a_mat += [[0.0, -1.0, -px], [1.0, 0.0, -py]]
    return np.linalg.pinv(np.array(a_mat))[2]


def _predicted_drift(theta: np.ndarray, cov: np.ndarray, n: int, sensor: int) -> dict[str, float]:
    """1-sigma heading drift per metre driven straight, per method (docs: "calibration fit").

    The true reported vector of a unit straight is estimated as G(theta)^-1 (0, 1)
    per sensor; a calibration theta' corrects it to G(theta') G(theta)^-1 (0, 1),
    whose difference to (0, 1) the method turns into a yaw increment. Its
    gradient in theta' and the fit's covariance give the variance.
    """
    unit = [np.linalg.solve(_g(theta[5 * i : 5 * i + 5]), (0.0, 1.0)) for i in range(n)]
    mounts = [(float(theta[5 * i + 3]), float(theta[5 * i + 4])) for i in range(n)]

    def delta(t: np.ndarray) -> np.ndarray:
        return np.concatenate([_g(t[5 * i : 5 * i + 5]) @ unit[i] for i in range(n)])

    jd = np.empty((2 * n, theta.size))
    for k in range(5 * n):
        h = 1e-7 * max(1.0, abs(theta[k]))
        tp, tm = theta.copy(), theta.copy()
        tp[k] += h
        tm[k] -= h
        jd[:, k] = (delta(tp) - delta(tm)) / (2 * h)
    jd[:, 5 * n :] = 0.0
    out = {}
    methods = ["exact"] + (["two-sensor"] if n >= 2 else [])
    for m in methods:
        if m == "exact" and mounts[sensor][0] == 0:
            continue
        g = _yaw_rate_row(m, mounts, sensor) @ jd
        out[m] = float(math.sqrt(max(g @ cov @ g, 0.0)))
    return out


def fit_advice(fit: MountFit, method: str) -> str:
    """What to add to the run for a better fit, in a few sentences (the wizard's results page).

    The count noise is a random walk, so a straight's direction -- what the heading drift
    comes from -- is known to about noise * sqrt(L) / L: the drift falls with the square root
    of the straights' total length (measured in mm_pc.bench.pose_calibration's sim, 0.5 to
    4 m: docs/pose-math.md "What one short run gives"), and straights four times as long
    halve it. Without a measured length the distances keep the scale reference's error
    (:data:`SCALE_REFERENCES`); the spins against the configured mount radii
    (``fit.mounts_scale``) say how far the sensors' own scale is off.
    """
    drift = fit.drift_per_m.get(method)
    if drift is None and fit.drift_per_m:
        method, drift = max(fit.drift_per_m.items(), key=lambda kv: kv[1])
    out = []
    total = fit.straight_total_m
    n_str = max(len(fit.straight_lengths), 1)
    if drift is not None and total > 0:
        each = 4 * total / n_str
        out.append(
            f"Your straights total {total:.1f} m: {method} keeps about "
            f"{math.degrees(drift):.2f} deg of heading per metre driven (1 sigma), "
            f"{math.degrees(drift) * 10:.1f} deg after 10 m. The drift falls with the square "
            f"root of the straights' length: record straights of {each:.1f} m (four times as "
            f"long) to halve it."
        )
    if fit.scale_reference != "distance":
        scale = 1.0 / fit.mounts_scale if fit.scale_reference == "sensors" else 1.0
        ref = {
            "sensors": "the sensors' CPI (typically a few % off)",
            "mounts": "the spins and the configured mount positions "
            f"(±{fit.mounts_scale_se * 100:.1f} % for mounts measured to "
            f"{MOUNT_SD * 1000:.0f} mm)",
        }[fit.scale_reference]
        sentence = f"No length was measured: distances take their scale from {ref}."
        if fit.scale_reference == "sensors" and math.isfinite(scale):
            sentence += (
                f" The spins against the configured mounts say distances read "
                f"{abs(scale - 1) * 100:.1f} % {'long' if scale > 1 else 'short'} "
                f"(±{fit.mounts_scale_se * 100:.1f} % if the mounts are right to "
                f"{MOUNT_SD * 1000:.0f} mm): choose the mounts as the scale on the distance "
                "page if you measured them."
            )
        out.append(
            sentence + " Best: measure one straight with a tape and enter its length "
            "(1 mm on 1 m is 0.1 %)."
        )
    return " ".join(out)
