"""How ``legacy_sensor_data.mcap`` was made (kept for the record; run once, at commit d834b41).

That code's ``SensorData`` had no header (today's ``LegacySensorData``), so the file
holds real old bytes and the old schema text. Run today, this would write the new type.
What it does: a sim mm-beagle (two emulated sensors on figure_eight) asked
``get_sensor_data`` with the single polls at about 20 Hz for 1.5 s (as the monitor's
bridge asks), every reply recorded by ``McapRecorder``, and the node's ``~/sensor_data``
(10 Hz) recorded as a live topic. ``legacy_sensor_data.json``: the replies, pose and
statistics that code read back from the file (``read_replies`` + ``MonitorSession``).

    source install/setup.bash
    cd /tmp && python /work/main/tests/data/make_legacy_sensor_data.py out.mcap
"""

from __future__ import annotations

import os
import sys
import time

from mm_beagle.tools.harness import BeagleClient, beagle_process, use_isolated_ros_env


def main(out: str) -> None:
    from rclpy.qos import qos_profile_sensor_data

    from mm_interfaces.msg import SensorData
    from mm_pc.core.sensor_data import Reading, Reply
    from mm_pc.monitor.io.bag_format import SENSOR_DATA_QOS
    from mm_pc.monitor.io.mcap_writer import McapRecorder

    use_isolated_ros_env()
    client = BeagleClient("mm_legacy_rec")
    live = []
    client.node.create_subscription(
        SensorData, "/mm_beagle/sensor_data", lambda m: live.append((time.time_ns(), m)),
        qos_profile_sensor_data, raw=True,
    )  # fmt: skip
    params = {"backend": "sim", "sim_trajectory": "figure_eight", "publish_rate": 10.0}
    with beagle_process(params, env=dict(os.environ), log_path="beagle.log"):
        assert client.wait(60)
        while not client.call("get_sensor_data", id="", timeout=10).success:
            time.sleep(0.2)
        rec = McapRecorder(out, rate_hz=20)
        devices: list[str] = []
        cursor: dict[str, int] = {}
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.5:
            sent = time.monotonic()
            res = client.call(
                "get_sensor_data", id="", polls_ids=devices,
                polls_since_seq=[cursor[d] for d in devices],
            )  # fmt: skip
            got = time.monotonic()
            assert res.success, res.message
            readings = tuple(Reading.from_msg(d) for d in res.data)
            polls = None
            if not devices:  # the first reply: the baseline, no polls asked
                devices = [r.id for r in readings]
                cursor = {r.id: r.seq for r in readings}
            else:
                polls = dict.fromkeys(devices)
                for p in res.polls:
                    polls[p.id] = p
                    cursor[p.id] = p.next_seq
            rec.write_reply(Reply(readings, received_s=got, rtt_s=got - sent, polls=polls))
            time.sleep(0.05)
        for t, data in live:
            rec.write_live(
                "/mm_beagle/sensor_data", "mm_interfaces/msg/SensorData", data,
                qos=[SENSOR_DATA_QOS], log_time_ns=t,
            )  # fmt: skip
        rec.close()
    client.close()


if __name__ == "__main__":
    main(sys.argv[1])
