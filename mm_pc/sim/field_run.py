"""A simulated lawn-mowing run with every sensor of seeds 000, 003 and 004, and its fusion.

Pure numpy, no ROS, no Qt. :func:`simulate_field_run` drives a mower over a
rectangular plot (default 20 m x 10 m, origin at the south-west corner, x east,
y north: the plot grid of seed 004, REP 103) and records, from one seeded
``numpy.random.Generator``, what its sensors would report;
:func:`run_fusion` replays that through :class:`mm_pc.core.fusion.ekf.PoseEKF`.

Derivations and measurements: docs/maps-and-fixes.md,
section "mm_pc.sim.field_run in detail".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mm_pc.core.angles import compass_to_rep103, rep103_to_compass
from mm_pc.core.fixes.gps import GpsQuality, LocalGrid, gps_accuracy_m, gps_fix_usable
from mm_pc.core.fixes.perimeter import PerimeterSegment, rectangle_perimeter
from mm_pc.core.fixes.wheels import tick_length
from mm_pc.core.fusion.ekf import PoseEKF, increments_from_poses
from mm_pc.core.fusion.inputs import (
    AxisInput,
    HeadingInput,
    MotionInput,
    PositionInput,
    RangeInput,
    gps_inflation,
    inflate_for_correlation,
)
from mm_pc.core.fusion.loop import FusionCore
from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.maps.trilateration import (
    Beacon,
    TrilaterationError,
    least_squares_fix,
    simulate_ranges,
)
from mm_pc.core.odometry import Odometry, Pose2D, arc_poses
from mm_pc.sim import robot as simulator

__all__ = [
    "FUSION_INPUTS",
    "MOTION_SOURCES",
    "CompassReading",
    "FieldSim",
    "GpsReading",
    "RangeReading",
    "WireContact",
    "corner_beacons",
    "errors",
    "lawn_path",
    "plot_grid",
    "run_fusion",
    "simulate_field_run",
]

PLOT_W, PLOT_H = 20.0, 10.0  # m
SPEED = 0.3  # m/s
LANE_SPACING = 1.0  # m
LANES = 10
OVERSHOOT = 0.3  # m past the east/west wire before the turn
DOCK = Pose2D(2.0, -1.0, math.pi / 2)  # south of the plot, facing north

ODOM_HZ = 20
GPS_EVERY, BEACON_EVERY, COMPASS_EVERY = 10, 4, 2  # requests: 2 Hz, 5 Hz, 10 Hz

MOUSE_CPI = 1600.0
MOUSE_NOISE_COUNTS = 0.2
MOUSE_SCALE = 1.01
MOUSE_MOUNT_YAW = math.radians(0.5)
MOUSE_CAL_RESIDUAL = math.radians(0.01)
ODOM_METHOD = "exact"

TRACK_WIDTH = 0.36  # m, a mower's wheel track
WHEEL_DIAMETER, WHEEL_TICKS = 0.18, 360

GPS_UERE = 2.5  # m (seed 004: +-2.5 m in good conditions)
GPS_TAU = 30.0  # s, correlation time of the GPS error
GPS_BAD_P, GPS_GHOST_P = 0.08, 0.01
GPS_ORIGIN = (48.2, 16.37)  # deg, the plot's SW corner (a garden near Vienna)

BEACON_HEIGHT = 1.0  # m above the range antenna
RANGE_SIGMA = 0.05  # m
RANGE_NLOS_P = 0.02

COMPASS_SIGMA = math.radians(2.0)
COMPASS_BIAS = math.radians(1.0)

WIRE_SIGMA = 0.03  # m

#: names :func:`run_fusion` accepts in ``use``.
FUSION_INPUTS = ("gps", "beacons", "trilateration", "compass", "perimeter")
#: motion models :func:`run_fusion` accepts.
MOTION_SOURCES = ("mouse", "wheels")


# --- measurements -----------------------------------------------------------------------


@dataclass(frozen=True)
class GpsReading:
    """One GPS epoch: ``k`` = request index it belongs to (pose index k in the arrays).

    ``lat``/``lon`` deg (what a NavSatFix carries); ``xy`` the same in plot
    metres; ``quality`` HDOP, satellites, fix type; ``error_m`` the true
    error (for evaluation only).
    """

    k: int
    t: float
    lat: float
    lon: float
    xy: tuple[float, float]
    quality: GpsQuality
    error_m: float


@dataclass(frozen=True)
class RangeReading:
    """Slant ranges (m) to each beacon in :attr:`FieldSim.beacons` order at request ``k``."""

    k: int
    t: float
    ranges: tuple[float, ...]


@dataclass(frozen=True)
class CompassReading:
    """Compass heading at request ``k``: seed convention, rad, 0 = north, clockwise+."""

    k: int
    t: float
    heading: float


@dataclass(frozen=True)
class WireContact:
    """The wire sensor fired during request ``k``; ``wire`` is the truth (evaluation only)."""

    k: int
    t: float
    wire: PerimeterSegment


@dataclass
class FieldSim:
    """One simulated run. Pose arrays have one row per request end, row 0 = the start.

    ``t`` (N+1,) s; ``truth``, ``raw`` (N+1, 3) x, y m (plot frame), yaw rad
    (continuous); ``mouse`` (N, 3) the raw odometry's body increments
    (fwd m, left m, dtheta rad) per request; ``wheels`` (N, 2) measured wheel
    travel (left, right) m per request; ``raw_wheels`` (N+1, 3) the wheel
    odometry's own path; measurement lists in time order. The remaining
    fields are what the replay needs: beacons, GPS grid, wires, and the noise
    figures it weights the readings with (m, m^2, rad^2).
    """

    t: np.ndarray
    truth: np.ndarray
    raw: np.ndarray
    mouse: np.ndarray
    wheels: np.ndarray
    raw_wheels: np.ndarray
    gps: list[GpsReading]
    ranges: list[RangeReading]
    compass: list[CompassReading]
    contacts: list[WireContact]
    beacons: tuple[Beacon, ...]
    grid: LocalGrid
    wires: tuple[PerimeterSegment, ...]
    plot: tuple[float, float] = (PLOT_W, PLOT_H)
    track_width: float = TRACK_WIDTH
    range_sigma: float = RANGE_SIGMA
    compass_var: float = COMPASS_SIGMA**2 + COMPASS_BIAS**2
    wire_var: float = WIRE_SIGMA**2
    gps_inflation: float = 1.0
    run_length_m: float = 0.0


# --- the path ----------------------------------------------------------------------------


def _pieces_to_twists(pieces, speed: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(length m, radius m or 0 for straight, turn sign) pieces -> per-step (v, omega)."""
    v_parts, w_parts = [], []
    for length, radius, sign in pieces:
        n = round(length / speed / dt)
        v_parts.append(np.full(n, speed))
        w_parts.append(np.full(n, sign * speed / radius if radius else 0.0))
    return np.concatenate(v_parts), np.concatenate(w_parts)


def lawn_path(speed: float = SPEED, dt: float = simulator.DT) -> tuple[np.ndarray, np.ndarray]:
    """The mowing run's twists (v m/s, omega rad/s) per ``dt`` step, starting at :data:`DOCK`."""
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be a finite number of m/s > 0, got {speed}")
    r = LANE_SPACING / 2
    quarter, half = math.pi * r / 2, math.pi * r
    lane = PLOT_W + 2 * OVERSHOOT
    first_lane = PLOT_W + OVERSHOOT - (DOCK.x + r)
    pieces = [(1.2, 0.0, 0), (quarter, r, -1), (first_lane, 0.0, 0)]
    for i in range(1, LANES):
        pieces.append((half, r, 1 if i % 2 else -1))  # left after an eastward lane
        pieces.append((lane if i < LANES - 1 else 5.8, 0.0, 0))
    pieces += [(quarter, r, -1), (0.8, 0.0, 0)]  # last lane runs west: right turn = north
    return _pieces_to_twists(pieces, speed, dt)


def _to_plot(local: np.ndarray, start: Pose2D) -> np.ndarray:
    """Poses relative to the start (integrate_pose) -> plot frame."""
    c, s = math.cos(start.yaw), math.sin(start.yaw)
    out = np.empty_like(local)
    out[:, 0] = start.x + c * local[:, 0] - s * local[:, 1]
    out[:, 1] = start.y + s * local[:, 0] + c * local[:, 1]
    out[:, 2] = start.yaw + local[:, 2]
    return out


# --- sensors -------------------------------------------------------------------------------


def _wheel_travel(v: np.ndarray, w: np.ndarray, ends: np.ndarray, gen) -> np.ndarray:
    """Measured (left, right) wheel travel (m) per request: slip, bursts, tick quantisation."""
    half = TRACK_WIDTH / 2 * w * simulator.DT
    per_step = np.stack([v * simulator.DT - half, v * simulator.DT + half], axis=1)
    starts = np.concatenate([[0], ends[:-1]])
    req = np.add.reduceat(per_step, starts, axis=0)
    factor = 1.02 + 0.02 * gen.standard_normal(req.shape)
    t_end = ends * simulator.DT
    t = 0.0
    while True:  # slip bursts: Poisson, about one a minute, one wheel, 0.5-2 s, +10 %
        t += gen.exponential(60.0)
        if t >= t_end[-1]:
            break
        burst = (t_end > t) & (t_end <= t + gen.uniform(0.5, 2.0))
        factor[burst, gen.integers(2)] += 0.1
    tick = tick_length(WHEEL_DIAMETER, WHEEL_TICKS)
    cum = np.floor(np.cumsum(req * factor, axis=0) / tick) * tick
    return np.diff(cum, axis=0, prepend=np.zeros((1, 2)))


def _crossings(poses: np.ndarray) -> list[tuple[int, PerimeterSegment]]:
    """(index into ``poses`` just after the crossing, wire) for every wire crossing."""
    out = []
    for wire in rectangle_perimeter(PLOT_W, PLOT_H):
        i_across, i_along = (0, 1) if wire.axis == "x" else (1, 0)
        side = poses[:, i_across] < wire.value
        idx = np.flatnonzero(side[1:] != side[:-1]) + 1
        along = poses[idx, i_along]
        out += [
            (int(i), wire) for i, a in zip(idx, along, strict=True) if wire.start <= a <= wire.end
        ]
    return sorted(out, key=lambda e: e[0])


def _gps_readings(truth, t, grid, gen) -> list[GpsReading]:
    """2 Hz GPS epochs with wandering (Gauss-Markov) error, bad epochs and ghosts."""
    ks = np.arange(GPS_EVERY, truth.shape[0], GPS_EVERY)
    phi = math.exp(-GPS_EVERY / ODOM_HZ / GPS_TAU)
    u = np.empty((ks.size, 2))
    u[0] = gen.standard_normal(2)
    for j in range(1, ks.size):
        u[j] = phi * u[j - 1] + math.sqrt(1 - phi * phi) * gen.standard_normal(2)
    out = []
    for j, k in enumerate(ks):
        roll = gen.uniform()
        hdop = gen.uniform(0.7, 1.6)
        sats = int(gen.integers(6, 13))
        err = u[j] * hdop * GPS_UERE / math.sqrt(2)
        if roll < GPS_BAD_P:
            if roll < GPS_BAD_P / 2:
                hdop = gen.uniform(3.0, 8.0)
            else:
                sats = int(gen.integers(3, 5))
            err = err + _random_vector(gen, 4.0, 12.0)
        elif roll < GPS_BAD_P + GPS_GHOST_P:
            err = err + _random_vector(gen, 6.0, 10.0)
        x, y = truth[k, 0] + err[0], truth[k, 1] + err[1]
        lat, lon = grid.to_geodetic(x, y)
        out.append(
            GpsReading(
                int(k),
                float(t[k]),
                float(lat),
                float(lon),
                (float(x), float(y)),
                GpsQuality(float(hdop), sats, 1),
                float(math.hypot(*err)),
            )
        )
    return out


def _random_vector(gen, lo: float, hi: float) -> np.ndarray:
    a = gen.uniform(0, 2 * math.pi)
    return gen.uniform(lo, hi) * np.array([math.cos(a), math.sin(a)])


def corner_beacons(height: float = BEACON_HEIGHT) -> tuple[Beacon, ...]:
    """Four beacons at the plot corners, ``height`` m above the robot's range antenna."""
    corners = (("SW", 0.0, 0.0), ("SE", PLOT_W, 0.0), ("NE", PLOT_W, PLOT_H), ("NW", 0.0, PLOT_H))
    return tuple(Beacon(x, y, float(height), name) for name, x, y in corners)


def plot_grid() -> LocalGrid:
    """The plot's GPS grid, scales from the surveyed SW and NE corners (the seed's method)."""
    wgs = LocalGrid(*GPS_ORIGIN)
    ne_lat, ne_lon = wgs.to_geodetic(PLOT_W, PLOT_H)
    return LocalGrid.from_plot(*GPS_ORIGIN, float(ne_lat), float(ne_lon), PLOT_W, PLOT_H)


# --- the run ---------------------------------------------------------------------------------


def simulate_field_run(seed: int | np.random.Generator = 1) -> FieldSim:
    """Simulate the mowing run; ``seed`` (int or Generator) fixes every noise draw."""
    gen = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    v, w = lawn_path()
    true_mounts = simulator.with_mount_yaw(DEFAULT_MOUNTS, MOUSE_MOUNT_YAW)
    req = simulator.request_samples(
        v, w, true_mounts, float(ODOM_HZ), cpi=MOUSE_CPI, noise_counts=MOUSE_NOISE_COUNTS, rng=gen
    )
    cal_mounts = simulator.with_mount_yaw(DEFAULT_MOUNTS, MOUSE_MOUNT_YAW - MOUSE_CAL_RESIDUAL)
    odo = Odometry(cal_mounts, ODOM_METHOD, pose=DOCK)
    start = DOCK.as_array()[None, :]
    raw = np.vstack([start, odo.integrate(req.dt, req.d * MOUSE_SCALE)])
    truth = np.vstack([start, _to_plot(req.truth, DOCK)])
    t = np.concatenate([[0.0], req.end_step * simulator.DT])
    n = req.dt.size

    wheels = _wheel_travel(v, w, req.end_step, gen)
    a = 0.5 * (wheels[:, 0] + wheels[:, 1])
    c = (wheels[:, 1] - wheels[:, 0]) / TRACK_WIDTH
    raw_wheels = np.vstack([start, arc_poses(DOCK.as_array(), a, None, c)])

    grid = plot_grid()
    gps = _gps_readings(truth, t, grid, gen)

    beacons = corner_beacons()
    ranges = []
    for k in range(BEACON_EVERY, n + 1, BEACON_EVERY):
        r = simulate_ranges(beacons, truth[k, 0], truth[k, 1], RANGE_SIGMA, gen)
        nlos = gen.uniform(size=r.size) < RANGE_NLOS_P
        r[nlos] += gen.uniform(0.3, 1.5, size=int(nlos.sum()))
        ranges.append(RangeReading(k, float(t[k]), tuple(float(x) for x in r)))

    ks = np.arange(COMPASS_EVERY, n + 1, COMPASS_EVERY)
    heading = rep103_to_compass(truth[ks, 2]) + COMPASS_BIAS
    heading = np.mod(heading + gen.normal(0.0, COMPASS_SIGMA, ks.size), 2 * math.pi)
    compass = [
        CompassReading(int(k), float(t[k]), float(h)) for k, h in zip(ks, heading, strict=True)
    ]

    full = np.vstack([start, _to_plot(simulator.integrate_pose(v, w, simulator.DT), DOCK)])
    contacts = []
    for step, wire in _crossings(full):
        k = int(np.searchsorted(req.end_step, step)) + 1
        contacts.append(WireContact(k, float(t[k]), wire))

    return FieldSim(
        t=t,
        truth=truth,
        raw=raw,
        mouse=increments_from_poses(raw),
        wheels=wheels,
        raw_wheels=raw_wheels,
        gps=gps,
        ranges=ranges,
        compass=compass,
        contacts=contacts,
        beacons=beacons,
        grid=grid,
        wires=rectangle_perimeter(PLOT_W, PLOT_H),
        run_length_m=float(np.sum(v) * simulator.DT),
        gps_inflation=gps_inflation(GPS_EVERY / ODOM_HZ, GPS_TAU),
    )


# --- replay ---------------------------------------------------------------------------------

#: After this many rejections in a row of one source the filter is taken to be lost
#: (off by more than its covariance admits, so it would reject every later reading too):
#: that source's next reading is applied ungated, to re-acquire.
REACQUIRE_AFTER = 10

#: EKF noise for wheel odometry as the motion model (m^2/m, rad^2/m, rad^2/rad): slip of
#: a few per cent per wheel, i.e. about twice the mouse's spread along and 3x in heading.
WHEEL_NOISE = {"q_pos": 0.03**2, "q_yaw_dist": 0.03**2, "q_yaw_turn": 0.03**2}

#: The replay's frame names (the node only checks that they stay the same).
_FRAMES = {"mouse": "odom", "wheel": "wheel_odom"}


def _input_of(source: str) -> str:
    """The :data:`FUSION_INPUTS` name of a FusionCore source ('beacon/SW' -> 'beacons')."""
    return "beacons" if source.startswith("beacon/") else source


def _readings_by_request(sim: FieldSim, use: Sequence[str]) -> dict[int, list]:
    events: dict[int, list] = {}
    lists = {
        "compass": sim.compass,
        "beacons": sim.ranges,
        "trilateration": sim.ranges,
        "gps": sim.gps,
        "perimeter": sim.contacts,
    }
    for name in FUSION_INPUTS:
        if name in use:
            for m in lists[name]:
                events.setdefault(m.k, []).append((name, m))
    return events


def _records(core: FusionCore, sim: FieldSim, name: str, m, stamp: float) -> list:
    """The FusionCore records of one simulated reading, as mm-fusion would read them from
    mm-field-sim's topics. A reading without a usable value is counted as such instead."""
    if name == "compass":
        yaw = float(compass_to_rep103(m.heading))
        return [HeadingInput(stamp, "compass", yaw, sim.compass_var)]
    if name == "beacons":
        return [
            RangeInput(stamp, f"beacon/{b.name}", b, float(r), sim.range_sigma)
            for b, r in zip(sim.beacons, m.ranges, strict=True)
        ]
    if name == "trilateration":
        try:
            fix = least_squares_fix(
                sim.beacons, m.ranges, sim.range_sigma, initial=tuple(core.ekf.state[:2])
            )
        except TrilaterationError as exc:
            core.count("trilateration", "unusable", str(exc))
            return []
        cov = tuple(tuple(float(v) for v in row) for row in fix.covariance)
        return [PositionInput(stamp, "trilateration", (fix.x, fix.y), cov)]
    if name == "gps":
        if not gps_fix_usable(m.quality):
            core.count("gps", "unusable", "GPS quality too poor")
            core.heard("gps", stamp)
            return []
        var = gps_accuracy_m(m.quality) ** 2 / 2
        x, y = sim.grid.to_local(m.lat, m.lon)
        fix = PositionInput(stamp, "gps", (float(x), float(y)), ((var, 0.0), (0.0, var)))
        return [inflate_for_correlation(fix, sim.gps_inflation)]
    # perimeter: which wire is a guess from the estimate, as on the robot
    return [AxisInput(stamp, "perimeter", None, None)]


def run_fusion(
    sim: FieldSim,
    use: Sequence[str] = ("gps", "beacons", "compass", "perimeter"),
    motion: str = "mouse",
    stats: dict | None = None,
) -> np.ndarray:
    """Replay ``sim`` through :class:`~mm_pc.core.fusion.loop.FusionCore`; the (N+1, 3) fused poses.

    The same loop as ``mm-fusion``: one :meth:`~mm_pc.core.fusion.loop.FusionCore.step` per
    request for its odometry, one for the readings that belong to its end. ``use``: which
    corrections to apply, a subset of :data:`FUSION_INPUTS` ('beacons' = raw ranges, one
    record per beacon; 'trilateration' = the same ranges as least-squares fixes).
    ``motion``: 'mouse' (the raw mouse odometry's poses) or 'wheels' (the wheel odometry's
    poses, which FusionCore takes as the motion model when no mouse odometry comes). Row k
    is the estimate after request k's predict and its measurements. ``stats``, if given,
    receives counts: ``predicts``; ``applied``, ``rejected`` (failed the gate),
    ``skipped`` (not usable: bad GPS quality, no trilateration fix, no wire near) and
    ``reacquired`` (applied ungated after :data:`REACQUIRE_AFTER` rejections in a row),
    in total and per input under ``by_input``.
    """
    if isinstance(use, str) or any(u not in FUSION_INPUTS for u in use):
        raise ValueError(f"use must be a collection of names from {FUSION_INPUTS}, got {use!r}")
    if motion not in MOTION_SOURCES:
        raise ValueError(f"motion must be one of {MOTION_SOURCES}, got {motion!r}")
    source, poses = ("mouse", sim.raw) if motion == "mouse" else ("wheel", sim.raw_wheels)
    core = FusionCore(
        PoseEKF(Pose2D(*sim.truth[0])),
        wheel_noise=(WHEEL_NOISE["q_pos"], WHEEL_NOISE["q_yaw_dist"], WHEEL_NOISE["q_yaw_turn"]),
        reacquire_after=REACQUIRE_AFTER,
        wires=sim.wires,
        wire_var=sim.wire_var,
        wire_max_distance=2.0,
    )
    readings = _readings_by_request(sim, use)
    out = np.empty((poses.shape[0], 3))
    for k in range(poses.shape[0]):
        stamp = float(sim.t[k])
        core.step([MotionInput(stamp, source, _FRAMES[source], Pose2D(*poses[k]))])
        records = []
        for name, m in readings.get(k, ()):
            records += _records(core, sim, name, m, stamp)
        core.step(records)
        out[k] = core.ekf.state
    if stats is not None:
        kinds = ("applied", "rejected", "skipped", "reacquired")
        by_input = {name: dict.fromkeys(kinds, 0) for name in use}
        for src, c in core.counts.items():
            name = _input_of(src)
            if name not in by_input:
                continue
            count = by_input[name]
            count["applied"] += c.accepted
            count["rejected"] += c.rejected
            count["skipped"] += c.unusable + c.invalid + c.stale
            count["reacquired"] += c.reacquired
        stats.clear()
        stats["predicts"] = int(poses.shape[0] - 1)
        for kind in kinds:
            stats[kind] = sum(c[kind] for c in by_input.values())
        stats["by_input"] = by_input
    return out


def errors(sim: FieldSim, poses: np.ndarray) -> dict[str, float]:
    """Position errors (m) of ``poses`` (N+1, 3) against the truth: final, max, RMS."""
    e = np.hypot(poses[:, 0] - sim.truth[:, 0], poses[:, 1] - sim.truth[:, 1])
    return {
        "final_m": float(e[-1]),
        "max_m": float(np.max(e)),
        "rms_m": float(np.sqrt(np.mean(e * e))),
    }
