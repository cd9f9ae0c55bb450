"""What one reply of mm_beagle holds, as plain Python (no Qt, no ROS): the one reader of
``mm_interfaces/SensorData``.

The monitor's ROS bridge turns each ``SensorData`` into a :class:`Reading` (duck-typed:
:meth:`Reading.from_msg` reads attributes only), so the monitor's session and the replay
of a recording run the very same code without rclpy; mm-odometry's totals
(:meth:`mm_pc.core.polls.SensorTotals.from_msg`) and mm-watch read it through here too.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Reading", "Reply"]


@dataclass(frozen=True)
class Reading:
    """One sensor in one reply. Sensor counting axes (X right, Y forward), metres, seconds.

    ``x_total``/``y_total``: measured displacement since the node started;
    ``x_lift_total``/``y_lift_total``: the node's estimate of what lifts lost
    (not included in the measured totals); ``seq``: polls done so far (it
    goes back when the node restarts); ``stamp_ns``: wall-clock time of the newest
    poll (ns since the epoch; the pose arithmetic uses it). Every other field of
    ``SensorData`` is kept too, so a recording holds the reply exactly.
    """

    id: str
    stamp_ns: int
    seq: int
    x_total: float
    y_total: float
    x_lift_total: float = 0.0
    y_lift_total: float = 0.0
    x_speed: float = 0.0
    y_speed: float = 0.0
    x_counts: int = 0
    y_counts: int = 0
    cpi: int = 0
    samples: int = 0
    lift_events: int = 0
    lift_events_total: int = 0
    interval: float = 0.0
    x_disp: float = 0.0
    y_disp: float = 0.0
    x_total_counts: int = 0
    y_total_counts: int = 0
    x_lift_est_counts: float = 0.0
    y_lift_est_counts: float = 0.0
    x_lift_est_disp: float = 0.0
    y_lift_est_disp: float = 0.0
    #: the node's random identity drawn at its start (0: unknown, e.g. an old recording);
    #: a different value is a restart whatever ``seq`` says
    instance_id: int = 0
    #: the sensor's chip ('' = an old node or recording: a PLN2033, no quality figure),
    #: the newest poll's quality figure (-1 = none; an old node's zero-filled 0 becomes
    #: -1 here), and the polls below the chip's quality threshold in the interval / in all
    chip: str = ""
    quality: int = -1
    low_quality_events: int = 0
    low_quality_events_total: int = 0
    #: the header (issue 25): the counting-axes TF frame ('' = an old node or recording,
    #: which had no header) and the newest poll on the node clock (ns; 0 = none)
    frame_id: str = ""
    header_stamp_ns: int = 0

    @classmethod
    def from_msg(cls, msg) -> Reading:
        """From an ``mm_interfaces/SensorData`` (or anything with its fields; the issue-15
        fields and the header may be missing: a ``LegacySensorData`` of an old recording)."""
        chip = str(getattr(msg, "chip", "") or "")
        header = getattr(msg, "header", None)
        return cls(
            id=str(msg.id),
            stamp_ns=int(msg.stamp.sec) * 1_000_000_000 + int(msg.stamp.nanosec),
            seq=int(msg.seq),
            x_total=float(msg.x_total_disp),
            y_total=float(msg.y_total_disp),
            x_lift_total=float(msg.x_lift_est_total_disp),
            y_lift_total=float(msg.y_lift_est_total_disp),
            x_speed=float(msg.x_speed),
            y_speed=float(msg.y_speed),
            x_counts=int(msg.x_counts),
            y_counts=int(msg.y_counts),
            cpi=int(msg.cpi),
            samples=int(msg.samples),
            lift_events=int(msg.lift_events),
            lift_events_total=int(msg.lift_events_total),
            interval=float(msg.interval),
            x_disp=float(msg.x_disp),
            y_disp=float(msg.y_disp),
            x_total_counts=int(msg.x_total_counts),
            y_total_counts=int(msg.y_total_counts),
            x_lift_est_counts=float(msg.x_lift_est_counts),
            y_lift_est_counts=float(msg.y_lift_est_counts),
            x_lift_est_disp=float(msg.x_lift_est_disp),
            y_lift_est_disp=float(msg.y_lift_est_disp),
            instance_id=int(getattr(msg, "instance_id", 0)),
            chip=chip,
            quality=int(getattr(msg, "quality", -1)) if chip else -1,
            low_quality_events=int(getattr(msg, "low_quality_events", 0)),
            low_quality_events_total=int(getattr(msg, "low_quality_events_total", 0)),
            frame_id=str(header.frame_id) if header is not None else "",
            header_stamp_ns=(
                int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
                if header is not None
                else 0
            ),
        )


@dataclass(frozen=True)
class Reply:
    """One answer of ``get_sensor_data``: the readings, and when and how fast it came.

    ``received_s``: monotonic time of arrival (s); ``rtt_s``: request to reply (s).
    ``polls``: device -> the polls this reply's totals cover: the ``SensorPolls`` the
    ``get_sensor_data`` reply carried, or a ``get_samples`` reply (None: that fetch
    failed); or None when no polls were fetched at all (the session then integrates
    the pose per reply).
    """

    readings: tuple[Reading, ...]
    received_s: float = 0.0
    rtt_s: float = 0.0
    polls: dict[str, object] | None = None

    def by_id(self) -> dict[str, Reading]:
        return {r.id: r for r in self.readings}
