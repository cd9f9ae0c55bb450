"""Write a monitor recording: replies, fetched single polls and live topics as ROS 2 MCAP.

The layout of the file is described in :mod:`mm_pc.monitor.io`; a path without
``.mcap`` becomes a rosbag2 folder (:mod:`.bag_format`). No Qt: the window's
File > Record (:mod:`mm_pc.monitor.recording`) attaches a recorder to the context.
"""

from __future__ import annotations

import re
import threading
import time
from datetime import datetime, timezone
from pathlib import Path

from mm_pc.core.sensor_data import Reply
from mm_pc.monitor.io.bag_format import (
    DEFAULT_QOS,
    ROSBAG2_RECORD,
    bag_info,
    qos_yaml,
    recording_target,
    rosbag2_record,
    type_hash,
    write_metadata,
)
from mm_pc.monitor.io.cdr import polls_msg, ros_types, serialize_reading
from mm_pc.monitor.io.mcap_size import SizeTracker, metadata_bytes
from mm_pc.monitor.io.schemas import (
    META_LABEL,
    META_TOPIC,
    META_TYPE,
    POLLS_TYPE,
    REPLY_POLLS_TOPIC,
    SAMPLES_TOPIC,
    SENSOR_TOPIC,
    SENSOR_TYPE,
    ros2msg_definition,
)

__all__ = ["McapRecorder"]


class McapRecorder:
    """Writes replies, fetched single polls and live topics to ``path``, ROS 2 MCAP.

    ``path`` ending in ``.mcap``: one file; any other path: a rosbag2 folder
    (``<dir>/<dir name>_0.mcap`` + ``metadata.yaml`` at :meth:`close`). Raises
    ValueError for a path that cannot take a recording (see
    :func:`~mm_pc.monitor.io.bag_format.recording_target`) and OSError when the
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
            self._size = SizeTracker(self._file)
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
        self._metadata_size = (-1, 0)  # (channels, bytes of the Metadata records and index)
        ros = ros_types()
        self._meta_layout = ros.MultiArrayLayout(
            dim=[ros.MultiArrayDimension(label=META_LABEL, size=2, stride=2)]
        )

    def _channel(
        self, topic: str, type_name: str, metadata: dict | None = None,
        qos: list[dict] | None = None,
    ) -> int:  # fmt: skip
        schemas = self._schemas
        if type_name not in schemas:
            definition = ros2msg_definition(type_name).encode()
            schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding="ros2msg", data=definition
            )
            self._size.schema(type_name, "ros2msg", definition)
        profiles = [DEFAULT_QOS] if qos is None else list(qos)
        meta = {"offered_qos_profiles": qos_yaml(profiles)}
        if digest := type_hash(type_name):
            meta["topic_type_hash"] = digest
        meta = {**meta, **(metadata or {})}
        channel = self._writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=schemas[type_name], metadata=meta
        )
        self._size.channel(topic, "cdr", meta)
        self._topics[channel] = [topic, type_name, profiles, 0]
        return channel

    def _add(self, channel: int, log_time: int, data: bytes, publish_time: int, seq: int) -> None:
        self._writer.add_message(channel, log_time, data, publish_time, seq)
        self._size.message(channel, log_time, data, publish_time, seq)
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
        ros = ros_types()
        msgs = [(r, serialize_reading(r)) for r in reply.readings]
        polls = [
            (dev, ros.serialize(polls_msg(dev, res)))
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
        ros = ros_types()
        msg = polls_msg(device, response)
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

    def _metadata_records(self) -> tuple[dict, list[tuple[str, dict[str, str]]]]:
        """The bag's info and the Metadata records :meth:`close` writes (name, fields)."""
        info = bag_info(self.file.name, list(self._topics.values()), self._first_ns, self._last_ns)
        own = {
            "start_time": self.started.isoformat(),
            "start_time_ns": str(int(self.started.timestamp() * 1e9)),
            "end_time": datetime.now(timezone.utc).isoformat(),
            "beagle": self.beagle,
            "devices": ",".join(self.devices),
            "rate_hz": f"{self.rate_hz:g}",
            "replies": str(self.replies),
            "reply_meta": f"{META_TOPIC}: data = [received_s, rtt_s] (s, monotonic)",
        }
        return info, [("mm_monitor", own), (ROSBAG2_RECORD, rosbag2_record(info))]

    def size_bytes(self) -> int:
        """The file's size so far (bytes): what it would measure if closed now, the chunk
        still in memory counted compressed (:class:`~.mcap_size.SizeTracker`); once closed,
        its size on disk (for a folder, the ``.mcap`` file's)."""
        with self._lock:
            if not self.closed:
                if self._metadata_size[0] != len(self._topics):  # YAML: only when it grows
                    records = self._metadata_records()[1]
                    self._metadata_size = (len(self._topics), metadata_bytes(records))
                return self._size.estimate() + self._metadata_size[1]
        try:
            return self.file.stat().st_size
        except OSError:
            return 0

    def topic_counts(self) -> dict[str, int]:
        """Messages written so far per topic."""
        return {t[0]: t[3] for t in self._topics.values()}

    def close(self) -> None:
        """Write the metadata records and the index, close the file, then a folder's
        metadata.yaml (idempotent).

        Two Metadata records: ``mm_monitor`` (the recording's own facts) and
        ``rosbag2`` (the bag's metadata, the same as a folder's metadata.yaml:
        :func:`~mm_pc.monitor.io.bag_format.rosbag2_record`).
        """
        with self._lock:
            if self.closed:
                return
            self.closed = True
            info, records = self._metadata_records()
            try:
                for name, data in records:
                    self._writer.add_metadata(name, data)
                self._writer.finish()
            except OSError as e:
                if not self.error:
                    self._fail(e)
            finally:
                self._file.close()
            if self.folder is not None:
                try:
                    write_metadata(self.folder, info)
                except OSError as e:
                    if not self.error:
                        self._fail(e)
