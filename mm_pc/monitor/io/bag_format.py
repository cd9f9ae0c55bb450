"""What makes a monitor recording a rosbag2 bag: QoS profiles, type hashes, the folder layout
and its ``metadata.yaml`` (rosbag2 Jazzy, bag format version 9, storage ``mcap``).

A recording path ending in ``.mcap`` is a single MCAP file; any other path is a
rosbag2 folder: ``<dir>/<dir name>_0.mcap`` plus ``<dir>/metadata.yaml``, which
``ros2 bag info/play`` and rosbags read. Either way the MCAP file carries the
bag's metadata in a Metadata record ``rosbag2`` (:func:`rosbag2_record`), as
Jazzy's MCAP storage plugin writes it. No rclpy here (the recorder and the
bridge hand their QoS over as the plain dicts below).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import yaml

__all__ = [
    "BAG_VERSION",
    "DEFAULT_QOS",
    "DIAGNOSTICS_QOS",
    "ROSBAG2_RECORD",
    "ROS_DISTRO",
    "SENSOR_DATA_QOS",
    "TF_QOS",
    "TF_STATIC_QOS",
    "LiveTopic",
    "bag_files",
    "bag_info",
    "live_topics",
    "qos_profile",
    "qos_yaml",
    "recording_target",
    "rosbag2_record",
    "type_hash",
    "write_metadata",
]

#: rosbag2's metadata.yaml version of Jazzy (QoS profiles as a YAML list, type hashes)
BAG_VERSION = 9
#: the ROS 2 distribution the bag format and the message types are those of
ROS_DISTRO = "jazzy"
#: the name of the MCAP Metadata record rosbag2's MCAP storage plugin reads and writes
ROSBAG2_RECORD = "rosbag2"

_ZERO = {"sec": 0, "nsec": 0}
#: rmw's "default" for deadline/lifespan/lease duration, as rosbag2 writes it
_INFINITE = {"sec": 9223372036, "nsec": 854775807}


def qos_profile(
    reliability: str = "reliable", durability: str = "volatile", depth: int = 10
) -> dict:
    """One QoS profile in rosbag2's v9 form (history keep_last, default deadline etc.)."""
    return {
        "history": "keep_last",
        "depth": int(depth),
        "reliability": reliability,
        "durability": durability,
        "deadline": dict(_INFINITE),
        "lifespan": dict(_INFINITE),
        "liveliness": "automatic",
        "liveliness_lease_duration": dict(_INFINITE),
        "avoid_ros_namespace_conventions": False,
    }


#: the channels the monitor makes itself (what `ros2 bag play` offers for them)
DEFAULT_QOS = qos_profile()
#: rclpy's qos_profile_sensor_data: mm-beagle's ~/sensor_data
SENSOR_DATA_QOS = qos_profile("best_effort", depth=5)
#: tf2_ros's broadcasters
TF_QOS = qos_profile(depth=100)
TF_STATIC_QOS = qos_profile(durability="transient_local", depth=1)
DIAGNOSTICS_QOS = qos_profile()


def qos_yaml(profiles: list[dict]) -> str:
    """The ``offered_qos_profiles`` string rosbag2 puts into an MCAP channel's metadata."""
    return yaml.dump(
        profiles, Dumper=_PlainDumper, default_flow_style=False, sort_keys=False
    ).strip()


@dataclass(frozen=True)
class LiveTopic:
    """A topic the recorder subscribes to: name, ``pkg/msg/Type``, the QoS of its publisher
    (``qos``, the v9 dict, what the recording states was offered) and the depth the
    subscription keeps (``listen_depth``, 0 = the publisher's)."""

    name: str
    type_name: str
    qos: dict
    listen_depth: int = 0

    @property
    def subscription_qos(self) -> dict:
        """The v9 dict the recorder subscribes with: the publisher's, at ``listen_depth``."""
        return {**self.qos, "depth": self.listen_depth} if self.listen_depth else self.qos


def live_topics(beagle: str = "/mm_beagle") -> tuple[LiveTopic, ...]:
    """The live topics of a Mouse Monitor system next to the beagle node ``beagle``.

    SensorData of mm-beagle, the three odometries (mm-odometry, mm-beagle's own,
    mm-fusion), TF and the diagnostics. A topic nobody publishes costs nothing.
    """
    base = "/" + beagle.strip("/")
    ns = base.rpartition("/")[0]  # the beagle's namespace: the other nodes run beside it
    odom = "nav_msgs/msg/Odometry"
    return (
        LiveTopic(f"{base}/sensor_data", "mm_interfaces/msg/SensorData", SENSOR_DATA_QOS),
        LiveTopic(f"{ns}/mm_odometry/odom", odom, DEFAULT_QOS),
        LiveTopic(f"{base}/odom", odom, DEFAULT_QOS),
        LiveTopic(f"{ns}/mm_fusion/odom", odom, DEFAULT_QOS),
        LiveTopic("/tf", "tf2_msgs/msg/TFMessage", TF_QOS),
        # tf2_ros's listener depth: several nodes' latched mounts may arrive together
        LiveTopic("/tf_static", "tf2_msgs/msg/TFMessage", TF_STATIC_QOS, listen_depth=100),
        LiveTopic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", DIAGNOSTICS_QOS),
    )


@functools.cache
def type_hash(type_name: str) -> str:
    """The RIHS01 type hash of ``pkg/msg/Type`` from its installed ``.json`` type description
    ('' when the package or the file is missing)."""
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    pkg, kind, name = type_name.split("/")
    try:
        path = Path(get_package_share_directory(pkg)) / kind / f"{name}.json"
        hashes = json.loads(path.read_text())["type_hashes"]
    except (PackageNotFoundError, OSError, KeyError, ValueError):
        return ""
    return next((h["hash_string"] for h in hashes if h["type_name"] == type_name), "")


def recording_target(path: str | Path) -> tuple[Path, Path | None]:
    """(the MCAP file to write, the rosbag2 folder or None) for a recording ``path``.

    ``*.mcap`` -> that file (its folder must exist); any other path -> a new
    rosbag2 folder (it must not exist or be empty; its parent must exist).
    ValueError saying what is wrong; nothing is created here.
    """
    path = Path(path)
    if path.suffix.lower() == ".mcap":
        if path.is_dir():
            raise ValueError(f"{path} is a folder, not a file")
        if not path.parent.is_dir():
            raise ValueError(f"the folder {path.parent} does not exist")
        return path, None
    if path.exists() and not path.is_dir():
        raise ValueError(
            f"{path} exists and is no folder (a recording into a file needs the .mcap suffix)"
        )
    if path.is_dir() and any(path.iterdir()):
        raise ValueError(f"the folder {path} is not empty (a rosbag2 recording needs a new one)")
    if not path.parent.is_dir():
        raise ValueError(f"the folder {path.parent} does not exist")
    name = path.resolve().name or "recording"
    return path / f"{name}_0.mcap", path


def bag_files(path: str | Path) -> list[Path]:
    """The MCAP files of a recording: ``path`` itself, or a rosbag2 folder's files (in the
    order of its metadata.yaml, else its ``*.mcap`` sorted; the folder's ``metadata.yaml``
    stands for the folder). ValueError for a folder without any."""
    path = Path(path)
    if path.name == "metadata.yaml" and path.is_file():  # the folder's index chosen
        path = path.parent
    if not path.is_dir():
        return [path]
    meta = path / "metadata.yaml"
    if meta.is_file():
        try:
            info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
            files = [path / str(p) for p in info["relative_file_paths"]]
        except (yaml.YAMLError, KeyError, TypeError, OSError) as e:
            raise ValueError(
                f"{meta} is no rosbag2 metadata file ({type(e).__name__}: {e})"
            ) from None
        if info.get("storage_identifier") != "mcap":
            raise ValueError(
                f"{path} is a rosbag2 bag with storage {info.get('storage_identifier')!r}; "
                "only mcap bags can be replayed"
            )
        return files
    files = sorted(path.glob("*.mcap"))
    if not files:
        raise ValueError(f"the folder {path} holds no recording (no metadata.yaml, no *.mcap)")
    return files


class _PlainDumper(yaml.SafeDumper):
    """Every profile written out in full (no YAML anchors/aliases, as rosbag2 writes it)."""

    def ignore_aliases(self, data) -> bool:
        return True


def bag_info(
    mcap_name: str,
    topics: list[tuple[str, str, list[dict], int]],
    start_ns: int,
    end_ns: int,
) -> dict:
    """The bag's metadata (``rosbag2_bagfile_information``) of one MCAP file ``mcap_name``.

    ``topics``: (name, type, offered QoS profiles, message count) of each
    channel; ``start_ns``/``end_ns``: the first and last message's log time
    (ns since the epoch; equal or 0 for an empty recording).
    """
    duration = max(0, int(end_ns) - int(start_ns))
    count = sum(t[3] for t in topics)
    start = {"nanoseconds_since_epoch": int(start_ns)}
    return {
        "version": BAG_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": start,
        "message_count": count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": name,
                    "type": type_name,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": profiles,
                    "type_description_hash": type_hash(type_name),
                },
                "message_count": n,
            }
            for name, type_name, profiles, n in topics
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [mcap_name],
        "files": [
            {
                "path": mcap_name,
                "starting_time": dict(start),
                "duration": {"nanoseconds": duration},
                "message_count": count,
            }
        ],
        "custom_data": {"recorded_by": "mm_monitor"},
        "ros_distro": ROS_DISTRO,
    }


def _dump(data: dict) -> str:
    return yaml.dump(data, Dumper=_PlainDumper, sort_keys=False)


def rosbag2_record(info: dict) -> dict[str, str]:
    """The fields of the MCAP Metadata record :data:`ROSBAG2_RECORD` for the bag ``info``.

    ``serialized_metadata``: ``info`` as YAML without the
    ``rosbag2_bagfile_information`` key, as rosbag2 Jazzy's MCAP storage plugin
    writes it (``update_metadata``) and reads it back for ``ros2 bag info`` of a bare
    file; ``ROS_DISTRO``: the key Humble's and Iron's plugin wrote instead (Jazzy reads
    it too, and keeps the distro inside ``serialized_metadata``).
    """
    return {"serialized_metadata": _dump(info), "ROS_DISTRO": ROS_DISTRO}


def write_metadata(folder: Path, info: dict) -> Path:
    """Write ``folder/metadata.yaml`` with the bag ``info`` (:func:`bag_info`)."""
    out = folder / "metadata.yaml"
    tmp = out.with_suffix(".yaml.tmp")
    tmp.write_text(_dump({"rosbag2_bagfile_information": info}))
    tmp.replace(out)
    return out
