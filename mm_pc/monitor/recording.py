"""Record what the monitor received to an MCAP file that ROS 2 tools open.

File layout (MCAP profile ``ros2``, schemas ``ros2msg``, messages ``cdr``):

``/mm_beagle/sensor_data_replies`` -- ``mm_interfaces/msg/SensorData``
    One message per sensor per reply, built from each :class:`Reading`
    (stamp from ``stamp_ns``), every field as the node served it.
``/mm_monitor/reply_meta`` -- ``std_msgs/msg/Float64MultiArray``
    One message per reply, ``data = [received_s, rtt_s]``: the exact
    monotonic arrival time and round-trip time (s) of the reply.
``/mm_monitor/reply_polls/<device>`` -- ``mm_interfaces/msg/SensorPolls``
    The single polls each reply's totals cover (``Reply.polls``, fetched by the
    bridge for the per-poll pose), with the reply's number as ``sequence``; the
    reply's ``reply_meta`` then has a third value 1.0 ("polls were fetched": a
    device without a message had a failed fetch). A replay integrates them per
    poll, as live; a recording without them is integrated per reply.
``/mm_monitor/samples/<device>`` -- ``mm_interfaces/msg/SensorPolls``
    The single 1 kHz polls, whenever they were fetched while recording (the
    recorder listens to the bridge's ``samples_received``;
    :meth:`McapRecorder.write_samples`); channel metadata ``device``.
Live topics (:meth:`McapRecorder.write_live`, subscribed by the bridge:
:func:`mm_pc.monitor.bag_format.live_topics`) -- under their own names and types
    ``<beagle>/sensor_data``, the odometries' ``.../odom``, ``/tf``,
    ``/tf_static``, ``/diagnostics``, as the publishers sent them (log time =
    arrival on the system clock).

Recordings before the SensorPolls type carry the polls as
``mm_interfaces/srv/GetSamples_Response``; they are still read. Every channel has
rosbag2's ``offered_qos_profiles`` (and ``topic_type_hash``) metadata; a path
without ``.mcap`` is recorded as a rosbag2 folder with ``metadata.yaml``
(:mod:`mm_pc.monitor.bag_format`).

Every message of one reply has the reply's number (from 0) as its MCAP
``sequence`` and the same ``log_time``: the arrival time on the system clock
(the monotonic ``received_s`` shifted by system-minus-monotonic at the first
reply), so tools show wall-clock times. ``publish_time`` is the node's poll
stamp for sensor data. A metadata record ``mm_monitor`` holds the start time,
the beagle node's name, the devices, the sample rate and the reply count.

:func:`read_replies` gives the replies back exactly (every :class:`Reading`
field, ``received_s`` and ``rtt_s``), so a replay runs the very same
processing. ``ros2 bag play`` / Foxglove / rosbags read the file without
this code.
"""

from __future__ import annotations

import contextlib
import functools
import math
import re
import threading
import time
import warnings
from datetime import datetime, timezone
from pathlib import Path
from types import SimpleNamespace

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QFileDialog, QLabel

from mm_pc.monitor.bag_format import (
    DEFAULT_QOS,
    bag_files,
    qos_yaml,
    recording_target,
    type_hash,
    write_metadata,
)
from mm_pc.monitor.model.readings import Reading, Reply
from mm_pc.monitor.settings import last_folder, remember_folder

__all__ = [
    "LEGACY_POLLS_TYPE",
    "META_TOPIC",
    "POLLS_TYPE",
    "REPLY_POLLS_TOPIC",
    "SAMPLES_TOPIC",
    "SENSOR_TOPIC",
    "McapRecorder",
    "read_replies",
    "read_samples",
    "ros2msg_definition",
    "start_recording",
    "stop_recording",
    "toggle_recording",
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
SAMPLES_TYPE = POLLS_TYPE
_POLL_TYPES = (POLLS_TYPE, LEGACY_POLLS_TYPE)
META_LABEL = "received_s,rtt_s"

_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}  # fmt: skip
_SEPARATOR = "=" * 80


# -- message definitions -------------------------------------------------------------------


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


# -- Reading <-> SensorData -------------------------------------------------------------------


@functools.cache
def _ros() -> SimpleNamespace:
    """The rclpy pieces, imported once (an import statement per message is costly under Qt)."""
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

    from mm_interfaces.msg import SensorData, SensorPolls
    from mm_interfaces.srv import GetSamples

    return SimpleNamespace(
        Time=Time,
        SensorData=SensorData,
        SensorPolls=SensorPolls,
        GetSamplesResponse=GetSamples.Response,
        Float64MultiArray=Float64MultiArray,
        MultiArrayDimension=MultiArrayDimension,
        MultiArrayLayout=MultiArrayLayout,
        serialize=serialize_message,
        deserialize=deserialize_message,
    )


#: integer fields of Reading -> (min, max) of their SensorData type
_INT_RANGES = {
    "x_counts": (-(2**31), 2**31 - 1),
    "y_counts": (-(2**31), 2**31 - 1),
    "cpi": (0, 2**16 - 1),
    "samples": (0, 2**32 - 1),
    "lift_events": (0, 2**32 - 1),
    "seq": (0, 2**64 - 1),
    "instance_id": (0, 2**64 - 1),
    "lift_events_total": (0, 2**64 - 1),
    "x_total_counts": (-(2**63), 2**63 - 1),
    "y_total_counts": (-(2**63), 2**63 - 1),
    "stamp_ns": (0, (2**31 - 1) * 1_000_000_000),
    "quality": (-(2**15), 2**15 - 1),
    "low_quality_events": (0, 2**32 - 1),
    "low_quality_events_total": (0, 2**64 - 1),
}


def _polls_msg(device: str, res):
    """The ``SensorPolls`` of ``device`` from anything with GetSamples' response fields
    (a response, the bridge's empty stand-ins, a SensorPolls)."""
    ros = _ros()
    stamps = res.stamp_ns
    newest = int(stamps[-1]) if len(stamps) else 0
    return ros.SensorPolls(
        stamp=ros.Time(sec=newest // 1_000_000_000, nanosec=newest % 1_000_000_000),
        id=device, first_seq=int(res.first_seq), next_seq=int(res.next_seq),
        dropped=int(res.dropped), cpi=int(res.cpi),
        stamp_ns=[int(v) for v in stamps], dx=[int(v) for v in res.dx],
        dy=[int(v) for v in res.dy], status=[int(v) for v in res.status],
        flags=[int(v) for v in res.flags],
        # one figure per poll; empty: none (a chip without one, an old node or recording)
        quality=[int(v) for v in getattr(res, "quality", ())],
    )  # fmt: skip


def _serialize_reading(r: Reading) -> bytes:
    """CDR bytes of the SensorData of one reading; ValueError when a value does not fit."""
    # checked here: rclpy's serializer mishandles out-of-range integers (SystemError)
    for name, (lo, hi) in _INT_RANGES.items():
        v = getattr(r, name)
        if not (isinstance(v, int) and lo <= v <= hi):
            raise ValueError(
                f"reading of {r.id!r} does not fit mm_interfaces/SensorData: "
                f"{name}={v!r} is not an integer in {lo}..{hi}"
            )
    ros = _ros()
    Time, SensorData = ros.Time, ros.SensorData  # noqa: N806 - message classes
    try:
        return ros.serialize(SensorData(
            stamp=Time(sec=r.stamp_ns // 1_000_000_000, nanosec=r.stamp_ns % 1_000_000_000),
            id=r.id,
            x_disp=r.x_disp,
            y_disp=r.y_disp,
            x_total_counts=r.x_total_counts,
            y_total_counts=r.y_total_counts,
            x_lift_est_counts=r.x_lift_est_counts,
            y_lift_est_counts=r.y_lift_est_counts,
            x_lift_est_disp=r.x_lift_est_disp,
            y_lift_est_disp=r.y_lift_est_disp,
            x_speed=r.x_speed,
            y_speed=r.y_speed,
            x_counts=r.x_counts,
            y_counts=r.y_counts,
            cpi=r.cpi,
            samples=r.samples,
            lift_events=r.lift_events,
            interval=r.interval,
            seq=r.seq,
            x_total_disp=r.x_total,
            y_total_disp=r.y_total,
            lift_events_total=r.lift_events_total,
            x_lift_est_total_disp=r.x_lift_total,
            y_lift_est_total_disp=r.y_lift_total,
            instance_id=r.instance_id,
            chip=r.chip,
            quality=r.quality,
            low_quality_events=r.low_quality_events,
            low_quality_events_total=r.low_quality_events_total,
        ))  # fmt: skip
    except (AssertionError, TypeError, ValueError, OverflowError, SystemError) as e:
        raise ValueError(
            f"reading of {r.id!r} does not fit mm_interfaces/SensorData: {e}"
        ) from None


# -- the recorder --------------------------------------------------------------------------------


class McapRecorder:
    """Writes replies, fetched single polls and live topics to ``path``, ROS 2 MCAP.

    ``path`` ending in ``.mcap``: one file; any other path: a rosbag2 folder
    (``<dir>/<dir name>_0.mcap`` + ``metadata.yaml`` at :meth:`close`). Raises
    ValueError for a path that cannot take a recording (see
    :func:`~mm_pc.monitor.bag_format.recording_target`) and OSError when the
    file cannot be created. A write error later (disk full) does not raise
    into the monitor: the recorder stops writing, keeps the message in
    ``error`` and calls ``on_error(message)`` once. Thread-safe: the live
    topics arrive on the bridge's executor thread, the replies on the GUI thread.
    """

    def __init__(self, path: str | Path, beagle: str = "/mm_beagle", rate_hz: float = 0.0) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self.file, self.folder = recording_target(self.path)
        self.beagle = beagle
        self.rate_hz = float(rate_hz)
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        #: channel id -> [topic, type, offered QoS profiles, message count]
        self._topics: dict[int, list] = {}
        self._first_ns = self._last_ns = 0
        if self.folder is not None:
            self.folder.mkdir(exist_ok=True)
        self._file = open(self.file, "wb")  # noqa: SIM115 - closed in close()
        try:
            self._writer = Writer(self._file, compression=CompressionType.ZSTD)
            self._writer.start(profile="ros2", library="mm_monitor")
            self._sensor_channel = self._channel(SENSOR_TOPIC, SENSOR_TYPE)
            self._meta_channel = self._channel(META_TOPIC, META_TYPE)
        except Exception:
            self._file.close()
            raise
        self._sample_channels: dict[str, int] = {}
        self._poll_channels: dict[str, int] = {}
        self._live_channels: dict[str, int] = {}
        self.started = datetime.now(timezone.utc)
        self.replies = 0
        self.samples_messages = 0
        self.live_messages = 0
        #: live topics not recorded: topic -> why (their type's definition is not installed)
        self.skipped: dict[str, str] = {}
        self.devices: list[str] = []
        self.error = ""
        self.on_error = None
        self.closed = False
        self._offset_ns: int | None = None
        ros = _ros()
        self._meta_layout = ros.MultiArrayLayout(
            dim=[ros.MultiArrayDimension(label=META_LABEL, size=2, stride=2)]
        )

    def _channel(
        self, topic: str, type_name: str, metadata: dict | None = None,
        qos: list[dict] | None = None,
    ) -> int:  # fmt: skip
        schemas = self._schemas
        if type_name not in schemas:
            schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding="ros2msg", data=ros2msg_definition(type_name).encode()
            )
        profiles = [DEFAULT_QOS] if qos is None else list(qos)
        meta = {"offered_qos_profiles": qos_yaml(profiles)}
        if digest := type_hash(type_name):
            meta["topic_type_hash"] = digest
        channel = self._writer.register_channel(
            topic=topic,
            message_encoding="cdr",
            schema_id=schemas[type_name],
            metadata={**meta, **(metadata or {})},
        )
        self._topics[channel] = [topic, type_name, profiles, 0]
        return channel

    def _add(self, channel: int, log_time: int, data: bytes, publish_time: int, seq: int) -> None:
        self._writer.add_message(channel, log_time, data, publish_time, seq)
        self._topics[channel][3] += 1
        if not self._first_ns or log_time < self._first_ns:
            self._first_ns = log_time
        self._last_ns = max(self._last_ns, log_time)

    def _log_time(self, received_s: float) -> int:
        ns = round(received_s * 1e9)
        if self._offset_ns is None:
            self._offset_ns = time.time_ns() - ns
        return max(0, ns + self._offset_ns)

    def write_reply(self, reply: Reply) -> None:
        """Append one reply: its readings, its single polls and its arrival/round-trip times.

        ValueError (nothing written) when a reading does not fit SensorData
        or the recorder is closed.
        """
        if self.closed:
            raise ValueError(f"the recording {self.path} is closed")
        if self.error:
            return
        ros = _ros()
        msgs = [(r, _serialize_reading(r)) for r in reply.readings]
        polls = [
            (dev, ros.serialize(_polls_msg(dev, res)))
            for dev, res in (reply.polls or {}).items()
            if res is not None
        ]
        values = [float(reply.received_s), float(reply.rtt_s)]
        if reply.polls is not None:
            values.append(1.0)
        meta = ros.serialize(ros.Float64MultiArray(layout=self._meta_layout, data=values))
        with self._lock:
            if self.closed:
                return
            log_time = self._log_time(reply.received_s)
            seq = self.replies & 0xFFFFFFFF
            try:
                self._add(self._meta_channel, log_time, meta, log_time, seq)
                for r, data in msgs:
                    self._add(self._sensor_channel, log_time, data, r.stamp_ns, seq)
                for dev, data in polls:
                    self._add(self._poll_channel(dev), log_time, data, log_time, seq)
            except OSError as e:
                self._fail(e)
                return
            self.replies += 1
        for r in reply.readings:
            if r.id not in self.devices:
                self.devices.append(r.id)

    def _device_channel(self, channels: dict, prefix: str, device: str) -> int:
        if device not in channels:
            suffix = re.sub(r"[^A-Za-z0-9_/]", "_", device).strip("/") or "sensor"
            channels[device] = self._channel(f"{prefix}/{suffix}", POLLS_TYPE, {"device": device})
        return channels[device]

    def _poll_channel(self, device: str) -> int:
        return self._device_channel(self._poll_channels, REPLY_POLLS_TOPIC, device)

    def write_samples(self, device: str, response) -> None:
        """Append the single polls of a ``GetSamples.Response`` of ``device`` (the debug
        view's fetches) as a SensorPolls."""
        if self.closed:
            raise ValueError(f"the recording {self.path} is closed")
        if self.error:
            return
        ros = _ros()
        msg = _polls_msg(device, response)
        data = ros.serialize(msg)
        with self._lock:
            if self.closed:
                return
            try:
                channel = self._device_channel(self._sample_channels, SAMPLES_TOPIC, device)
                now = time.time_ns()
                publish = int(msg.stamp_ns[-1]) if len(msg.stamp_ns) else now
                self._add(channel, now, data, publish, self.samples_messages & 0xFFFFFFFF)
            except OSError as e:
                self._fail(e)
                return
            self.samples_messages += 1

    def write_live(
        self, topic: str, type_name: str, data: bytes, qos: list[dict] | None = None,
        log_time_ns: int | None = None,
    ) -> None:  # fmt: skip
        """Append one CDR message received on a live topic (any thread).

        ``qos``: the publishers' offered profiles, stored with the channel when
        the topic's first message arrives. After :meth:`close` it is dropped
        silently (a message still on its way from the executor thread).
        """
        now = time.time_ns() if log_time_ns is None else int(log_time_ns)
        with self._lock:
            if self.closed or self.error:
                return
            if topic in self.skipped:
                return
            try:
                channel = self._live_channels.get(topic)
                if channel is None:
                    try:
                        channel = self._channel(topic, type_name, qos=qos)
                    except ValueError as e:  # no installed definition: never raise into rclpy
                        self.skipped[topic] = str(e)
                        return
                    self._live_channels[topic] = channel
                self._add(channel, now, bytes(data), now, self._topics[channel][3] & 0xFFFFFFFF)
            except OSError as e:
                self._fail(e)
                return
            self.live_messages += 1

    def _fail(self, e: OSError) -> None:
        self.error = f"recording to {self.path} stopped: {e}"
        if self.on_error is not None:
            self.on_error(self.error)

    def topic_counts(self) -> dict[str, int]:
        """Messages written so far per topic."""
        return {t[0]: t[3] for t in self._topics.values()}

    def close(self) -> None:
        """Write the metadata and the index, close the file, then a folder's metadata.yaml
        (idempotent)."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
            try:
                self._writer.add_metadata(
                    "mm_monitor",
                    {
                        "start_time": self.started.isoformat(),
                        "start_time_ns": str(int(self.started.timestamp() * 1e9)),
                        "end_time": datetime.now(timezone.utc).isoformat(),
                        "beagle": self.beagle,
                        "devices": ",".join(self.devices),
                        "rate_hz": f"{self.rate_hz:g}",
                        "replies": str(self.replies),
                        "reply_meta": f"{META_TOPIC}: data = [received_s, rtt_s] (s, monotonic)",
                    },
                )
                self._writer.finish()
            except OSError as e:
                if not self.error:
                    self._fail(e)
            finally:
                self._file.close()
            if self.folder is not None:
                try:
                    write_metadata(
                        self.folder, self.file.name, list(self._topics.values()),
                        self._first_ns, self._last_ns,
                    )  # fmt: skip
                except OSError as e:
                    if not self.error:
                        self._fail(e)


# -- reading back ------------------------------------------------------------------------------


def _open_messages(path: str | Path):
    """((schema, channel, message) of every message, {topic: schema name}) of a file or a
    rosbag2 folder; ValueError saying what is wrong with one that cannot be read."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"no recording at {path} (file not found)")
    messages, types = [], {}
    for file in bag_files(path):
        m, t = _open_file(file)
        messages += m
        for k, v in t.items():
            types.setdefault(k, v)
    return messages, types


def _open_file(path: Path):
    from mcap.reader import make_reader

    if not path.is_file():
        raise ValueError(f"no recording at {path} (file not found)")
    try:
        with open(path, "rb") as f:
            if f.read(8) != b"\x89MCAP0\r\n":
                raise ValueError(f"{path} is not an MCAP file (it does not start with MCAP magic)")
            f.seek(0)
            reader = make_reader(f, validate_crcs=True)
            messages = list(reader.iter_messages(log_time_order=False))
            summary = reader.get_summary()
    except ValueError:
        raise
    except Exception as e:  # the mcap reader raises many kinds on a damaged file
        raise ValueError(
            f"{path} is a damaged or incomplete MCAP file ({type(e).__name__}: {e}); "
            "a recording cut short can be repaired with `mcap recover`"
        ) from None
    types = {c.topic: (s.name if s else "") for s, c, _ in messages}
    if summary is not None:  # channels without messages (an empty recording)
        for c in summary.channels.values():
            schema = summary.schemas.get(c.schema_id)
            types.setdefault(c.topic, schema.name if schema else "")
    return messages, types


def read_replies(path: str | Path) -> list[Reply]:
    """The replies recorded in ``path`` (by :class:`McapRecorder`, or any MCAP file with
    ``mm_interfaces/msg/SensorData`` messages), in recorded order.

    With the ``/mm_monitor/reply_meta`` channel, messages are grouped by their
    sequence number and ``received_s``/``rtt_s`` are exact; without it, the
    SensorData messages with the same ``log_time`` form one reply
    (``received_s`` = log_time in s, ``rtt_s`` = 0). Raises ValueError for a
    missing, non-MCAP or damaged file, or one without sensor data.
    """
    ros = _ros()
    deserialize_message, SensorData = ros.deserialize, ros.SensorData  # noqa: N806
    Float64MultiArray = ros.Float64MultiArray  # noqa: N806
    messages, types = _open_messages(path)
    meta = [m for s, c, m in messages if c.topic == META_TOPIC and s and s.name == META_TYPE]
    # a monitor recording's replies are on SENSOR_TOPIC (the live topic's SensorData is
    # another stream); a foreign bag's SensorData on any topic
    sensor = [
        (c, m) for s, c, m in messages
        if s is not None and s.name == SENSOR_TYPE and (not meta or c.topic == SENSOR_TOPIC)
    ]  # fmt: skip
    if SENSOR_TYPE not in types.values():
        topics = sorted(types)
        raise ValueError(
            f"{path} holds no {SENSOR_TYPE} messages (topics: {', '.join(topics) or 'none'})"
        )
    try:
        readings = [
            (m.sequence, m.log_time, Reading.from_msg(_deserialize_appended(m.data, SensorData)))
            for c, m in sensor
            if c.message_encoding == "cdr"
        ]
        metas = {}
        for m in meta:
            values = list(deserialize_message(m.data, Float64MultiArray).data)
            fetched = len(values) > 2 and values[2] == 1.0
            metas[m.sequence] = (m.log_time, float(values[0]), float(values[1]), fetched)
        polls: dict[int, dict[str, object]] = {}
        for s, c, m in messages:
            if c.topic.startswith(REPLY_POLLS_TOPIC + "/") and s is not None:
                device = c.metadata.get("device", c.topic)
                polls.setdefault(m.sequence, {})[device] = _decode_polls(s.name, m.data)
    except Exception as e:  # deserialisation of foreign bytes can fail in many ways
        raise ValueError(
            f"{path}: a message could not be decoded ({type(e).__name__}: {e})"
        ) from None
    if metas:
        groups: dict[int, list[Reading]] = {k: [] for k in metas}
        for seq, _, r in readings:
            groups.setdefault(seq, []).append(r)
        out = []
        for seq in sorted(groups):  # the reply number: recorded order
            _, received, rtt, fetched = metas.get(seq, (0, math.nan, 0.0, False))
            got = None
            if fetched:  # a device without a message: its fetch had failed
                got = {r.id: polls.get(seq, {}).get(r.id) for r in groups[seq]}
            out.append(Reply(tuple(groups[seq]), received_s=received, rtt_s=rtt, polls=got))
        return out
    by_time: dict[int, list[Reading]] = {}
    for _, log_time, r in readings:
        by_time.setdefault(log_time, []).append(r)
    return [Reply(tuple(v), received_s=t / 1e9) for t, v in sorted(by_time.items())]


def _deserialize_appended(data: bytes, msg_type):
    """``data`` as ``msg_type``; also a recording made before fields were appended.

    SensorData, SensorPolls and GetSamples' response grew fields at their end
    (``instance_id`` in issue 13; chip and quality in issue 15). Older CDR bytes
    end early, so they get zero bytes appended: every missing field then reads 0,
    '' or empty ("unknown"), whatever alignment padding it needs.
    """
    ros = _ros()
    try:
        return ros.deserialize(data, msg_type)
    except Exception:  # rclpy raises RMWError for bytes that end early
        return ros.deserialize(bytes(data) + bytes(_APPENDED_ROOM), msg_type)


_APPENDED_ROOM = 64  # bytes: more than the appended fields and their padding need


def _decode_polls(schema: str, data: bytes):
    """A SensorPolls, or a GetSamples response of a recording made before SensorPolls
    (both have the fields the pose needs); ValueError for another type."""
    ros = _ros()
    if schema == POLLS_TYPE:
        return _deserialize_appended(data, ros.SensorPolls)
    if schema == LEGACY_POLLS_TYPE:
        return _deserialize_appended(data, ros.GetSamplesResponse)
    raise ValueError(f"single polls of type {schema!r}, expected {POLLS_TYPE}")


def read_samples(path: str | Path) -> list[tuple[str, object]]:
    """(device, SensorPolls or old GetSamples response) of every recorded single-poll fetch
    on ``/mm_monitor/samples/*``, in order."""
    out = []
    for s, c, m in _open_messages(path)[0]:
        if s is not None and s.name in _POLL_TYPES and c.topic.startswith(SAMPLES_TOPIC + "/"):
            device = c.metadata.get("device", c.topic)
            out.append((m.log_time, device, _decode_polls(s.name, m.data)))
    return [(d, r) for _, d, r in sorted(out, key=lambda x: x[0])]


# -- the window's File > Record action -------------------------------------------------------------


def _set_indicator(window, text: str | None) -> None:
    label = getattr(window, "_recording_label", None)
    if text is None:
        if label is not None:
            window.statusBar().removeWidget(label)
            label.deleteLater()
            window._recording_label = None
        return
    if label is None:
        label = QLabel()
        label.setStyleSheet("color: #b00020; font-weight: bold")
        window.statusBar().addPermanentWidget(label)
        window._recording_label = label
    label.setText(text)


def start_recording(window, path: str | Path, live: bool = True) -> bool:
    """Record every reply from now on to ``path`` (``*.mcap`` or a rosbag2 folder), and
    with ``live`` and a bridge also the live topics
    (:func:`~mm_pc.monitor.bag_format.live_topics` of the watched node); False (nothing
    attached) on an error, which is shown in the status bar."""
    ctx = window.ctx
    if ctx.recorder is not None:
        window.statusBar().showMessage(f"already recording to {ctx.recorder.path}", 8000)
        return False
    try:
        recorder = McapRecorder(path, beagle=ctx.config.beagle, rate_hz=ctx.config.rate_hz)
    except (OSError, ValueError) as e:
        window.statusBar().showMessage(f"cannot record to {path}: {e}", 10000)
        return False

    def failed(message: str) -> None:
        # called from inside ctx.on_reply: detach after it returns
        QTimer.singleShot(0, lambda: _stop_after_error(window, recorder, message))

    recorder.on_error = failed
    ctx.recorder = recorder
    if ctx.bridge is not None:  # single polls fetched by anyone (the debug view) go in too
        ctx.bridge.samples_received.connect(recorder.write_samples)
        if live:
            from mm_pc.monitor.bag_format import live_topics

            ctx.bridge.record_topics(live_topics(ctx.config.beagle), recorder.write_live)
    window.record_action.setText("Stop &recording")
    _set_indicator(window, f"● REC {recorder.path.name}")
    window.statusBar().showMessage(f"recording to {recorder.path}")
    return True


def _stop_after_error(window, recorder: McapRecorder, message: str) -> None:
    if window.ctx.recorder is recorder:
        stop_recording(window)
    window.statusBar().showMessage(message, 15000)


def stop_recording(window) -> Path | None:
    """Stop and close the recording; the file's path (None when nothing was recorded)."""
    recorder = window.ctx.recorder
    if recorder is None:
        return None
    window.ctx.recorder = None
    if window.ctx.bridge is not None:
        with contextlib.suppress(RuntimeError, TypeError), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            window.ctx.bridge.samples_received.disconnect(recorder.write_samples)
        window.ctx.bridge.stop_recording_topics()
    recorder.close()
    window.record_action.setText("&Record…")
    _set_indicator(window, None)
    if recorder.error:
        window.statusBar().showMessage(recorder.error, 15000)
    else:
        window.statusBar().showMessage(
            f"recorded {recorder.replies} replies to {recorder.path}", 8000
        )
    return recorder.path


def toggle_recording(window) -> None:
    """File > Record: ask for a file and start, or stop the running recording."""
    if window.ctx.recorder is not None:
        stop_recording(window)
        return
    default = Path(last_folder("recording")) / datetime.now().strftime(
        "mouse-monitor-%Y%m%d-%H%M%S.mcap"
    )
    name, _ = QFileDialog.getSaveFileName(
        window, "Record replies to", str(default), "MCAP recordings (*.mcap);;All files (*)"
    )
    if name:
        remember_folder("recording", name)
        start_recording(window, name)
