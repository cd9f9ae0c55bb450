"""The recording's topics and message types, and the ``ros2msg`` schema texts of the types.

Topic layout: see :mod:`mm_pc.monitor.io`. The schema texts are read from the
installed interface files (ament index), no rclpy.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

__all__ = [
    "LEGACY_POLLS_TYPE",
    "LEGACY_SENSOR_HASH",
    "LEGACY_SENSOR_TYPE",
    "META_LABEL",
    "META_TOPIC",
    "META_TYPE",
    "POLLS_TYPE",
    "POLL_TYPES",
    "REPLY_POLLS_TOPIC",
    "SAMPLES_TOPIC",
    "SAMPLES_TYPE",
    "SENSOR_TOPIC",
    "SENSOR_TYPE",
    "is_legacy_sensor_schema",
    "ros2msg_definition",
]

SENSOR_TOPIC = "/mm_beagle/sensor_data_replies"
META_TOPIC = "/mm_monitor/reply_meta"
SAMPLES_TOPIC = "/mm_monitor/samples"
REPLY_POLLS_TOPIC = "/mm_monitor/reply_polls"
SENSOR_TYPE = "mm_interfaces/msg/SensorData"
META_TYPE = "std_msgs/msg/Float64MultiArray"
POLLS_TYPE = "mm_interfaces/msg/SensorPolls"
#: how recordings before SensorPolls carried the polls (read, no longer written)
LEGACY_POLLS_TYPE = "mm_interfaces/srv/GetSamples_Response"
#: how recordings before SensorData's header (issue 25) are decoded: their channels say
#: SensorData, but their schema text is this type's (read, never written or published)
LEGACY_SENSOR_TYPE = "mm_interfaces/msg/LegacySensorData"
#: the RIHS01 hash of SensorData before its header (a channel's ``topic_type_hash``)
LEGACY_SENSOR_HASH = "RIHS01_5c159d52bc2a9db2f23fc71bff3e55d90f687990bff7f0833aa29faf66abbca5"
SAMPLES_TYPE = POLLS_TYPE
POLL_TYPES = (POLLS_TYPE, LEGACY_POLLS_TYPE)
META_LABEL = "received_s,rtt_s"

_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}  # fmt: skip
_SEPARATOR = "=" * 80


def _interface_text(type_name: str) -> str:
    """The .msg text of ``pkg/msg/Type``, or the response part of ``pkg/srv/Type_Response``."""
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    pkg, kind, name = type_name.split("/")
    try:
        share = Path(get_package_share_directory(pkg))
    except PackageNotFoundError:
        raise ValueError(f"the ROS package {pkg!r} of {type_name} is not installed") from None
    if kind == "srv":
        base, _, part = name.rpartition("_")
        text = (share / "srv" / f"{base}.srv").read_text()
        request, _, response = text.partition("\n---\n")
        return response if part == "Response" else request
    return (share / "msg" / f"{name}.msg").read_text()


def _first_field(text: str) -> str:
    """The first field line of a .msg text ('type name', comments and blanks skipped)."""
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if line:
            return " ".join(line.split()[:2])
    return ""


def is_legacy_sensor_schema(schema: bytes | str, type_hash: str = "") -> bool:
    """Is a ``SensorData`` channel with this ``ros2msg`` schema text (and
    ``topic_type_hash``, '' = none) one recorded before the header (issue 25)?

    The old type starts with ``builtin_interfaces/Time stamp``, the new one with
    ``std_msgs/Header header``; a schema without text falls back to the hash.
    """
    text = schema.decode("utf-8", "replace") if isinstance(schema, bytes) else schema
    first = _first_field(text)
    if first:
        return first.startswith("builtin_interfaces/Time ")
    return type_hash == LEGACY_SENSOR_HASH


def _field_types(text: str, pkg: str) -> list[str]:
    """Non-primitive field types (``pkg/Type``) used in a .msg text, in order."""
    out = []
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        ftype = line.split()[0]
        if "=" in line.split(None, 1)[-1].split()[0]:
            continue  # a constant
        base = re.sub(r"\[.*\]$", "", ftype)
        base = re.sub(r"<=\d+$", "", base)
        if base in _PRIMITIVES:
            continue
        if base == "Header":
            base = "std_msgs/Header"
        out.append(base if "/" in base else f"{pkg}/{base}")
    return out


@functools.cache
def ros2msg_definition(type_name: str) -> str:
    """The full ``ros2msg`` schema text of ``pkg/msg/Type`` as rosbag2 writes it into MCAP.

    The type's own .msg text, then each dependency once (depth first) after
    a line of 80 ``=`` and ``MSG: pkg/Type``. Read from the installed
    interface files (ament index).
    """
    pkg = type_name.split("/")[0]
    text = _interface_text(type_name)
    parts, seen = [text.rstrip("\n")], set()

    def add_deps(body: str, owner_pkg: str) -> None:
        for dep in _field_types(body, owner_pkg):
            if dep in seen:
                continue
            seen.add(dep)
            dpkg, dname = dep.split("/")
            dep_text = _interface_text(f"{dpkg}/msg/{dname}")
            parts.append(f"{_SEPARATOR}\nMSG: {dep}\n{dep_text.rstrip(chr(10))}")
            add_deps(dep_text, dpkg)

    add_deps(text, pkg)
    return "\n".join(parts) + "\n"
