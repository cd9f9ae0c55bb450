"""The poller's options, defined once: name, default, range and description.

Both ways of starting a poller read this table: the node's ROS parameters
(:mod:`mm_beagle.node.params` builds ParameterDescriptors from it) and the agent's
command line and YAML file (:mod:`mm_beagle.link.agent_cli` builds its defaults and
range checks from it), and both build their PollerConfig from the checked values
with :func:`poller_config_from`. Only what both share is here; the node's publishing
and odometry parameters and the agent's zenoh options stay with them.
No ROS, no numpy (the board's agent imports it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mm_beagle.poller import chip_config
from mm_beagle.poller.poller import PollerConfig, poller_config
from mm_beagle.poller.sim_backend import (
    SimConfig,
    check_trajectory,
    parse_fail_windows,
    sim_chips,
)
from mm_pc.core.user_file import check_user_file


@dataclass(frozen=True)
class Option:
    """One option. ``lo``/``hi`` bound a number (None: unbounded), ``step`` an integer's
    grid (0: any); ``unit`` is for messages. A list default is a list of strings."""

    name: str
    default: object
    description: str
    lo: float | None = None
    hi: float | None = None
    step: int = 0
    unit: str = ""
    choices: tuple[str, ...] = ()


def _options(*items: Option) -> dict[str, Option]:
    return {o.name: o for o in items}


_CPI_LO, _CPI_HI, _CPI_STEP = chip_config.cpi_union()

#: the poller's options, shared by the node (ROS parameters) and the agent (command line)
OPTIONS = _options(
    Option(
        "devices",
        ["/dev/spidev1.0", "/dev/spidev1.1"],
        "spidev device paths, one per sensor; they are also the sensor ids",
    ),
    Option(
        "backend",
        "spidev",
        "'spidev' (real sensors) or 'sim' (emulated sensors)",
        choices=("spidev", "sim"),
    ),
    Option(
        "cpi",
        1600,
        "resolution of every sensor, counts per inch (X and Y); each chip also checks its "
        "own range (pln2033 100..6400/100, pmw3360 100..12000/100, pmw3389 50..16000/50); "
        "fixed-resolution chips (pmw3901, paa5100) ignore it",
        _CPI_LO,
        _CPI_HI,
        _CPI_STEP,
    ),
    Option(
        "chips",
        [],
        "the chip of each device, in device order, or one name for all ('' = all "
        f"pln2033; 'a,b' in one string works too); allowed: {chip_config.chips_help()}",
    ),
    Option(
        "chip_options",
        [],
        "driver options as key=value, each to every chip whose driver takes it, or "
        "CHIP.key=value for one chip type (e.g. height_m=0.08, pmw3389.product_id=0x42)",
    ),
    Option(
        "srom_file",
        "",
        "SROM (PixArt firmware) for PMW3360/PMW3389, a file in patch_dir ('' = none)",
    ),
    Option("poll_rate", 1000.0, "sensor polls per second (Hz)", 10.0, 2000.0, unit=" Hz"),
    Option("spi_speed_hz", 3_000_000, "SPI clock (Hz)", 100_000, 8_000_000, unit=" Hz"),
    Option("register_map", "", "YAML file overriding the assumed register map ('' = defaults)"),
    Option(
        "patch_file",
        "",
        "vendor patch code to load into the DSP RAM, a file in patch_dir ('' = none)",
    ),
    Option(
        "patch_dir", "", "the only directory patch files are loaded from ('' = patch loading off)"
    ),
    Option(
        "realtime_priority",
        50,
        "SCHED_FIFO priority of the poller process (0 = normal scheduling)",
        0,
        99,
    ),
    Option(
        "retry_interval",
        1.0,
        "seconds between attempts to bring a failed sensor up",
        0.1,
        60.0,
        unit=" s",
    ),
    Option(
        "sim_trajectory",
        "figure_eight",
        "sim backend: still | straight | figure_eight | square | round_trip | meander | "
        "s_curves | mixed_tour, or file:PATH (CSV t,v,w or t,vx,vy,w at >= 100 Hz)",
    ),
    Option("sim_speed", 0.2, "sim backend: robot speed (m/s)", 0.001, 5.0, unit=" m/s"),
    Option("sim_loop", True, "sim backend: repeat the trajectory; false = stop after one lap"),
    Option(
        "sim_duration",
        0.0,
        "sim backend: seconds of motion, then stand still (0 = the path as it is)",
        0.0,
        1e6,
        unit=" s",
    ),
    Option(
        "sim_start_delay",
        0.0,
        "sim backend: seconds standing still before the path starts",
        0.0,
        3600.0,
        unit=" s",
    ),
    Option("sim_lift_rate", 0.0, "sim backend: lifts per second per sensor", 0.0, 100.0),
    Option("sim_chips", [], "sim backend: the emulated chip of each device ('' = as 'chips')"),
    Option(
        "sim_low_quality_rate",
        0.0,
        "sim backend: poor-surface windows (20 ms, quality low) per second per sensor",
        0.0,
        100.0,
    ),
    Option("sim_noise_counts", 0.0, "sim backend: count noise per sqrt(second)", 0.0, 1e6),
    Option(
        "sim_fail_windows",
        [],
        "sim backend: 'DEVICE@START-END' (s) windows in which a sensor fails",
    ),
)


def _num(v: float) -> str:
    """3000000 not 3e+06, 0.1 not 0.10000: numbers as a person writes them."""
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"


def option_bounds(option: Option) -> str:
    """``"10..2000"``, ``">= 60"``, ``"<= 5"`` or '' (unbounded)."""
    lo, hi = option.lo, option.hi
    if lo is not None and hi is not None:
        return f"{_num(lo)}..{_num(hi)}"
    if lo is not None:
        return f">= {_num(lo)}"
    return f"<= {_num(hi)}" if hi is not None else ""


def range_problem(option: Option, value: object) -> str:
    """Why ``value`` is outside the option's range or choices ('' = it is not)."""
    if option.choices and value not in option.choices:
        return f"'{option.name}' is '{value}'; allowed: {', '.join(option.choices)}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return ""
    if not math.isfinite(value):  # NaN passes every comparison below
        return f"'{option.name}' must be a finite number, got {value}"
    lo, hi = option.lo, option.hi
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        return f"'{option.name}' must be {option_bounds(option)}{option.unit}, got {_num(value)}"
    return ""


def check_ranges(options: dict[str, Option], values: dict[str, object]) -> None:
    """ValueError for the first value outside its option's range (options absent from
    ``values`` are skipped)."""
    for name, option in options.items():
        if name in values and (problem := range_problem(option, values[name])):
            raise ValueError(problem)


def poller_config_from(
    values: dict, ring_size: int, sim_mounts: list[tuple[float, float, float]] | None = None
) -> PollerConfig:
    """The PollerConfig of option values already typed and range-checked, by the node
    (its parameters) and the agent (its command line) alike: devices, chips and their
    options, the firmware files and the sim backend checked here; ValueError says what
    is wrong. ``sim_mounts``: the sim backend's sensor mounts (base_link x, y, yaw)."""
    devices = list(values["devices"])
    if not devices or any(not d for d in devices) or len(set(devices)) != len(devices):
        raise ValueError(f"'devices' must name distinct devices, got {devices}")
    fails = [s for s in values["sim_fail_windows"] if s]
    parse_fail_windows(fails, devices)  # checked whatever the backend, with a clear message
    sim = SimConfig(
        trajectory=values["sim_trajectory"],
        speed=values["sim_speed"],
        loop=values["sim_loop"],
        duration=values["sim_duration"],
        start_delay=values["sim_start_delay"],
        mounts=list(sim_mounts or []),
        lift_rate=values["sim_lift_rate"],
        noise_counts=values["sim_noise_counts"],
        fail_windows=fails,
        chips=chip_config.split_names(values["sim_chips"]),
        low_quality_rate=values["sim_low_quality_rate"],
    )
    backend = values["backend"]
    if backend == "sim":
        check_trajectory(sim.trajectory)
    chips = chip_config.split_names(values["chips"])  # a config file may write "a,b" too
    options = chip_config.parse_chip_options(list(values["chip_options"]))
    if values["register_map"]:  # a FIFO would block the start, /dev/zero never end
        try:
            check_user_file(values["register_map"])
        except OSError as exc:
            raise ValueError(
                f"cannot read register map {values['register_map']}: {exc.strerror or exc}"
            ) from None
    chip_config.check_board_config(devices, chips, options, values["cpi"], values["register_map"])
    cfg = poller_config(
        {**values, "devices": devices, "chips": chips, "chip_options": options}, ring_size, sim
    )
    if backend == "sim":  # a bad emulated chip name now, with a clear message
        emulated, driven = sim_chips(cfg), chip_config.resolve_chips(chips, devices)
        if emulated != driven:  # another chip's emulator crashes the driver (an OTOS is I2C)
            raise ValueError(
                f"'sim_chips' {','.join(emulated)} differ from 'chips' {','.join(driven)}: "
                "each device's driver talks to its own chip's emulator; give chips the same "
                "list (or leave sim_chips empty: the emulators follow chips)"
            )
    return cfg
