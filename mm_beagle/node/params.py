"""The node's parameters, declared in one place with descriptors and ranges."""

from __future__ import annotations

from dataclasses import dataclass

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node

from mm_beagle.link import link
from mm_beagle.node.otos_calibration import otos_options
from mm_beagle.poller import chip_config
from mm_beagle.poller.poller import PollerConfig, poller_config
from mm_beagle.poller.sim_backend import SimConfig, check_trajectory, parse_fail_windows
from mm_pc.ros.tf import frame_ids_problem, sensor_frame_names

BACKENDS = ("spidev", "sim", "remote")


#: parameters that may change while the node runs (``ros2 param set``); the rest are read-only
LIVE = ("cpi", "publish_rate", "diagnostics_period", "odom_frame", "base_frame")


def _int(desc: str, lo: int, hi: int, step: int = 0) -> ParameterDescriptor:
    return ParameterDescriptor(
        description=desc,
        read_only=True,
        integer_range=[IntegerRange(from_value=lo, to_value=hi, step=step)],
    )


def _float(desc: str, lo: float, hi: float) -> ParameterDescriptor:
    return ParameterDescriptor(
        description=desc,
        read_only=True,
        floating_point_range=[FloatingPointRange(from_value=lo, to_value=hi, step=0.0)],
    )


def _plain(desc: str) -> ParameterDescriptor:
    return ParameterDescriptor(description=desc, read_only=True)


# name -> (default, descriptor)
PARAMETERS = {
    "devices": (
        ["/dev/spidev1.0", "/dev/spidev1.1"],
        _plain("spidev device paths, one per sensor; they are also the sensor ids"),
    ),
    "backend": (
        "spidev",
        _plain(
            "'spidev' (real sensors), 'sim' (emulated PLN2033s) or 'remote' (an mm-beagle-agent "
            "on the board polls them)"
        ),
    ),
    "agent": (
        link.DEFAULT_ENDPOINT,
        _plain("remote backend: the agent's zenoh endpoint, e.g. tcp/192.168.7.2:7447"),
    ),
    "agent_name": (link.DEFAULT_NAME, _plain("remote backend: the agent's --name (keys mm/NAME)")),
    "agent_credentials": (
        "",
        _plain("remote backend: user:password file (mode 600) the agent asks for ('' = none)"),
    ),
    "agent_clock_sync": (
        True,
        _plain("remote backend: move the agent's stamps to this clock (false if both run NTP)"),
    ),
    "cpi": (
        1600,
        _int(
            "resolution of every sensor, counts per inch (X and Y); each chip also checks its "
            "own range (pln2033 100..6400/100, pmw3360 100..12000/100, pmw3389 50..16000/50); "
            "fixed-resolution chips (pmw3901, paa5100) ignore it",
            *chip_config.cpi_union(),
        ),
    ),
    "chips": (
        [""],
        _plain(
            "the chip of each device, in device order, or one name for all ('' = all "
            f"pln2033; 'a,b' in one string works too); allowed: {chip_config.chips_help()}"
        ),
    ),
    "chip_options": (
        [""],
        _plain(
            "driver options as key=value, each to every chip whose driver takes it, or "
            "CHIP.key=value for one chip type (e.g. height_m=0.08, pmw3389.product_id=0x42)"
        ),
    ),
    "srom_file": (
        "",
        _plain("SROM (PixArt firmware) for PMW3360/PMW3389, a file in patch_dir ('' = none)"),
    ),
    "poll_rate": (1000.0, _float("sensor polls per second (Hz)", 10.0, 2000.0)),
    "spi_speed_hz": (3_000_000, _int("SPI clock (Hz)", 100_000, 8_000_000)),
    "register_map": ("", _plain("YAML file overriding the assumed register map ('' = defaults)")),
    "patch_file": (
        "",
        _plain("vendor patch code to load into the DSP RAM, a file in patch_dir ('' = none)"),
    ),
    "patch_dir": (
        "",
        _plain("the only directory patch files are loaded from ('' = patch loading off)"),
    ),
    "realtime_priority": (
        50,
        _int("SCHED_FIFO priority of the poller process (0 = normal scheduling)", 0, 99),
    ),
    "retry_interval": (
        1.0,
        _float("seconds between attempts to bring a failed sensor up", 0.1, 60.0),
    ),
    "ring_size": (65536, _int("single polls kept per sensor for get_samples", 1024, 4_194_304)),
    "publish_rate": (
        50.0,
        _float("rate of the sensor_data topic (Hz); 0 = no topic", 0.0, 1000.0),
    ),
    "diagnostics_period": (1.0, _float("seconds between /diagnostics messages", 0.1, 60.0)),
    "odometry_rate": (
        0.0,
        _float("rate of the node's own 1 kHz odometry on ~/odom (Hz); 0 = off", 0.0, 200.0),
    ),
    "odometry_method": ("exact", _plain("pose method: exact | two-sensor | seed-approach1 | ...")),
    "odometry_sensor": (0, _int("which sensor the one-sensor methods use", 0, 15)),
    "mounts": (
        [0.049, -0.0395, 0.0, 0.049, 0.0395, 0.0],
        _plain("odometry: x, y, yaw (base_link m, rad) of each sensor, flattened"),
    ),
    "calibration_file": (
        "",
        _plain(
            "odometry: YAML calibration to apply ('' = none); an OTOS also gets its linear "
            "scalar and offset from it, written at every start"
        ),
    ),
    "odom_frame": ("odom", _plain("odometry: frame_id")),
    "base_frame": ("base_link", _plain("odometry: child_frame_id")),
    "publish_tf": (
        False,
        _plain(
            "odometry: broadcast odom -> base_link on /tf and the sensor mounts on /tf_static; "
            "mm-odometry normally owns odom -> base_link (its publish_tf is true): set this "
            "true only where this node's own odometry replaces mm-odometry"
        ),
    ),
    "sensor_frames": (
        [""],
        _plain("odometry: TF frame of each sensor, in device order ('' = mouse_ + device name)"),
    ),
    "sim_trajectory": (
        "figure_eight",
        _plain(
            "sim backend: still | straight | figure_eight | square | round_trip | meander | "
            "s_curves | mixed_tour, or file:PATH (CSV t,v,w or t,vx,vy,w at >= 100 Hz)"
        ),
    ),
    "sim_speed": (0.2, _float("sim backend: robot speed (m/s)", 0.001, 5.0)),
    "sim_loop": (True, _plain("sim backend: repeat the trajectory; false = stop after one lap")),
    "sim_duration": (
        0.0,
        _float(
            "sim backend: seconds of motion, then stand still (0 = the path as it is)", 0.0, 1e6
        ),
    ),
    "sim_start_delay": (
        0.0,
        _float("sim backend: seconds standing still before the path starts", 0.0, 3600.0),
    ),
    "sim_mounts": (
        [0.049, -0.0395, 0.0, 0.049, 0.0395, 0.0],
        _plain("sim backend: x, y, yaw (base_link m, rad) of each sensor, flattened"),
    ),
    "sim_lift_rate": (0.0, _float("sim backend: lifts per second per sensor", 0.0, 100.0)),
    "sim_chips": (
        [""],
        _plain("sim backend: the emulated chip of each device ('' = as 'chips')"),
    ),
    "sim_low_quality_rate": (
        0.0,
        _float(
            "sim backend: poor-surface windows (20 ms, quality low) per second per sensor",
            0.0,
            100.0,
        ),
    ),
    "sim_noise_counts": (0.0, _float("sim backend: count noise per sqrt(second)", 0.0, 1e6)),
    "sim_fail_windows": (
        [""],
        _plain("sim backend: 'DEVICE@START-END' (s) windows in which a sensor fails"),
    ),
}

for _name in LIVE:
    PARAMETERS[_name][1].read_only = False
    PARAMETERS[_name][1].description += " (live: ros2 param set)"


@dataclass
class OdometrySettings:
    """The node's own odometry (off when rate == 0)."""

    rate: float
    method: str
    sensor: int
    mounts: list[tuple[float, float, float]]
    calibration_file: str
    odom_frame: str
    base_frame: str
    publish_tf: bool = False
    sensor_frames: tuple[str, ...] = ()


@dataclass
class RemoteSettings:
    """Where the agent is (remote backend)."""

    agent: str
    name: str
    credentials: str
    clock_sync: bool


@dataclass
class NodeSettings:
    poller: PollerConfig
    publish_rate: float
    diagnostics_period: float
    odometry: OdometrySettings
    remote: RemoteSettings


def declare(node: Node) -> NodeSettings:
    """Declare every parameter and return validated settings; ValueError says what is wrong."""
    for name, (default, desc) in PARAMETERS.items():
        node.declare_parameter(name, default, desc)
    p = {name: node.get_parameter(name).value for name in PARAMETERS}
    devices = list(p["devices"])
    if not devices or any(not d for d in devices) or len(set(devices)) != len(devices):
        raise ValueError(f"'devices' must name distinct devices, got {devices}")
    if p["backend"] not in BACKENDS:
        raise ValueError(f"'backend' is '{p['backend']}'; allowed: {', '.join(BACKENDS)}")
    mounts_flat = list(p["sim_mounts"])
    if len(mounts_flat) % 3:
        raise ValueError("'sim_mounts' needs x, y, yaw per sensor (a multiple of 3 numbers)")
    mounts = [tuple(mounts_flat[i : i + 3]) for i in range(0, len(mounts_flat), 3)]
    fails = [s for s in p["sim_fail_windows"] if s]
    parse_fail_windows(fails, devices)  # validate now, with a clear message
    sim = SimConfig(
        trajectory=p["sim_trajectory"],
        speed=p["sim_speed"],
        loop=p["sim_loop"],
        duration=p["sim_duration"],
        start_delay=p["sim_start_delay"],
        mounts=mounts,  # type: ignore[arg-type]
        lift_rate=p["sim_lift_rate"],
        noise_counts=p["sim_noise_counts"],
        fail_windows=fails,
        chips=chip_config.split_names(p["sim_chips"]),
        low_quality_rate=p["sim_low_quality_rate"],
    )
    if p["backend"] == "sim":
        check_trajectory(sim.trajectory)
    chips = chip_config.split_names(p["chips"])
    options = chip_config.parse_chip_options(list(p["chip_options"]))
    chip_config.check_board_config(devices, chips, options, p["cpi"], p["register_map"])
    cfg = poller_config(
        {**p, "devices": devices, "chips": chips, "chip_options": options}, p["ring_size"], sim
    )
    if p["backend"] == "sim":
        from mm_beagle.poller.sim_backend import sim_chips

        sim_chips(cfg)  # a bad name now, with a clear message
    cfg.device_options = otos_options(
        devices, chip_config.resolve_chips(chips, devices), p["calibration_file"], p["mounts"]
    )
    flat = list(p["mounts"])
    if p["odometry_rate"] > 0 and len(flat) != 3 * len(devices):
        raise ValueError(
            f"'mounts' needs x, y, yaw for each of the {len(devices)} devices, got {len(flat)}"
        )
    odometry = OdometrySettings(
        rate=p["odometry_rate"],
        method=p["odometry_method"],
        sensor=p["odometry_sensor"],
        mounts=[tuple(flat[i : i + 3]) for i in range(0, len(flat), 3)],  # type: ignore[misc]
        calibration_file=p["calibration_file"],
        odom_frame=p["odom_frame"],
        base_frame=p["base_frame"],
        publish_tf=p["publish_tf"],
        sensor_frames=tuple(p["sensor_frames"]),
    )
    if odometry.rate > 0:  # checked before the poller starts
        if problem := frame_ids_problem(p, ("odom_frame", "base_frame")):
            raise ValueError(problem)
        sensor_frame_names(devices, odometry.sensor_frames)
    remote = RemoteSettings(
        p["agent"], p["agent_name"], p["agent_credentials"], p["agent_clock_sync"]
    )
    if p["backend"] == "remote":
        try:
            link.endpoint_host(remote.agent)
            link.keys(remote.name)
            if remote.credentials:
                link.load_credentials(remote.credentials)
        except link.LinkError as exc:
            raise ValueError(str(exc)) from None
    return NodeSettings(cfg, p["publish_rate"], p["diagnostics_period"], odometry, remote)
