"""The sim backend: emulated PLN2033s moved along a ground-truth path.

Each device gets a register-level :class:`~pln2033.emulator.EmulatedPLN2033`
whose motion is the robot simulator's path seen from that sensor's mount, so
the real driver and poller code run unchanged. Needs numpy (through the
simulator); the spidev path never imports this module.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pln2033 import RegisterMap


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


# --- sensor backends -----------------------------------------------------------------------


def make_sim_buses(cfg, t0: float) -> dict[str, object]:
    """One emulated PLN2033 per device, driven by the ground-truth simulator."""
    import random

    import numpy as np

    from mm_pc.sim import robot as simulator
    from pln2033.emulator import EmulatedPLN2033
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
    buses: dict[str, object] = {}
    for i, dev in enumerate(cfg.devices):
        mount = mounts[i % len(mounts)]
        cx, cy = simulator.cumulative_sensor_path(v, w, simulator.DT, mount, vy)
        path = SampledPath(cx, cy, simulator.DT, t_start=t0, loop=loop)
        lifts = []
        if sim.lift_rate > 0:
            rng = random.Random(sim.seed * 1000 + i)
            t = t0
            horizon = t0 + 24 * 3600
            while t < horizon and len(lifts) < 200_000:
                t += rng.expovariate(sim.lift_rate)
                lifts.append((t, t + sim.lift_duration))
                t += sim.lift_duration
        buses[dev] = EmulatedPLN2033(
            motion=path,
            regmap=regmap,
            lift_windows=lifts,
            noise_counts=sim.noise_counts,
            fault_windows=[(t0 + a, t0 + b, "raise") for a, b in fails[dev]],
            seed=sim.seed + i,
        )
    return buses
