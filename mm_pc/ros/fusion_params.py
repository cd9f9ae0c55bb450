"""mm-fusion's parameters: the table (defaults, descriptors with ranges), the live ones,
and the readers that turn them into beacons, the GPS grid and checked triples."""

from __future__ import annotations

import math

from mm_pc.core.fixes.gps import LocalGrid
from mm_pc.core.maps.trilateration import Beacon
from mm_pc.core.uncertainty import (
    Q_POS,
    Q_YAW_DIST,
    Q_YAW_TURN,
)
from mm_pc.ros.parameters import float_range, int_range, mark_live, read_only
from mm_pc.ros.tf import (
    frame_prefix_parameter,
)

COMPASS_INPUTS = ("imu", "heading", "none")
GPS_SCALES = ("wgs84", "plot")


PARAMETERS = {
    "mouse_odom_topic": (
        "mm_odometry/odom",
        read_only("mouse odometry (nav_msgs/Odometry), relative to the namespace; '' = off"),
    ),
    "wheel_odom_topic": ("/wheel/odom", read_only("wheel odometry (nav_msgs/Odometry); ''=off")),
    "gps_topic": ("/gps/fix", read_only("GPS (sensor_msgs/NavSatFix); '' = off")),
    "compass_input": ("imu", read_only(f"compass input: {', '.join(COMPASS_INPUTS)}")),
    "imu_topic": ("/imu/data", read_only("compass as sensor_msgs/Imu (REP 103 yaw)")),
    "heading_topic": (
        "/compass/heading",
        read_only("compass as std_msgs/Float64: rad, 0 = north, clockwise (seed 004)"),
    ),
    "perimeter_topic": (
        "/perimeter/contact",
        read_only("wire contacts (geometry_msgs/PointStamped, unmeasured axis NaN); '' = off"),
    ),
    "beacon_topic": (
        "/beacons/{name}/range",
        read_only("sensor_msgs/Range topic per beacon, {name} = beacon name; '' = off"),
    ),
    "beacon_names": (["SW", "SE", "NE", "NW"], read_only("beacon names")),
    "beacon_x": ([0.0, 20.0, 20.0, 0.0], read_only("beacon x (m, map frame)")),
    "beacon_y": ([0.0, 0.0, 10.0, 10.0], read_only("beacon y (m, map frame)")),
    "beacon_heights": (
        [1.0, 1.0, 1.0, 1.0],
        read_only("beacon heights above the robot's range antenna (m)"),
    ),
    "range_sigma": (0.05, read_only("beacon range noise (m)", **float_range(1e-4, 100.0))),
    "map_frame": ("map", read_only("frame of the estimate (and of wire coordinates)")),
    "base_frame": ("base_link", read_only("robot frame; odometry inputs must use it as child")),
    "gps_frame": ("", read_only("required NavSatFix frame_id ('' = any)")),
    "imu_frame": ("", read_only("required Imu frame_id ('' = any)")),
    "range_frame": ("", read_only("required Range frame_id ('' = any)")),
    # map_frame and base_frame only: the required input frames above are taken as given
    "frame_prefix": frame_prefix_parameter(),
    "gps_origin_lat": (48.2, read_only("latitude of the plot's south-west corner (deg)")),
    "gps_origin_lon": (16.37, read_only("longitude of the plot's south-west corner (deg)")),
    "gps_scale": (
        "wgs84",
        read_only("metres per degree: 'wgs84' (at the origin) or 'plot' (plot size / NE corner)"),
    ),
    "gps_ne_lat": (0.0, read_only("latitude of the plot's NE corner (deg; gps_scale 'plot')")),
    "gps_ne_lon": (0.0, read_only("longitude of the plot's NE corner (deg; gps_scale 'plot')")),
    "plot_width": (
        20.0,
        read_only("plot west-east size (m); wires on its edges", **float_range(0.0, 1e4)),
    ),
    "plot_height": (
        10.0,
        read_only("plot south-north size (m); 0 x 0 = no wires", **float_range(0.0, 1e4)),
    ),
    "gps_default_sigma": (
        2.5,
        read_only(
            "GPS sigma per axis (m) when the fix gives no covariance", **float_range(0.01, 1e3)
        ),
    ),
    "gps_max_sigma": (
        3.55,
        read_only(
            "fixes with a larger sigma (m) are not used (HDOP 2 x 2.5 m / sqrt 2)",
            **float_range(0.01, 1e3),
        ),
    ),
    "gps_error_tau": (
        30.0,
        read_only(
            "correlation time of the GPS error (s): fixes are weighted as what a stream "
            "of them is worth (0 = independent fixes)",
            **float_range(0.0, 1e5),
        ),
    ),
    "compass_sigma": (
        math.radians(math.hypot(2.0, 1.0)),
        read_only("compass sigma (rad) when the message gives none", **float_range(1e-5, math.pi)),
    ),
    "compass_offset": (
        0.0,
        read_only(
            "added to every compass yaw (rad): declination, mounting", **float_range(-7.0, 7.0)
        ),
    ),
    "wire_sigma": (0.03, read_only("wire contact position sigma (m)", **float_range(1e-4, 10.0))),
    "wire_max_distance": (
        2.0,
        read_only(
            "an unnamed contact takes the nearest wire within this (m)", **float_range(0.0, 1e3)
        ),
    ),
    "initial_pose": ([2.0, -1.0, math.pi / 2], read_only("start pose x, y (m), yaw (rad) in map")),
    "initial_sigma": ([0.01, 0.01, 0.01], read_only("start sigma x, y (m), yaw (rad), each > 0")),
    "mouse_noise": (
        [Q_POS, Q_YAW_DIST, Q_YAW_TURN],
        read_only(
            "mouse increment noise q_pos (m^2/m), q_yaw_dist (rad^2/m), q_yaw_turn (rad^2/rad)"
        ),
    ),
    "wheel_noise": (
        [0.03**2, 0.03**2, 0.03**2],
        read_only("wheel increment noise, as mouse_noise"),
    ),
    "mouse_stale_timeout": (
        0.5,
        read_only(
            "mouse odometry silent this long (s, stamps) -> wheels", **float_range(0.01, 60.0)
        ),
    ),
    "max_delay": (
        1.0,
        read_only(
            "a quiet source is waited for this long (s, stamps); later fixes are dropped",
            **float_range(0.01, 3600.0),
        ),
    ),
    "max_speed": (
        5.0,
        read_only(
            "odometry faster than this (m/s) is a reset or corrupt", **float_range(0.01, 1000.0)
        ),
    ),
    "reacquire_after": (
        10,
        read_only(
            "gate rejections in a row before a source's next fix is applied ungated (0 = never)",
            **int_range(0, 10**6),
        ),
    ),
    "queue_depth": (
        200,
        read_only("subscription queue depth", **int_range(1, 10**5)),
    ),
    "publish_rate": (
        20.0,
        read_only("~/odom messages per second (Hz)", **float_range(0.1, 1000.0)),
    ),
    "path_rate": (1.0, read_only("~/path messages per second (Hz)", **float_range(0.01, 100.0))),
    "path_spacing": (
        0.05,
        read_only("a path pose every this many metres", **float_range(0.0, 100.0)),
    ),
    "path_length": (
        10000,
        read_only("poses kept in the path", **int_range(2, 10**6)),
    ),
    "diagnostics_rate": (
        1.0,
        read_only("/diagnostics messages per second (Hz)", **float_range(0.01, 100.0)),
    ),
    "publish_tf": (
        True,
        read_only(
            "broadcast map -> odom on /tf (from the estimate and the mouse odometry's pose); "
            "odom -> base_link stays mm-odometry's"
        ),
    ),
}

#: parameters that take ``ros2 param set`` while the node runs; the rest are read-only
LIVE = ("publish_rate", "path_rate", "diagnostics_rate", "map_frame", "base_frame")
mark_live(PARAMETERS, LIVE)

def triple(name: str, values, positive: bool = False) -> list[float]:
    """A three-number parameter (a pose, sigmas, noise) checked: finite, > 0 if asked."""
    v = [float(x) for x in values]
    ok = len(v) == 3 and all(math.isfinite(x) and (x > 0 if positive else True) for x in v)
    if not ok:
        need = "three finite numbers" + (" > 0" if positive else "")
        raise ValueError(f"'{name}' needs {need}, got {list(values)}")
    return v


def beacons_from(names, xs, ys, heights) -> tuple[Beacon, ...]:
    """Beacons from the four parallel parameter lists (lengths must agree)."""
    n = len(names)
    if not (len(xs) == len(ys) == len(heights) == n):
        raise ValueError(
            f"'beacon_names', 'beacon_x', 'beacon_y', 'beacon_heights' must have the same "
            f"length, got {n}, {len(xs)}, {len(ys)}, {len(heights)}"
        )
    if len(set(names)) != n or not all(names):
        raise ValueError(f"'beacon_names' must be distinct and non-empty, got {list(names)}")
    return tuple(
        Beacon(float(x), float(y), float(h), str(name))
        for name, x, y, h in zip(names, xs, ys, heights, strict=True)
    )


def grid_from(p: dict) -> LocalGrid:
    """The GPS LocalGrid from the parameters."""
    if p["gps_scale"] not in GPS_SCALES:
        raise ValueError(f"'gps_scale' must be one of {GPS_SCALES}, got '{p['gps_scale']}'")
    if p["gps_scale"] == "wgs84":
        return LocalGrid(p["gps_origin_lat"], p["gps_origin_lon"])
    return LocalGrid.from_plot(
        p["gps_origin_lat"],
        p["gps_origin_lon"],
        p["gps_ne_lat"],
        p["gps_ne_lon"],
        p["plot_width"],
        p["plot_height"],
    )
