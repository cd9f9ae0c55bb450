"""Read a monitor recording back: the replies exactly as received, and the fetched polls.

An MCAP file or a rosbag2 folder (:func:`.bag_format.bag_files`); layout in
:mod:`mm_pc.monitor.io`. Errors are ValueErrors saying what is wrong with the file.

Each reader is also a generator of steps (``*_steps``): it yields (None) after every
:data:`STEP_MESSAGES` messages read or decoded and returns its result, so the window can
read a recording in slices from a timer on its own thread (:func:`run_steps` drains one
at once). A worker thread decoding in Python starved the GUI thread of the GIL for the
whole read (0.2-0.4 s stalls at the start of a replay, docs/benchmarks.md).
"""

from __future__ import annotations

import contextlib
import math
import struct
from pathlib import Path

from mm_pc.core.sensor_data import Reading, Reply
from mm_pc.monitor.io.bag_format import bag_files
from mm_pc.monitor.io.cdr import decode_polls, decode_sensor_data, ros_types
from mm_pc.monitor.io.schemas import (
    META_TOPIC,
    META_TYPE,
    POLL_TYPES,
    REPLY_POLLS_TOPIC,
    SAMPLES_TOPIC,
    SENSOR_TOPIC,
    SENSOR_TYPE,
    is_legacy_sensor_schema,
)

__all__ = [
    "STEP_MESSAGES", "open_messages", "read_replies", "read_replies_up_to_cut",
    "read_replies_up_to_cut_steps", "read_samples", "run_steps",
]  # fmt: skip

#: messages read or decoded between two yields of a ``*_steps`` generator (~2-5 ms)
STEP_MESSAGES = 50


def run_steps(steps):
    """Drain a ``*_steps`` generator at once; its result."""
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value


def open_messages(path: str | Path):
    """((schema, channel, message) of every message, {topic: schema name}) of a file or a
    rosbag2 folder; ValueError saying what is wrong with one that cannot be read."""
    return run_steps(open_messages_steps(path))


def open_messages_steps(path: str | Path):
    """:func:`open_messages` as a generator of steps (see the module doc)."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"no recording at {path} (file not found)")
    messages, types = [], {}
    for file in bag_files(path):
        m, t = yield from _open_file_steps(file)
        messages += m
        for k, v in t.items():
            types.setdefault(k, v)
    return messages, types


def _open_file_steps(path: Path):
    from mcap.reader import make_reader

    yield  # the first import of mcap (and zstandard) is a step of its own

    if not path.is_file():
        raise ValueError(f"no recording at {path} (file not found)")
    try:
        with open(path, "rb") as f:
            if f.read(8) != b"\x89MCAP0\r\n":
                raise ValueError(f"{path} is not an MCAP file (it does not start with MCAP magic)")
            f.seek(0)
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            if summary is not None and summary.chunk_indexes:
                source = _indexed_messages(f, summary)
            else:  # no index: mcap's linear reader
                source = reader.iter_messages(log_time_order=False)
            messages = []
            for m in source:
                messages.append(m)
                if len(messages) % STEP_MESSAGES == 0:
                    yield
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


def _indexed_messages(f, summary):
    """(schema, channel, message) of an indexed file's chunks in file order, one record at
    a time (CRCs checked). mcap's ``iter_messages`` parses a whole chunk (thousands of
    messages, ~50 ms) in one go: one slice of reading that froze the window."""
    import io

    from mcap.data_stream import ReadDataStream
    from mcap.opcode import Opcode
    from mcap.records import Channel, Chunk, Message, Schema
    from mcap.stream_reader import get_chunk_data_stream

    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        f.seek(index.chunk_start_offset + 1 + 8, io.SEEK_SET)  # past opcode and length
        chunk = Chunk.read(ReadDataStream(f))
        stream, length = get_chunk_data_stream(chunk, validate_crc=True)
        while stream.count < length:
            opcode = stream.read1()
            size = stream.read8()
            if opcode == Opcode.MESSAGE:
                message = Message.read(stream, size)
                channel = summary.channels[message.channel_id]
                schema = summary.schemas[channel.schema_id] if channel.schema_id else None
                yield schema, channel, message
            elif opcode == Opcode.CHANNEL:
                Channel.read(stream)
            elif opcode == Opcode.SCHEMA:
                Schema.read(stream)
            else:
                stream.read(size)


def read_up_to_cut(path: str | Path):
    """(messages, types, warning) of one MCAP file that may be cut short (a crash, a full
    disk): the messages of its whole chunks, in file order, and a warning saying how much
    was read ("" for a whole file). A file that is damaged in another way (bad magic, a
    CRC error) raises the ValueError of :func:`open_messages`."""
    return run_steps(read_up_to_cut_steps(path))


def read_up_to_cut_steps(path: str | Path):
    """:func:`read_up_to_cut` as a generator of steps (see the module doc)."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Channel, DataEnd, Message, Schema
    from mcap.stream_reader import StreamReader

    path = Path(path)
    try:
        messages, types = yield from _open_file_steps(path)
        return messages, types, ""
    except ValueError as e:
        strict_error = e
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages, whole_bytes, record = [], 0, None

    def take(records) -> None:
        nonlocal record, whole_bytes
        for record in records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message) and record.channel_id in channels:
                channel = channels[record.channel_id]
                messages.append((schemas.get(channel.schema_id), channel, record))
                whole_bytes = f.tell()  # after the chunk holding it (or the file's end)
                if len(messages) % STEP_MESSAGES == 0:
                    yield
            elif isinstance(record, DataEnd):
                break  # every message is read; the cut is in the index after them

    with open(path, "rb") as f:
        if f.read(8) != b"\x89MCAP0\r\n":
            raise strict_error
        f.seek(0)
        ends = [8]  # where each whole record of the file ends (the magic is 8 bytes)
        try:
            yield from take(_noting_ends(StreamReader(f, validate_crcs=True).records, f, ends))
        except (EndOfFile, struct.error):  # the cut (a short read): what came before is whole
            f.seek(ends[-1])
            # the whole messages at the start of a chunk cut in its middle (a damaged one
            # is lost, the chunks before it stand)
            with contextlib.suppress(Exception):
                yield from take(_cut_chunk_records(f.read()))
            if whole_bytes == 0:
                raise ValueError(
                    f"{path} is cut short (a crash or a full disk?) before its first whole "
                    f"block of messages ({path.stat().st_size} bytes): nothing to replay"
                ) from None
        except Exception:
            raise strict_error from None
        else:
            if whole_bytes == 0 or not isinstance(record, DataEnd):
                raise strict_error  # it read to the end: the file is damaged, not cut
    size = path.stat().st_size
    types = {c.topic: (schemas[c.schema_id].name if c.schema_id in schemas else "")
             for c in channels.values()}  # fmt: skip
    if isinstance(record, DataEnd):
        warning = (
            f"{path.name} is cut short (a crash or a full disk?): all {len(messages)} messages "
            f"were read; only the index at its end ({size} bytes) is missing"
        )
    elif whole_bytes >= size:  # the last ones from the block the cut fell in
        warning = (
            f"{path.name} is cut short (a crash or a full disk?) at byte {size}: read "
            f"{len(messages)} whole messages, up to the cut; the rest of the recording is lost"
        )
    else:
        warning = (
            f"{path.name} is cut short (a crash or a full disk?) at byte {size}: read "
            f"{len(messages)} whole messages from its first {whole_bytes} bytes; the rest "
            "is lost"
        )
    return messages, types, warning


def _noting_ends(records, f, ends: list[int]):
    """``records`` as they come, noting in ``ends`` where the file stood after each."""
    for r in records:
        ends.append(f.tell())
        yield r


def _cut_chunk_records(data: bytes):
    """The whole records at the start of ``data``: a Chunk record cut short (zstd or not
    compressed), decompressed as far as it goes."""
    import io

    import zstandard
    from mcap.exceptions import EndOfFile
    from mcap.stream_reader import StreamReader

    head = struct.Struct("<BQQQQI")  # opcode, length, start, end, uncompressed size, crc
    if len(data) < head.size + 4 or data[0] != 0x06:  # 0x06: a Chunk
        return
    at = head.size
    (n,) = struct.unpack_from("<I", data, at)
    compression = data[at + 4 : at + 4 + n].decode()
    at += 4 + n + 8  # the compression's name, the records' length
    body = data[at:]
    if compression == "zstd":
        body = zstandard.ZstdDecompressor().decompressobj().decompress(body)
    elif compression:
        return  # lz4: not written by the monitor
    stream = StreamReader(io.BytesIO(body), skip_magic=True)
    with contextlib.suppress(EndOfFile, struct.error):  # the record the cut fell in
        yield from stream.records


def read_replies_up_to_cut(path: str | Path) -> tuple[list[Reply], str]:
    """(replies, warning) like :func:`read_replies`, but a single MCAP file cut short gives
    the replies of its whole messages and a warning saying how much was read ("" when the
    file is whole); see :func:`read_up_to_cut`."""
    return run_steps(read_replies_up_to_cut_steps(path))


def read_replies_up_to_cut_steps(path: str | Path):
    """:func:`read_replies_up_to_cut` as a generator of steps (see the module doc)."""
    path = Path(path)
    if not path.is_file():  # a rosbag2 folder or a missing file: read strictly
        messages, types = yield from open_messages_steps(path)
        replies = yield from _replies_of_steps(path, messages, types)
        return replies, ""
    messages, types, warning = yield from read_up_to_cut_steps(path)
    replies = yield from _replies_of_steps(path, messages, types)
    if warning and len(replies) >= 2 and not _as_whole(replies[-1], replies[-2]):
        replies.pop()  # the cut fell between its messages
        warning += "; the last reply, cut in two, is left out"
    if warning:
        warning += f"; {len(replies)} replies to replay"
    return replies, warning


def _as_whole(last: Reply, before: Reply) -> bool:
    """Does ``last`` have as many readings and fetched polls as ``before``?"""
    def polls(r: Reply) -> int:
        return sum(v is not None for v in (r.polls or {}).values())

    return len(last.readings) >= len(before.readings) and polls(last) >= polls(before)


def read_replies(path: str | Path) -> list[Reply]:
    """The replies recorded in ``path`` (by :class:`McapRecorder`, or any MCAP file with
    ``mm_interfaces/msg/SensorData`` messages), in recorded order.

    With the ``/mm_monitor/reply_meta`` channel, messages are grouped by their
    sequence number and ``received_s``/``rtt_s`` are exact; without it, the
    SensorData messages with the same ``log_time`` form one reply
    (``received_s`` = log_time in s, ``rtt_s`` = 0). Raises ValueError for a
    missing, non-MCAP or damaged file, or one without sensor data.
    """
    messages, types = open_messages(path)
    return _replies_of(path, messages, types)


def _replies_of(path, messages, types) -> list[Reply]:
    return run_steps(_replies_of_steps(path, messages, types))


def _ros_types_steps():
    """:func:`~.cdr.ros_types` with its imports and each type's C support loaded in steps of
    their own (the first time, 0.1-0.2 s each without a bridge, under load)."""
    import importlib

    from rclpy.type_support import check_for_type_support

    for name in ("rclpy.serialization", "builtin_interfaces.msg", "std_msgs.msg",
                 "mm_interfaces.msg", "mm_interfaces.srv"):  # fmt: skip
        importlib.import_module(name)
        yield
    ros = ros_types()
    for msg_type in (ros.SensorData, ros.Float64MultiArray, ros.SensorPolls):
        check_for_type_support(msg_type)
        yield
    return ros


def _replies_of_steps(path, messages, types):
    ros = yield from _ros_types_steps()
    deserialize_message, Float64MultiArray = ros.deserialize, ros.Float64MultiArray  # noqa: N806
    meta = []
    for n, (s, c, m) in enumerate(messages):
        if n % (8 * STEP_MESSAGES) == 0:
            yield
        if c.topic == META_TOPIC and s and s.name == META_TYPE:
            meta.append(m)
    # a monitor recording's replies are on SENSOR_TOPIC (the live topic's SensorData is
    # another stream); a foreign bag's SensorData on any topic. Each channel's schema
    # says whether it was recorded before SensorData's header (issue 25).
    legacy: dict[tuple[bytes, str], bool] = {}  # by schema (channel ids repeat across files)
    sensor = []
    for n, (s, c, m) in enumerate(messages):
        if n % (4 * STEP_MESSAGES) == 0:
            yield
        if (
            s is not None and s.name == SENSOR_TYPE and (not meta or c.topic == SENSOR_TOPIC)
            and c.message_encoding == "cdr"
        ):  # fmt: skip
            key = (bytes(s.data), c.metadata.get("topic_type_hash", ""))
            if key not in legacy:
                legacy[key] = is_legacy_sensor_schema(*key)
            sensor.append((legacy[key], m))
    if SENSOR_TYPE not in types.values():
        topics = sorted(types)
        raise ValueError(
            f"{path} holds no {SENSOR_TYPE} messages (topics: {', '.join(topics) or 'none'})"
        )
    try:
        readings = []
        for old, m in sensor:
            readings.append(
                (m.sequence, m.log_time, Reading.from_msg(decode_sensor_data(m.data, old)))
            )
            if len(readings) % STEP_MESSAGES == 0:
                yield
        metas = {}
        for m in meta:
            values = list(deserialize_message(m.data, Float64MultiArray).data)
            fetched = len(values) > 2 and values[2] == 1.0
            metas[m.sequence] = (m.log_time, float(values[0]), float(values[1]), fetched)
            if len(metas) % (4 * STEP_MESSAGES) == 0:
                yield
        polls: dict[int, dict[str, object]] = {}
        n = 0
        for s, c, m in messages:
            if c.topic.startswith(REPLY_POLLS_TOPIC + "/") and s is not None:
                device = c.metadata.get("device", c.topic)
                polls.setdefault(m.sequence, {})[device] = decode_polls(s.name, m.data)
                n += 1
                if n % STEP_MESSAGES == 0:
                    yield
    except Exception as e:  # deserialisation of foreign bytes can fail in many ways
        raise ValueError(
            f"{path}: a message could not be decoded ({type(e).__name__}: {e})"
        ) from None
    if metas:
        groups: dict[int, list[Reading]] = {k: [] for k in metas}
        for n, (seq, _, r) in enumerate(readings):
            groups.setdefault(seq, []).append(r)
            if n % (8 * STEP_MESSAGES) == 0:
                yield
        out = []
        for seq in sorted(groups):  # the reply number: recorded order
            if len(out) % (4 * STEP_MESSAGES) == 0:
                yield
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


def read_samples(path: str | Path) -> list[tuple[str, object]]:
    """(device, SensorPolls or old GetSamples response) of every recorded single-poll fetch
    on ``/mm_monitor/samples/*``, in order."""
    out = []
    for s, c, m in open_messages(path)[0]:
        if s is not None and s.name in POLL_TYPES and c.topic.startswith(SAMPLES_TOPIC + "/"):
            device = c.metadata.get("device", c.topic)
            out.append((m.log_time, device, decode_polls(s.name, m.data)))
    return [(d, r) for _, d, r in sorted(out, key=lambda x: x[0])]
