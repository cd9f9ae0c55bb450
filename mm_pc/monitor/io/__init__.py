"""A monitor recording on disk: an MCAP file (or rosbag2 folder) that ROS 2 tools open. No Qt.

File layout (MCAP profile ``ros2``, schemas ``ros2msg``, messages ``cdr``):

``/mm_beagle/sensor_data_replies`` -- ``mm_interfaces/msg/SensorData``
    One message per sensor per reply, built from each :class:`Reading`
    (stamp from ``stamp_ns``, the header from ``frame_id`` and ``header_stamp_ns``),
    every field as the node served it.
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
    :meth:`.mcap_writer.McapRecorder.write_samples`); channel metadata ``device``.
Live topics (:meth:`.mcap_writer.McapRecorder.write_live`, subscribed by the bridge:
:func:`.bag_format.live_topics`) -- under their own names and types
    ``<beagle>/sensor_data``, the odometries' ``.../odom``, ``/tf``,
    ``/tf_static``, ``/diagnostics``, as the publishers sent them (log time =
    arrival on the system clock).

Recordings before the SensorPolls type carry the polls as
``mm_interfaces/srv/GetSamples_Response``; they are still read. Recordings before
SensorData's header (issue 25) carry its old schema text and are decoded as
``mm_interfaces/msg/LegacySensorData`` (:func:`.schemas.is_legacy_sensor_schema`). Every channel has
rosbag2's ``offered_qos_profiles`` (and ``topic_type_hash``) metadata; a path
without ``.mcap`` is recorded as a rosbag2 folder with ``metadata.yaml``
(:mod:`.bag_format`).

Every message of one reply has the reply's number (from 0) as its MCAP
``sequence`` and the same ``log_time``: the arrival time on the system clock
(the monotonic ``received_s`` shifted by system-minus-monotonic at the first
reply), so tools show wall-clock times. ``publish_time`` is the node's poll
stamp for sensor data. A metadata record ``mm_monitor`` holds the start time,
the beagle node's name, the devices, the sample rate and the reply count; a
metadata record ``rosbag2`` (``serialized_metadata``, ``ROS_DISTRO``) the bag's
metadata as rosbag2 Jazzy's MCAP writer stores it (:func:`.bag_format.rosbag2_record`).

:func:`.mcap_reader.read_replies` gives the replies back exactly (every :class:`Reading`
field, ``received_s`` and ``rtt_s``), so a replay runs the very same
processing. ``ros2 bag play`` / Foxglove / rosbags read the file without
this code.

Modules: :mod:`.schemas` (topics, types, ``ros2msg`` schema texts), :mod:`.cdr`
(Reading and polls <-> CDR bytes, rclpy serialisation), :mod:`.mcap_writer`
(:class:`~.mcap_writer.McapRecorder`), :mod:`.mcap_reader` (``read_replies``,
``read_samples``), :mod:`.bag_format` (the rosbag2 side). The Qt side (File >
Record) is :mod:`mm_pc.monitor.recording`.
"""
