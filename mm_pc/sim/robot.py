"""Ground-truth simulator: a differential-drive robot on scripted paths.

Pure numpy, no ROS, no Qt. A path is a sequence of body twists (v, omega)
held for ``dt`` each (v in m/s along base_link x, omega in rad/s CCW+). From
it the simulator computes what each mounted sensor measures: mouse sensors
integrate the surface velocity in their own (rotating) frame, so for a twist
held constant over a step the sensor-frame displacement of that step is
exact -- no pose integration is involved in the counts.

Frames: base_link per REP 103 (x forward, y left, yaw CCW+). The sensor's own
axes follow the seed: sensor +y = robot forward, sensor +x = robot right.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from mm_pc.core.geometry import DEFAULT_MOUNTS, SensorMount
from pln2033 import INCH_M

__all__ = [
    "DEFAULT_MOUNTS",
    "DT",
    "TRAJECTORIES",
    "RequestSamples",
    "SensorMount",
    "cumulative_sensor_path",
    "guided_calibration_run",
    "guided_calibration_steps",
    "integrate_pose",
    "lift_mask",
    "load_trajectory_file",
    "request_boundaries",
    "request_samples",
    "resolve_trajectory",
    "sensor_displacements",
    "trajectory",
    "with_mount_yaw",
]

DT = 0.001  # s, one 1 kHz poll


DEFAULT_AXIS_LENGTH = 0.079


def sensor_displacements(
    v: np.ndarray, omega: np.ndarray, dt: float, mount: SensorMount, vy=None
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step sensor-frame displacement (dX right, dY forward) in metres.

    The sensor at base_link (px, py) moves with body velocity
    (v - omega*py, vy + omega*px); in sensor axes (X = -base_link y, Y = base_link x)
    that is X = -(vy + omega*px), Y = v - omega*py, then turned by the mounting error.
    ``vy``: lateral slip (m/s, base_link +y = left), per step or scalar; None = 0.
    """
    lateral = omega * mount.x if vy is None else np.asarray(vy) + omega * mount.x
    ideal_x = -lateral * dt
    ideal_y = (v - omega * mount.y) * dt
    c, s = math.cos(mount.yaw), math.sin(mount.yaw)
    return c * ideal_x + s * ideal_y, -s * ideal_x + c * ideal_y


def integrate_pose(v: np.ndarray, omega: np.ndarray, dt: float, vy=None) -> np.ndarray:
    """Exact poses (x, y, yaw) after each step of constant twist, start at 0.

    ``vy``: lateral velocity (m/s, base_link +y), per step or scalar; None = 0.
    """
    yaw_end = np.cumsum(omega * dt)
    yaw_start = yaw_end - omega * dt
    dtheta = omega * dt
    # Chord of the arc: the body vector (v, vy)*dt shortened by sinc(dtheta/2),
    # at the heading yaw_start + dtheta/2.
    k = dt * np.sinc(dtheta / (2 * np.pi))
    heading = yaw_start + dtheta / 2
    c, s = np.cos(heading), np.sin(heading)
    if vy is None:
        x = np.cumsum(k * v * c)
        y = np.cumsum(k * v * s)
    else:
        vy = np.broadcast_to(np.asarray(vy, dtype=float), np.shape(v))
        x = np.cumsum(k * (v * c - vy * s))
        y = np.cumsum(k * (v * s + vy * c))
    return np.stack([x, y, yaw_end], axis=1)


# --- scripted paths (v, omega per step) ------------------------------------------------


def _segments(parts: list[tuple[float, float, float]], dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate (duration s, v, omega) segments into per-step arrays."""
    v_parts, w_parts = [], []
    for duration, v, w in parts:
        n = round(duration / dt)
        v_parts.append(np.full(n, v))
        w_parts.append(np.full(n, w))
    return np.concatenate(v_parts), np.concatenate(w_parts)


def straight(speed: float = 0.2, distance: float = 1.0, dt: float = DT):
    return _segments([(distance / abs(speed), speed, 0.0)], dt)


def still(duration: float = 10.0, dt: float = DT):
    return _segments([(duration, 0.0, 0.0)], dt)


def figure_eight(speed: float = 0.2, radius: float = 0.4, dt: float = DT):
    """Two full circles, left then right: ends where it started."""
    w = speed / radius
    lap = 2 * math.pi / w
    return _segments([(lap, speed, w), (lap, speed, -w)], dt)


def square(speed: float = 0.2, side: float = 0.5, turn_rate: float = 1.0, dt: float = DT):
    """Drive a square with pivot turns on the spot (left turns)."""
    parts = []
    for _ in range(4):
        parts.append((side / speed, speed, 0.0))
        parts.append(((math.pi / 2) / turn_rate, 0.0, turn_rate))
    return _segments(parts, dt)


def round_trip(speed: float = 0.2, distance: float = 1.0, turn_rate: float = 1.0, dt: float = DT):
    """The seed's round trip: out, turn on the spot, back."""
    return _segments(
        [
            (distance / speed, speed, 0.0),
            (math.pi / turn_rate, 0.0, turn_rate),
            (distance / speed, speed, 0.0),
        ],
        dt,
    )


def meander(
    speed: float = 0.2,
    lane_length: float = 3.4,
    lanes: int = 5,
    lane_spacing: float = 0.5,
    dt: float = DT,
):
    """Lawn-mower lanes: ``lanes`` straight lanes joined by half circles of
    diameter ``lane_spacing``, alternately left and right (default about 20 m:
    5 x 3.4 m + 4 x pi*0.25 m)."""
    r = lane_spacing / 2
    w = speed / r
    parts = []
    for i in range(lanes):
        parts.append((lane_length / speed, speed, 0.0))
        if i < lanes - 1:
            parts.append((math.pi / w, speed, w if i % 2 == 0 else -w))
    return _segments(parts, dt)


def _smooth(duration: float, v_of_t, w_of_t, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """One segment whose twist changes every step: v(t), omega(t) at the step midpoints."""
    t = (np.arange(round(duration / dt)) + 0.5) * dt
    v = np.broadcast_to(v_of_t(t), t.shape).astype(float)
    return v, np.broadcast_to(w_of_t(t), t.shape).astype(float)


def s_curves(speed: float = 0.2, duration: float = 50.0, dt: float = DT):
    """Speed and curvature changing continuously (no step in either): v swings
    between 0.5x and 1.5x ``speed``, omega is a sum of two sines (peak ~1 rad/s).
    About ``speed * duration`` metres (10 m by default)."""
    return _smooth(
        duration,
        lambda t: speed * (1.0 + 0.5 * np.sin(2 * np.pi * t / 13.0)),
        lambda t: 0.7 * np.sin(2 * np.pi * t / 9.0) + 0.3 * np.sin(2 * np.pi * t / 4.1),
        dt,
    )


def mixed_tour(speed: float = 0.2, dt: float = DT):
    """The ~12 m test tour: straights, continuously varying S-curves, spins on the
    spot both ways, reverse driving with a turn, an arc and a fast straight
    (2.5x ``speed``). The benchmark tour of ``mm-bench pose``."""
    parts = [
        _segments([(2.0 / speed, speed, 0.0)], dt),
        _smooth(
            4.0 / speed,
            lambda t: speed * (1.0 + 0.5 * np.sin(2 * np.pi * t / 7.0)),
            lambda t: 1.0 * np.sin(2 * np.pi * t / 8.0),
            dt,
        ),
        _segments([(2 * math.pi / 1.0, 0.0, 1.0)], dt),  # one full spin left
        _segments([(1.0 / speed, -speed, 0.2)], dt),  # reverse with a gentle turn
        _segments([(2.0 / (1.5 * speed), 1.5 * speed, -1.5 * speed / 0.6)], dt),  # arc right, r 0.6
        _segments([((math.pi / 2) / 1.0, 0.0, -1.0)], dt),  # quarter spin right
        _segments([(3.0 / (2.5 * speed), 2.5 * speed, 0.0)], dt),  # fast straight
    ]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def guided_calibration_steps(
    speed: float = 0.2,
    distance: float = 0.5,
    spins: int = 2,
    turn_rate: float = 1.0,
    pause: float = 0.5,
    dt: float = DT,
    straights: int = 1,
) -> list[tuple[str, int, int]]:
    """The steps of :func:`guided_calibration_run`: (kind, first step, end step) each.

    ``kind`` is "straight" or "spin" (the kinds of
    :mod:`mm_pc.core.calibration_fit`); steps index the 1 ms twist arrays.
    """
    out, t = [], round(pause / dt)
    moves = [("straight", distance / speed)] * (2 * straights)
    moves += [("spin", 2 * math.pi / turn_rate)] * (2 * spins)
    for kind, duration in moves:
        n = round(duration / dt)
        out.append((kind, t, t + n))
        t += n + round(pause / dt)
    return out


def guided_calibration_run(
    speed: float = 0.2,
    distance: float = 0.5,
    spins: int = 2,
    turn_rate: float = 1.0,
    pause: float = 0.5,
    dt: float = DT,
    straights: int = 1,
):
    """The calibration wizard's guided run: stand, ``straights`` times straight
    forward ``distance`` m and back, then ``spins`` full turns on the spot each
    way (left, right, left, ...), standing ``pause`` s before and after each
    (where the user presses Stop/Start). Steps: :func:`guided_calibration_steps`."""
    for name, k in (("spins", spins), ("straights", straights)):
        if not (isinstance(k, int) and k >= 1):
            raise ValueError(f"{name} must be an integer >= 1, got {k!r}")
    parts = [(pause, 0.0, 0.0)]
    moves = [(distance / speed, speed, 0.0), (distance / speed, -speed, 0.0)] * straights
    for k in range(2 * spins):
        w = turn_rate if k % 2 == 0 else -turn_rate
        moves.append((2 * math.pi / turn_rate, 0.0, w))
    for move in moves:
        parts += [move, (pause, 0.0, 0.0)]
    return _segments(parts, dt)


TRAJECTORIES: dict[str, Callable[..., tuple[np.ndarray, np.ndarray]]] = {
    "still": still,
    "straight": straight,
    "figure_eight": figure_eight,
    "square": square,
    "round_trip": round_trip,
    "meander": meander,
    "s_curves": s_curves,
    "mixed_tour": mixed_tour,
    "calibration_run": guided_calibration_run,
}


def trajectory(name: str, speed: float = 0.2, dt: float = DT) -> tuple[np.ndarray, np.ndarray]:
    """A named scripted path at ``speed`` m/s (see TRAJECTORIES)."""
    try:
        fn = TRAJECTORIES[name]
    except KeyError:
        raise ValueError(f"unknown trajectory '{name}'; known: {sorted(TRAJECTORIES)}") from None
    if name == "still":
        return fn(dt=dt)
    if not speed > 0:
        raise ValueError(f"speed must be > 0 m/s, got {speed}")
    return fn(speed=speed, dt=dt)


# --- paths from a file -------------------------------------------------------------------

FILE_PREFIX = "file:"
#: Longest interval between two rows of a trajectory file (s): at least 100 Hz.
MAX_FILE_INTERVAL_S = 0.01
FILE_HEADERS = (("t", "v", "w"), ("t", "vx", "vy", "w"))


def load_trajectory_file(
    path, dt: float = DT
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A path from a CSV file: per 1 kHz step (v m/s, omega rad/s, vy m/s or None).

    The file: a header ``t,v,w`` or ``t,vx,vy,w`` (s, m/s forward, m/s lateral slip to
    the left, rad/s CCW), then one row per sample, ``t`` strictly increasing at 100 Hz
    or faster (no interval over 10 ms); blank lines and lines starting with ``#`` are
    skipped. Time starts at the first row; each step's twist is the linear
    interpolation at the step's midpoint. Raises ValueError naming the file and the line.
    """
    import csv
    from pathlib import Path

    from mm_pc.core.user_file import read_user_text

    name = str(path)
    try:  # a regular file only (a FIFO blocked the start), <= 64 MiB (~1 h at 1 kHz)
        text = read_user_text(Path(path), 64 << 20)
    except OSError as e:
        raise ValueError(f"trajectory file {name}: cannot read it ({e.strerror or e})") from None
    except UnicodeDecodeError:
        raise ValueError(f"trajectory file {name}: not a text (CSV) file") from None
    header: tuple[str, ...] | None = None
    rows: list[list[float]] = []
    lines = []
    for no, raw in enumerate(text.splitlines(), start=1):
        if raw.strip() and not raw.lstrip().startswith("#"):
            lines.append((no, raw))
    if not lines:
        raise ValueError(f"trajectory file {name}: empty; it needs a header t,v,w or t,vx,vy,w")
    for no, fields in zip((n for n, _ in lines), csv.reader(r for _, r in lines), strict=True):
        cells = [c.strip() for c in fields]
        where = f"trajectory file {name}, line {no}"
        if header is None:
            if tuple(c.lower() for c in cells) not in FILE_HEADERS:
                raise ValueError(
                    f"{where}: header {','.join(cells)!r}; expected 't,v,w' or 't,vx,vy,w' "
                    "(s, m/s, [m/s,] rad/s)"
                )
            header = tuple(c.lower() for c in cells)
            continue
        if len(cells) != len(header):
            raise ValueError(f"{where}: {len(cells)} values, the header has {len(header)}")
        try:
            vals = [float(c) for c in cells]
        except ValueError:
            raise ValueError(f"{where}: not a number in {','.join(cells)!r}") from None
        if not all(math.isfinite(x) for x in vals):
            raise ValueError(f"{where}: {','.join(cells)!r} is not finite (NaN or inf)")
        if rows:
            gap = vals[0] - rows[-1][0]
            if not gap > 0:
                raise ValueError(f"{where}: t = {vals[0]:g} s does not increase")
            if gap > MAX_FILE_INTERVAL_S + 1e-9:
                raise ValueError(
                    f"{where}: {gap * 1e3:g} ms after the row before; the rate must be "
                    f">= {1 / MAX_FILE_INTERVAL_S:g} Hz (at most {MAX_FILE_INTERVAL_S * 1e3:g} ms)"
                )
        rows.append(vals)
    if header is None or len(rows) < 2:
        raise ValueError(f"trajectory file {name}: needs at least two rows after the header")
    a = np.array(rows)
    t = a[:, 0] - a[0, 0]
    n = round(t[-1] / dt)
    if n < 1:
        raise ValueError(f"trajectory file {name}: lasts {t[-1]:g} s, less than one step")
    mid = (np.arange(n) + 0.5) * dt
    cols = dict(zip(header, a.T, strict=True))
    v = np.interp(mid, t, cols["v"] if "v" in cols else cols["vx"])
    w = np.interp(mid, t, cols["w"])
    vy = np.interp(mid, t, cols["vy"]) if "vy" in cols else None
    return v, w, vy


def resolve_trajectory(
    spec: str, speed: float = 0.2, dt: float = DT
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``file:PATH`` (:func:`load_trajectory_file`) or a name of :data:`TRAJECTORIES` at
    ``speed``: per step (v, omega, vy or None). ValueError with the allowed values."""
    if spec.startswith(FILE_PREFIX):
        return load_trajectory_file(spec[len(FILE_PREFIX) :], dt)
    if spec not in TRAJECTORIES:
        raise ValueError(
            f"trajectory '{spec}' is unknown; allowed: {', '.join(TRAJECTORIES)} or file:PATH "
            "(a CSV t,v,w or t,vx,vy,w)"
        )
    v, w = trajectory(spec, speed, dt)
    return v, w, None


def cumulative_sensor_path(
    v: np.ndarray, omega: np.ndarray, dt: float, mount: SensorMount, vy=None
) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative sensor-frame position (starting at 0) at every step boundary."""
    dx, dy = sensor_displacements(v, omega, dt, mount, vy)
    return np.concatenate([[0.0], np.cumsum(dx)]), np.concatenate([[0.0], np.cumsum(dy)])


# --- per-request samples (what the Beagle node serves) ------------------------------------


@dataclass(frozen=True)
class RequestSamples:
    """Samples as a client polling at ``request_hz`` receives them, with ground truth.

    ``dt`` (N,) s: interval length per request (whole 1 kHz polls).
    ``d`` (N, n_sensors, 2) m: sensor-frame displacement (dX right, dY forward)
    counted by each sensor over the interval, as reported (mounting error,
    quantisation, noise and lifts included as asked).
    ``truth`` (N, 3): exact pose (x m, y m, yaw rad, odom -> base_link) at the
    end of each interval. ``end_step`` (N,): 1 kHz step count at each end.
    ``lifted_steps`` (N, n_sensors): how many 1 ms steps of the interval each
    sensor was lifted (their counts are lost).
    """

    dt: np.ndarray
    d: np.ndarray
    truth: np.ndarray
    end_step: np.ndarray
    lifted_steps: np.ndarray


def request_boundaries(n_steps: int, request_hz: float, dt: float = DT) -> np.ndarray:
    """Step indices (ending at ``n_steps``) where a client at ``request_hz`` asks.

    Requests fall at t = k/request_hz; each collects the polls completed by
    then, so the boundary is round(t/dt) steps (an interval of 1000/15 ms thus
    alternates 67, 67, 66 polls). Zero-length intervals are dropped; the last
    boundary is always ``n_steps`` (a final request after the run).
    """
    if not (math.isfinite(request_hz) and request_hz > 0):
        raise ValueError(f"request rate must be a finite number of Hz > 0, got {request_hz}")
    steps_per_request = 1.0 / (request_hz * dt)
    k = np.arange(1, math.ceil(n_steps / steps_per_request) + 1)
    ends = np.minimum(np.round(k * steps_per_request).astype(np.int64), n_steps)
    ends = np.unique(ends[ends > 0])
    if ends.size == 0 or ends[-1] != n_steps:
        ends = np.append(ends, n_steps)
    return ends


def request_samples(
    v: np.ndarray,
    omega: np.ndarray,
    mounts=DEFAULT_MOUNTS,
    request_hz: float = 1000.0,
    dt: float = DT,
    cpi: float | None = None,
    noise_counts: float = 0.0,
    lifted: np.ndarray | None = None,
    rng: np.random.Generator | int | None = None,
    gains: np.ndarray | None = None,
) -> RequestSamples:
    """Per-request samples from a 1 kHz twist sequence, vectorised.

    Sums the per-millisecond sensor displacements of each mount (its
    ``yaw`` is the mounting error the sensor reports with) over each request
    interval. Options:

    ``cpi``: counts per inch; quantise like the emulator (the reported count
    total is floor(cumulative true counts)), so no count is ever lost, only
    delayed; None = exact, unquantised metres.
    ``noise_counts``: standard deviation (counts, needs ``cpi``) of Gaussian
    noise added to each 1 ms count of each axis (a random walk in the total).
    ``lifted``: bool array (n_steps,) or (n_steps, n_sensors); the counts of
    lifted ms are dropped (the sensor reports nothing while lifted).
    ``rng``: numpy Generator or seed for the noise.
    ``gains``: (n_sensors, 2) factors on each sensor's X and Y counts (a
    sensor that over- or under-counts per axis); None = 1.
    """
    v = np.asarray(v, dtype=float)
    omega = np.asarray(omega, dtype=float)
    if v.shape != omega.shape or v.ndim != 1:
        raise ValueError(f"v and omega must be 1-D of equal length, got {v.shape}, {omega.shape}")
    mounts = tuple(mounts)
    n, k = v.size, len(mounts)
    if noise_counts and cpi is None:
        raise ValueError("noise_counts needs a cpi (the noise is in counts)")
    if not (math.isfinite(noise_counts) and noise_counts >= 0):
        raise ValueError(f"noise_counts must be >= 0, got {noise_counts}")
    if cpi is not None and not (math.isfinite(cpi) and cpi > 0):
        raise ValueError(f"cpi must be > 0, got {cpi}")
    step = np.empty((n, k, 2))
    for i, m in enumerate(mounts):
        step[:, i, 0], step[:, i, 1] = sensor_displacements(v, omega, dt, m)
    if gains is not None:
        gains = np.asarray(gains, dtype=float)
        if gains.shape != (k, 2) or not np.all(np.isfinite(gains) & (gains > 0)):
            raise ValueError(f"gains must be ({k}, 2) finite factors > 0, got {gains.tolist()}")
        step *= gains[None, :, :]
    if cpi is not None:
        step *= cpi / INCH_M  # metres -> fractional counts
        if noise_counts:
            gen = np.random.default_rng(rng)
            step += gen.normal(0.0, noise_counts, step.shape)
    lift = np.zeros((n, k), dtype=bool)
    if lifted is not None:
        lifted = np.asarray(lifted, dtype=bool)
        if lifted.shape == (n,):
            lifted = lifted[:, None]
        if lifted.shape not in ((n, 1), (n, k)):
            raise ValueError(f"lifted must have shape ({n},) or ({n}, {k}), got {lifted.shape}")
        lift = np.broadcast_to(lifted, (n, k))
        step[lift] = 0.0
    cum = np.concatenate([np.zeros((1, k, 2)), np.cumsum(step, axis=0)])
    if cpi is not None:
        cum = np.floor(cum) * (INCH_M / cpi)  # whole counts reported, back to metres
    ends = request_boundaries(n, request_hz, dt)
    starts = np.concatenate([[0], ends[:-1]])
    d = cum[ends] - cum[starts]
    lift_cum = np.concatenate([np.zeros((1, k), dtype=np.int64), np.cumsum(lift, axis=0)])
    truth = integrate_pose(v, omega, dt)[ends - 1]
    return RequestSamples(
        dt=(ends - starts) * dt,
        d=d,
        truth=truth,
        end_step=ends,
        lifted_steps=lift_cum[ends] - lift_cum[starts],
    )


def lift_mask(n_steps: int, lifts: list[tuple[float, float]], dt: float = DT) -> np.ndarray:
    """Bool mask (n_steps,) true during each (start s, duration s) lift."""
    mask = np.zeros(n_steps, dtype=bool)
    for start, duration in lifts:
        if not (start >= 0 and duration >= 0):
            raise ValueError(
                f"a lift needs start >= 0 s and duration >= 0 s, got {start, duration}"
            )
        mask[round(start / dt) : round((start + duration) / dt)] = True
    return mask


def with_mount_yaw(mounts, yaw: float | list[float]) -> tuple[SensorMount, ...]:
    """The mounts with a mounting error ``yaw`` (rad, one for all or one per mount)."""
    mounts = tuple(mounts)
    yaws = list(yaw) if isinstance(yaw, (list, tuple, np.ndarray)) else [yaw] * len(mounts)
    if len(yaws) != len(mounts):
        raise ValueError(f"{len(yaws)} yaw(s) for {len(mounts)} mount(s)")
    return tuple(replace(m, yaw=float(y)) for m, y in zip(mounts, yaws, strict=True))
