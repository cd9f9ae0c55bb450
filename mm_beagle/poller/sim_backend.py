"""The sim backend: emulated sensors moved along a ground-truth path.

Each device gets the register-level emulator of its chip (``sim_chips``, else
``chips``: :func:`pln2033.chips.make_emulator`; a PLN2033 by default) whose motion
is the robot simulator's path seen from that sensor's mount, so
the real driver and poller code run unchanged. Needs numpy (through the
simulator); the spidev path never imports this module.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pln2033.pln2033 import RegisterMap


@dataclass
class SimConfig:
    """The emulated sensors of the sim backend."""

    trajectory: str = "figure_eight"  # a name of mm_pc.sim.robot.TRAJECTORIES or file:PATH
    speed: float = 0.2  # m/s
    loop: bool = True  # repeat the path; False = stand still after one lap
    duration: float = 0.0  # s of motion (the path repeated or cut to fit); 0 = as the path is
    start_delay: float = 0.0  # s standing still before the path starts
    mounts: list[tuple[float, float, float]] = field(default_factory=list)  # base_link x, y, yaw
    lift_rate: float = 0.0  # lifts per second per sensor
    lift_duration: float = 0.01  # s
    noise_counts: float = 0.0  # count noise per sqrt(s)
    fail_windows: list[str] = field(default_factory=list)  # "DEVICE@START-END" (s from start)
    seed: int = 1
    chips: list[str] = field(default_factory=list)  # the emulated chips ([] = as 'chips')
    low_quality_rate: float = 0.0  # poor-surface windows per second per sensor
    low_quality_duration: float = 0.02  # s


def check_trajectory(spec: str) -> None:
    """ValueError (saying what is allowed, or the file's line) unless the sim backend can
    drive ``spec``: a name of mm_pc.sim.robot.TRAJECTORIES or ``file:PATH``."""
    from mm_pc.sim import robot as simulator

    if spec.startswith(simulator.FILE_PREFIX):
        simulator.load_trajectory_file(spec[len(simulator.FILE_PREFIX) :])
    elif spec not in simulator.TRAJECTORIES:
        raise ValueError(
            f"'sim_trajectory' is '{spec}'; allowed: {', '.join(simulator.TRAJECTORIES)} "
            "or file:PATH (a CSV with header t,v,w or t,vx,vy,w)"
        )


def parse_fail_windows(
    specs: list[str], devices: list[str]
) -> dict[str, list[tuple[float, float]]]:
    """``["/dev/spidev1.1@0-2.5"]`` -> {"/dev/spidev1.1": [(0.0, 2.5)]}; errors name the format."""
    out: dict[str, list[tuple[float, float]]] = {d: [] for d in devices}
    for spec in specs:
        try:
            dev, span = spec.rsplit("@", 1)
            a, b = (float(v) for v in span.split("-", 1))
        except ValueError:
            raise ValueError(f"fail window '{spec}' is not DEVICE@START-END (seconds)") from None
        if dev not in out:
            raise ValueError(f"fail window '{spec}' names an unknown device; devices: {devices}")
        if not 0 <= a < b:
            raise ValueError(f"fail window '{spec}' needs 0 <= START < END")
        out[dev].append((a, b))
    return out


SIM_MOUNTS_FORM = "X,Y,YAW per sensor (m, m, degrees), sensors separated by ';'"


def parse_sim_mounts(text: str, devices: list[str]) -> list[tuple[float, float, float]]:
    """``"0.051,-0.0385,3;0.047,0.041,-2"`` (mm-monitor's ``--sim-mounts``) -> one (x, y, yaw
    rad) per device, base_link; '' -> [] (as designed). ValueError saying the format for
    anything else: not 3 numbers per sensor, not one mount per device, non-finite, a
    position over 1 m, a yaw over 180 deg."""
    if not text.strip():
        return []
    parts = text.split(";")
    if len(parts) != len(devices):
        raise ValueError(
            f"'sim_mounts' has {len(parts)} sensors for {len(devices)} devices; {SIM_MOUNTS_FORM}"
        )
    mounts = []
    for k, part in enumerate(parts):
        try:
            x, y, yaw = (float(v) for v in part.split(","))
        except ValueError:
            raise ValueError(
                f"'sim_mounts' needs {SIM_MOUNTS_FORM}; sensor {k} is {part.strip()!r}"
            ) from None
        if not all(map(math.isfinite, (x, y, yaw))) or max(abs(x), abs(y)) > 1 or abs(yaw) > 180:
            raise ValueError(
                f"'sim_mounts': sensor {k} ({part.strip()}) needs |x|, |y| <= 1 m and "
                "|yaw| <= 180 deg"
            )
        mounts.append((x, y, math.radians(yaw)))
    return mounts


# --- sensor backends -----------------------------------------------------------------------


def _windows(rate: float, duration: float, seed: int, t0: float) -> list[tuple[float, float]]:
    """Poisson-spaced (start, end) windows over 24 h from ``t0`` (at most 200 000)."""
    import random

    out: list[tuple[float, float]] = []
    if rate <= 0:
        return out
    rng = random.Random(seed)
    t = t0
    horizon = t0 + 24 * 3600
    while t < horizon and len(out) < 200_000:
        t += rng.expovariate(rate)
        out.append((t, t + duration))
        t += duration
    return out


# emulator keywords taken from the driver options, so that the emulated chip matches
# the configured one (its height above the floor, its resolution encoding)
EMULATOR_OPTIONS = ("height_m", "resolution_offset")


def sim_chips(cfg) -> list[str]:
    """The emulated chip of each device: ``sim.chips``, else the poller's ``chips``."""
    from pln2033.chips import check_chips

    names = [c for c in cfg.sim.chips if c] or [c for c in cfg.chips if c]
    try:
        return check_chips(names, len(cfg.devices))
    except ValueError as exc:
        raise ValueError(f"'sim_chips': {exc}") from None


def make_sim_buses(cfg, t0: float) -> dict[str, Any]:
    """One emulated sensor per device (its chip's emulator: a bus its driver talks to),
    driven by the simulator."""
    import inspect

    import numpy as np

    from mm_pc.sim import robot as simulator
    from pln2033 import chips as registry
    from pln2033.motion import SampledPath

    sim = cfg.sim
    mounts = [simulator.SensorMount(*m) for m in sim.mounts] or list(simulator.DEFAULT_MOUNTS)
    v, w, vy = simulator.resolve_trajectory(sim.trajectory, sim.speed)
    vy = np.zeros_like(v) if vy is None else vy
    loop = sim.loop
    if sim.duration > 0:  # repeat or cut the path to this long, then stand still
        n = max(1, round(sim.duration / simulator.DT))
        v, w, vy = np.resize(v, n), np.resize(w, n), np.resize(vy, n)
        loop = False
    if sim.start_delay > 0:
        still = np.zeros(round(sim.start_delay / simulator.DT))
        v, w, vy = (np.concatenate([still, a]) for a in (v, w, vy))
    fails = parse_fail_windows(sim.fail_windows, cfg.devices)
    regmap = RegisterMap.load(cfg.register_map) if cfg.register_map else None
    chips = sim_chips(cfg)
    buses: dict[str, Any] = {}
    for i, (dev, chip) in enumerate(zip(cfg.devices, chips, strict=True)):
        mount = mounts[i % len(mounts)]
        cx, cy = simulator.cumulative_sensor_path(v, w, simulator.DT, mount, vy)
        path = SampledPath(cx.tolist(), cy.tolist(), simulator.DT, t_start=t0, loop=loop)
        kwargs: dict[str, object] = dict(
            motion=path,
            lift_windows=_windows(sim.lift_rate, sim.lift_duration, sim.seed * 1000 + i, t0),
            noise_counts=sim.noise_counts,
            fault_windows=[(t0 + a, t0 + b, "raise") for a, b in fails[dev]],
            seed=sim.seed + i,
        )
        poor = _windows(sim.low_quality_rate, sim.low_quality_duration, sim.seed * 7919 + i, t0)
        if poor:
            kwargs["low_quality_windows"] = poor
        if chip == registry.DEFAULT_CHIP:
            kwargs["regmap"] = regmap
        emulator_class = registry._load(registry._spec(chip).emulator)
        takes = set(inspect.signature(emulator_class).parameters)
        for key in EMULATOR_OPTIONS:
            if key in cfg.chip_options and key in takes:
                kwargs[key] = cfg.chip_options[key]
        buses[dev] = registry.make_emulator(chip, **kwargs)
    return buses
