"""A restarted node is seen by its identity, even when it ran longer than the old one.

Real processes: two mm-beagle runs one after the other (sim backend); the
monitor's session is fed their real replies.
"""

from __future__ import annotations

import os

import pytest
from fakes import scaled, wait_until

rclpy = pytest.importorskip("rclpy")

from mm_beagle.tools.harness import BeagleClient, beagle_process  # noqa: E402
from mm_pc.core.sensor_data import Reading, Reply  # noqa: E402
from mm_pc.monitor.model.session import MonitorSession  # noqa: E402

S0 = "/dev/spidev1.0"

pytestmark = pytest.mark.ros


def _reply(client) -> Reply:
    res = client.call("get_sensor_data", id="")
    assert res.success, res.message
    return Reply(tuple(Reading.from_msg(d) for d in res.data))


def _up(client, log) -> None:
    assert client.wait(scaled(60)), log.read_text()
    try:
        wait_until(lambda: client.call("get_sensor_data", id="", timeout=scaled(30)).success, 60,
                   "a get_sensor_data reply that succeeds", interval=0.2)
    except AssertionError as exc:
        raise AssertionError(f"{exc}; log:\n{log.read_text()}") from None


def _reply_past(client, seq: int) -> Reply:
    """The first reply in which every sensor has polled past ``seq``."""

    def past():
        reply = _reply(client)
        return reply if min(r.seq for r in reply.readings) > seq else None

    return wait_until(past, 60, f"a reply with every sensor past poll {seq}", interval=0.2)


def test_a_longer_running_new_node_is_detected_as_a_restart(tmp_path):
    client = BeagleClient("mm_identity_client")
    session = MonitorSession()
    params = {"backend": "sim", "sim_trajectory": "figure_eight"}
    try:
        log = tmp_path / "first.log"
        with beagle_process(params, env=dict(os.environ), log_path=str(log)):
            _up(client, log)
            first = _reply(client)
            session.process(first)
            old = _reply_past(client, max(r.seq for r in first.readings))
            assert session.process(old)
            samples = client.call("get_samples", id=S0, since_seq=0, max_samples=10)
            assert samples.instance_id == old.readings[0].instance_id != 0
        log = tmp_path / "second.log"
        with beagle_process(params, env=dict(os.environ), log_path=str(log)):
            _up(client, log)
            # the new node has polled more than the old one ever did
            new = _reply_past(client, max(r.seq for r in old.readings) + 500)
            x_before = session.pose.x
            assert new.readings[0].instance_id not in (0, old.readings[0].instance_id)
            assert not session.process(new)  # a new baseline, not a step
            assert session.stats.restarts == 1
            assert session.pose.x == x_before
            assert any(kind == "restart" for kind, _ in session.stats.events)
    finally:
        client.close()
