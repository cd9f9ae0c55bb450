"""Readings and single polls <-> CDR bytes (rclpy's serialisation; no Qt).

:func:`serialize_reading` checks the integer ranges first (rclpy's serializer
mishandles out-of-range integers); :func:`deserialize_appended` also reads bytes
of recordings made before fields were appended to the messages, and
:func:`decode_sensor_data` those made before SensorData's header (issue 25).
"""

from __future__ import annotations

import functools
from types import SimpleNamespace

from mm_pc.core.sensor_data import Reading
from mm_pc.monitor.io.schemas import LEGACY_POLLS_TYPE, POLLS_TYPE

__all__ = [
    "decode_polls",
    "decode_sensor_data",
    "deserialize_appended",
    "polls_msg",
    "ros_types",
    "serialize_reading",
]


@functools.cache
def ros_types() -> SimpleNamespace:
    """The rclpy pieces, imported once (an import statement per message is costly under Qt)."""
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension, MultiArrayLayout

    from mm_interfaces.msg import LegacySensorData, SensorData, SensorPolls
    from mm_interfaces.srv import GetSamples

    return SimpleNamespace(
        Time=Time,
        Header=Header,
        SensorData=SensorData,
        LegacySensorData=LegacySensorData,
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
    "header_stamp_ns": (0, (2**31 - 1) * 1_000_000_000),
    "quality": (-(2**15), 2**15 - 1),
    "low_quality_events": (0, 2**32 - 1),
    "low_quality_events_total": (0, 2**64 - 1),
}


def polls_msg(device: str, res):
    """The ``SensorPolls`` of ``device`` from anything with GetSamples' response fields
    (a response, the bridge's empty stand-ins, a SensorPolls)."""
    ros = ros_types()
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
        # each poll's CPI (issue 28); empty: the reply's cpi for all (an old node or recording)
        poll_cpi=[int(v) for v in getattr(res, "poll_cpi", ())],
    )  # fmt: skip


def serialize_reading(r: Reading) -> bytes:
    """CDR bytes of the SensorData of one reading; ValueError when a value does not fit."""
    # checked here: rclpy's serializer mishandles out-of-range integers (SystemError)
    for name, (lo, hi) in _INT_RANGES.items():
        v = getattr(r, name)
        if not (isinstance(v, int) and lo <= v <= hi):
            raise ValueError(
                f"reading of {r.id!r} does not fit mm_interfaces/SensorData: "
                f"{name}={v!r} is not an integer in {lo}..{hi}"
            )
    ros = ros_types()
    Time, SensorData = ros.Time, ros.SensorData  # noqa: N806 - message classes
    h = r.header_stamp_ns
    try:
        return ros.serialize(SensorData(
            header=ros.Header(
                stamp=Time(sec=h // 1_000_000_000, nanosec=h % 1_000_000_000),
                frame_id=r.frame_id,
            ),
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


def deserialize_appended(data: bytes, msg_type):
    """``data`` as ``msg_type``; also a recording made before fields were appended.

    SensorData (now LegacySensorData), SensorPolls and GetSamples' response grew
    fields at their end (``instance_id`` in issue 13; chip and quality in issue 15;
    ``poll_cpi`` in issue 28).
    Older CDR bytes end early, so they get zero bytes appended: every missing field
    then reads 0, '' or empty ("unknown"), whatever alignment padding it needs.
    (SensorData's header, issue 25, came first, not last: :func:`decode_sensor_data`.)
    """
    ros = ros_types()
    try:
        return ros.deserialize(data, msg_type)
    except Exception:  # rclpy raises RMWError for bytes that end early
        return ros.deserialize(bytes(data) + bytes(_APPENDED_ROOM), msg_type)


_APPENDED_ROOM = 64  # bytes: more than the appended fields and their padding need


def decode_sensor_data(data: bytes, legacy: bool):
    """A SensorData, or (``legacy``: a recording made before its header, see
    :func:`~mm_pc.monitor.io.schemas.is_legacy_sensor_schema`) a LegacySensorData,
    whose fields :meth:`~mm_pc.core.sensor_data.Reading.from_msg` reads the same."""
    ros = ros_types()
    return deserialize_appended(data, ros.LegacySensorData if legacy else ros.SensorData)


def decode_polls(schema: str, data: bytes):
    """A SensorPolls, or a GetSamples response of a recording made before SensorPolls
    (both have the fields the pose needs); ValueError for another type."""
    ros = ros_types()
    if schema == POLLS_TYPE:
        return deserialize_appended(data, ros.SensorPolls)
    if schema == LEGACY_POLLS_TYPE:
        return deserialize_appended(data, ros.GetSamplesResponse)
    raise ValueError(f"single polls of type {schema!r}, expected {POLLS_TYPE}")
