"""The node's parameters, declared in one place with descriptors and ranges.

The poller's options (devices, cpi, rates, chips, sim backend) come from
:mod:`mm_beagle.poller.options`, the table the agent's command line reads too; the
node adds its publishing, odometry and remote-backend parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

from mm_beagle.link import link, link_auth, link_checks, zenoh_config
from mm_beagle.node.otos_calibration import otos_options
from mm_beagle.poller import chip_config
from mm_beagle.poller.options import OPTIONS, poller_config_from
from mm_beagle.poller.poller import PollerConfig
from mm_pc.ros.parameters import declare_all, float_range, int_range, mark_live, ranged
from mm_pc.ros.parameters import read_only as _plain
from mm_pc.ros.tf import (
    frame_ids_problem,
    frame_prefix_parameter,
    frame_prefix_problem,
    prefixed,
    sensor_frame_names,
)

#: the poller's backends and the node's own: an mm-beagle-agent on the board polls them
BACKENDS = (*OPTIONS["backend"].choices, "remote")


#: parameters that may change while the node runs (``ros2 param set``); the rest are read-only
LIVE = ("cpi", "publish_rate", "diagnostics_period", "odom_frame", "base_frame")


def _from_option(name: str) -> tuple[object, ParameterDescriptor]:
    """(default, descriptor) of a poller option; an empty string list becomes [""] (ROS
    infers a parameter's type from its default)."""
    o = OPTIONS[name]
    default = o.default if o.default != [] else [""]
    return default, ranged(o.description, o.default, o.lo, o.hi, o.step)


def _float(desc: str, lo: float, hi: float) -> ParameterDescriptor:
    return _plain(desc, **float_range(lo, hi))


def _int(desc: str, lo: int, hi: int) -> ParameterDescriptor:
    return _plain(desc, **int_range(lo, hi))


# name -> (default, descriptor); _from_option: ranges and text in mm_beagle.poller.options
PARAMETERS = {
    "devices": _from_option("devices"),
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
    "cpi": _from_option("cpi"),
    "chips": _from_option("chips"),
    "chip_options": _from_option("chip_options"),
    "srom_file": _from_option("srom_file"),
    "poll_rate": _from_option("poll_rate"),
    "spi_speed_hz": _from_option("spi_speed_hz"),
    "register_map": _from_option("register_map"),
    "patch_file": _from_option("patch_file"),
    "patch_dir": _from_option("patch_dir"),
    "realtime_priority": _from_option("realtime_priority"),
    "retry_interval": _from_option("retry_interval"),
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
        _plain(
            "TF frame of each sensor, in device order ('' = mouse_ + device name); "
            "SensorData's frame_id is it + '_counts'"
        ),
    ),
    "frame_prefix": frame_prefix_parameter(),
    "sim_trajectory": _from_option("sim_trajectory"),
    "sim_speed": _from_option("sim_speed"),
    "sim_loop": _from_option("sim_loop"),
    "sim_duration": _from_option("sim_duration"),
    "sim_start_delay": _from_option("sim_start_delay"),
    "sim_mounts": (
        [0.049, -0.0395, 0.0, 0.049, 0.0395, 0.0],
        _plain("sim backend: x, y, yaw (base_link m, rad) of each sensor, flattened"),
    ),
    "sim_lift_rate": _from_option("sim_lift_rate"),
    "sim_chips": _from_option("sim_chips"),
    "sim_low_quality_rate": _from_option("sim_low_quality_rate"),
    "sim_noise_counts": _from_option("sim_noise_counts"),
    "sim_fail_windows": _from_option("sim_fail_windows"),
}
assert set(OPTIONS) <= set(PARAMETERS), "every poller option is a node parameter"
mark_live(PARAMETERS, LIVE)


@dataclass
class OdometrySettings:
    """The node's own odometry (off when rate == 0); ``odom_frame`` and ``base_frame`` as
    published, after ``frame_prefix`` (``sensor_frames`` as given: prefixed where named)."""

    rate: float
    method: str
    sensor: int
    mounts: list[tuple[float, float, float]]
    calibration_file: str
    odom_frame: str
    base_frame: str
    publish_tf: bool = False
    sensor_frames: tuple[str, ...] = ()
    frame_prefix: str = ""


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


def _triples(flat: list[float]) -> list[tuple[float, float, float]]:
    """[x0, y0, yaw0, x1, ...] -> [(x0, y0, yaw0), ...] (a length that is a multiple of 3)."""
    return [(flat[i], flat[i + 1], flat[i + 2]) for i in range(0, len(flat) - 2, 3)]


def declare(node: Node) -> NodeSettings:
    """Declare every parameter and return validated settings; ValueError says what is wrong."""
    p = declare_all(node, PARAMETERS)
    if p["backend"] not in BACKENDS:
        raise ValueError(f"'backend' is '{p['backend']}'; allowed: {', '.join(BACKENDS)}")
    mounts_flat = list(p["sim_mounts"])
    if len(mounts_flat) % 3:
        raise ValueError("'sim_mounts' needs x, y, yaw per sensor (a multiple of 3 numbers)")
    cfg = poller_config_from(p, p["ring_size"], _triples(mounts_flat))
    devices, chips = cfg.devices, cfg.chips
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
        mounts=_triples(flat),
        calibration_file=p["calibration_file"],
        odom_frame=prefixed(p["frame_prefix"], p["odom_frame"]),
        base_frame=prefixed(p["frame_prefix"], p["base_frame"]),
        publish_tf=p["publish_tf"],
        sensor_frames=tuple(p["sensor_frames"]),
        frame_prefix=p["frame_prefix"],
    )
    if problem := frame_prefix_problem(p["frame_prefix"]):
        raise ValueError(problem)
    # checked before the poller starts; the sensor frames name SensorData's frames too
    sensor_frame_names(devices, odometry.sensor_frames)
    if odometry.rate > 0 and (problem := frame_ids_problem(p, ("odom_frame", "base_frame"))):
        raise ValueError(problem)
    remote = RemoteSettings(
        p["agent"], p["agent_name"], p["agent_credentials"], p["agent_clock_sync"]
    )
    if p["backend"] != "remote" and (problem := link_checks.patch_dir_problem(p["patch_dir"])):
        raise ValueError(problem)  # (remote: the agent's own --patch-dir)
    if p["backend"] == "remote":
        try:  # name, endpoint (tls/quic certificates, iface) and credentials file
            link_checks.check_link_settings(
                remote.name, [remote.agent], "connect", remote.credentials
            )
            zenoh_config.endpoint_host(remote.agent)
            link.keys(remote.name)
            if remote.credentials:
                link_auth.load_credentials(remote.credentials)
        except link.LinkError as exc:
            raise ValueError(str(exc)) from None
    return NodeSettings(cfg, p["publish_rate"], p["diagnostics_period"], odometry, remote)
