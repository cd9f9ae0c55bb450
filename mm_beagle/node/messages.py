"""Turn poller totals into mm_interfaces messages (thin; no logic beyond deltas)."""

from __future__ import annotations

import os
from array import array

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from std_msgs.msg import Header

from mm_beagle.poller.shared_state import Totals
from mm_interfaces.msg import SensorData, SensorPolls, SensorSettings
from mm_pc.ros.tf import counts_frame, sensor_frame_names

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1


def stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _clamp32(v: int) -> int:
    return max(INT32_MIN, min(INT32_MAX, v))


def new_instance_id() -> int:
    """A random non-zero 64-bit node identity (0 means "unknown": a message before it)."""
    return int.from_bytes(os.urandom(8), "little") or 1


def counts_frames(devices, odometry) -> list[str]:
    """``SensorData.header.frame_id`` of each device: its sensor frame (``sensor_frames``,
    after ``frame_prefix``; ``odometry`` is the node's OdometrySettings) + ``_counts``."""
    names = sensor_frame_names(devices, odometry.sensor_frames, odometry.frame_prefix)
    return [counts_frame(n) for n in names]


def sensor_data(
    device: str,
    prev: Totals,
    now: Totals,
    instance_id: int = 0,
    chip: str = "pln2033",
    frame_id: str = "",
    header_stamp: Time | None = None,
) -> SensorData:
    """The displacement between two snapshots of one sensor's totals.

    ``instance_id``: the node's identity (:func:`new_instance_id`), so a client
    sees a restart whatever ``seq`` and the totals say. ``chip``: the device's chip
    (registry name); ``quality`` is the newest poll's figure (-1: the chip has none).
    ``frame_id``: the sensor's counting-axes frame (:func:`counts_frames`);
    ``header_stamp``: the newest poll on the node clock (``mm_pc.ros.clock.node_stamp``;
    None: its wall-clock stamp, what node_stamp gives without ``use_sim_time``).
    The ``stamp`` field is always the poll's wall-clock time.
    """
    interval = max(0.0, (now.stamp_ns - prev.stamp_ns) / 1e9)
    x_disp = now.x_total_m - prev.x_total_m
    y_disp = now.y_total_m - prev.y_total_m
    poll_stamp = stamp(now.stamp_ns)
    return SensorData(
        header=Header(
            stamp=poll_stamp if header_stamp is None else header_stamp, frame_id=frame_id
        ),
        stamp=poll_stamp,
        id=device,
        x_disp=x_disp,
        y_disp=y_disp,
        x_speed=x_disp / interval if interval > 0 else 0.0,
        y_speed=y_disp / interval if interval > 0 else 0.0,
        x_counts=_clamp32(now.x_total - prev.x_total),
        y_counts=_clamp32(now.y_total - prev.y_total),
        cpi=now.cpi_y,
        samples=now.seq - prev.seq,
        lift_events=now.lift_total - prev.lift_total,
        interval=interval,
        seq=now.seq,
        x_total_counts=now.x_total,
        y_total_counts=now.y_total,
        x_total_disp=now.x_total_m,
        y_total_disp=now.y_total_m,
        lift_events_total=now.lift_total,
        x_lift_est_counts=now.x_est_counts - prev.x_est_counts,
        y_lift_est_counts=now.y_est_counts - prev.y_est_counts,
        x_lift_est_disp=now.x_est_m - prev.x_est_m,
        y_lift_est_disp=now.y_est_m - prev.y_est_m,
        x_lift_est_total_disp=now.x_est_m,
        y_lift_est_total_disp=now.y_est_m,
        instance_id=instance_id,
        chip=chip,
        quality=max(-32768, min(32767, now.quality)),
        low_quality_events=now.low_quality_total - prev.low_quality_total,
        low_quality_events_total=now.low_quality_total,
    )


def sensor_settings(device: str, reply: dict) -> SensorSettings:
    """Any chip's dump as names + values and its CPI range; the 13 named register fields
    only for a PLN2033 (0 for other chips). Old agents send no chip: a PLN2033."""
    regs = reply["registers"]
    chip = reply.get("chip", "pln2033")
    msg = SensorSettings(spi_device=device, chip=chip)
    msg.register_names = [str(n) for n in regs]
    msg.register_values = array("H", (int(v) & 0xFFFF for v in regs.values()))
    lo, hi, step = reply.get("cpi_range", (0, 0, 0))
    msg.cpi_min, msg.cpi_max, msg.cpi_step = int(lo), int(hi), int(step)
    if chip == "pln2033":
        for name, value in regs.items():
            setattr(msg, f"{name}_register", int(value))
    msg.x_cpi = int(reply["cpi_x"])
    msg.y_cpi = int(reply["cpi_y"])
    msg.cpi = msg.y_cpi if msg.x_cpi == msg.y_cpi else 0
    msg.lifted = bool(reply["lifted"])
    msg.motion = bool(reply["motion"])
    return msg


def fill_polls(out, first: int, nxt: int, dropped: int, arr: dict, cpi_now: int):
    """Set the poll fields shared by GetSamples' response and SensorPolls on ``out``.

    ``first``/``nxt``/``dropped``/``arr``: the answer of
    :meth:`~mm_beagle.poller.shared_state.SharedState.samples`;
    ``cpi_now``: the CPI in force, for when no poll is returned. ``poll_cpi``: each
    poll's resolution from the ring, so a CPI change inside a reply is exact for the
    client (issue 28); ``cpi`` stays the newest poll's for old clients. Returns ``out``.
    """
    out.first_seq, out.next_seq, out.dropped = first, nxt, dropped
    out.cpi = int(arr["cpi"][-1]) if len(arr["cpi"]) else int(cpi_now)
    out.stamp_ns = as_array("Q", arr["stamp_ns"])
    out.dx = as_array("h", arr["dx"])
    out.dy = as_array("h", arr["dy"])
    out.status = as_array("H", arr["status"])
    out.flags = as_array("B", arr["flags"])
    out.quality = as_array("h", arr["quality"])  # the chip's figure per poll, -1 = none
    out.poll_cpi = as_array("H", arr["cpi"])
    return out


def sensor_polls(device: str, first: int, nxt: int, dropped: int, arr: dict, cpi_now: int):
    """A SensorPolls of ``device`` (stamp: its newest poll, 0 when empty); see fill_polls."""
    stamps = arr["stamp_ns"]
    msg = SensorPolls(id=device, stamp=stamp(int(stamps[-1]) if len(stamps) else 0))
    return fill_polls(msg, first, nxt, dropped, arr, cpi_now)


def as_array(typecode: str, values: np.ndarray) -> array:
    """numpy -> array.array: rclpy takes it for a primitive sequence without a per-item check."""
    out = array(typecode)
    out.frombytes(np.ascontiguousarray(values).tobytes())
    return out


def diagnostic(
    name: str, device: str, level: bytes, message: str, values: dict[str, object]
) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=level,
        name=name,
        message=message,
        hardware_id=device,
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
    )
