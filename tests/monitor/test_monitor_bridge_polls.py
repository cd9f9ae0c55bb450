"""The single polls come inside the get_sensor_data reply (one round trip a reply), and the
bridge falls back to one get_samples per sensor where a node answers without them.

The first tests replace the rclpy clients by recorders (what is asked, in which order);
the last one runs the real bridge against a real mm-beagle process both ways.
"""

from __future__ import annotations

import itertools
import os
from types import SimpleNamespace

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("mm_interfaces")

from mm_interfaces.msg import SensorData, SensorPolls
from mm_interfaces.srv import GetSamples, GetSensorData
from mm_pc.monitor.ros_bridge import RosBridge

S0, S1 = "/dev/spidev1.0", "/dev/spidev1.1"


class _Future:
    def __init__(self, result) -> None:
        self._result, self.callbacks = result, []

    def add_done_callback(self, cb) -> None:
        self.callbacks.append(cb)

    def result(self):
        return self._result

    def finish(self, result=None) -> None:
        if result is not None:
            self._result = result
        for cb in self.callbacks:
            cb(self)


class _Client:
    """Records the requests; the test answers them with ``finish``."""

    def __init__(self) -> None:
        self.sent: list[tuple[object, _Future]] = []

    def service_is_ready(self) -> bool:
        return True

    def call_async(self, request) -> _Future:
        f = _Future(None)
        self.sent.append((request, f))
        return f


def deliver_at_once(bridge: RosBridge) -> None:
    """These tests drive the executor side by hand: hand each reply on at once instead of
    through the GUI thread's delivery timer (test_monitor_bridge_delivery tests that)."""
    bridge._inbox_filled.disconnect(bridge._schedule_delivery)
    bridge._inbox_filled.connect(bridge._deliver)


def _bridge() -> tuple[RosBridge, _Client, _Client]:
    bridge = RosBridge(rate_hz=100.0)
    data, samples = _Client(), _Client()
    bridge._clients = {"get_sensor_data": data, "get_samples": samples}
    bridge._types = {"get_sensor_data": GetSensorData, "get_samples": GetSamples}
    deliver_at_once(bridge)
    return bridge, data, samples


def _data(seqs: dict[str, int], polls=None, old_node: bool = False):
    """A get_sensor_data response; ``old_node``: one without the polls field at all."""
    data = [SensorData(id=d, seq=s, cpi=1600, instance_id=7) for d, s in seqs.items()]
    if old_node:
        return SimpleNamespace(success=True, message="", data=data)
    return GetSensorData.Response(success=True, data=data, polls=polls or [])


def _polls(device: str, since: int, until: int) -> SensorPolls:
    n = until - since
    return SensorPolls(
        id=device, first_seq=since, next_seq=until, cpi=1600, stamp_ns=list(range(n)),
        dx=[1] * n, dy=[2] * n, status=[0] * n, flags=[0] * n,
    )  # fmt: skip


def test_polls_are_asked_for_in_the_data_request_and_used(qapp):
    bridge, data, samples = _bridge()
    got = []
    bridge.data_received.connect(got.extend)
    bridge._tick()
    req, fut = data.sent[-1]
    assert list(req.polls_ids) == []  # no cursor yet: nothing to ask
    fut.finish(_data({S0: 100, S1: 100}))
    assert got[-1].polls[S0].next_seq == 100 and len(got[-1].polls[S0].dx) == 0  # baseline
    bridge._tick()
    req, fut = data.sent[-1]
    assert list(req.polls_ids) == [S0, S1] and list(req.polls_since_seq) == [100, 100]
    fut.finish(_data({S0: 103, S1: 102}, [_polls(S0, 100, 103), _polls(S1, 100, 102)]))
    assert not samples.sent  # one round trip: no get_samples
    polls = got[-1].polls
    assert list(polls[S0].dx) == [1, 1, 1] and list(polls[S1].dy) == [2, 2]
    assert bridge.poll_fetches == 0 and bridge.poll_fetch_failures == 0


def test_an_older_node_without_polls_gets_one_get_samples_per_sensor(qapp):
    bridge, data, samples = _bridge()
    got = []
    bridge.data_received.connect(got.extend)
    bridge._tick()
    data.sent[-1][1].finish(_data({S0: 100, S1: 100}, old_node=True))
    bridge._tick()
    data.sent[-1][1].finish(_data({S0: 103, S1: 102}, old_node=True))
    assert len(got) == 1  # the reply waits for its polls
    asked = {r.id: (r.since_seq, r.max_samples) for r, _ in samples.sent}
    assert asked == {S0: (100, 3), S1: (100, 2)}
    for r, f in samples.sent:
        f.finish(
            GetSamples.Response(
                success=True, **_fields(_polls(r.id, 100, r.since_seq + r.max_samples))
            )
        )
    assert len(got) == 2 and len(got[-1].polls[S0].dx) == 3 and len(got[-1].polls[S1].dx) == 2
    assert bridge.poll_fetches == 2


def test_a_sensor_missing_from_the_reply_polls_is_fetched_alone(qapp):
    """A node with a busy ring answers the data without that sensor's polls: only that
    sensor is asked with get_samples; a carried entry that does not start at the cursor
    (not what was asked) is not used either."""
    bridge, data, samples = _bridge()
    got = []
    bridge.data_received.connect(got.extend)
    bridge._tick()
    data.sent[-1][1].finish(_data({S0: 100, S1: 100}))
    bridge._tick()
    data.sent[-1][1].finish(_data({S0: 103, S1: 102}, [_polls(S0, 100, 103)]))
    assert [(r.id, r.since_seq, r.max_samples) for r, _ in samples.sent] == [(S1, 100, 2)]
    samples.sent[0][1].finish(GetSamples.Response(success=True, **_fields(_polls(S1, 100, 102))))
    assert len(got) == 2 and set(got[-1].polls) == {S0, S1}
    bridge._tick()
    data.sent[-1][1].finish(_data({S0: 105, S1: 104}, [_polls(S0, 90, 105), _polls(S1, 102, 104)]))
    assert [(r.id, r.since_seq) for r, _ in samples.sent[1:]] == [(S0, 103)]


def test_cursors_a_restarted_node_refuses_are_dropped_without_a_failure(qapp):
    bridge, data, _samples = _bridge()
    got, failed = [], []
    bridge.data_received.connect(got.extend)
    bridge.data_failed.connect(failed.append)
    bridge._tick()
    data.sent[-1][1].finish(_data({S0: 5000, S1: 5000}))
    bridge._tick()
    refused = GetSensorData.Response(
        success=False,
        message="polls_since_seq 5000 for /dev/spidev1.0 is ahead of the newest poll (12); ...",
    )
    data.sent[-1][1].finish(refused)
    assert not failed and bridge.failed_replies == 0 and bridge.poll_fetch_failures == 1
    req, fut = data.sent[-1]  # asked again at once, without polls
    assert len(data.sent) == 3 and list(req.polls_ids) == []
    fut.finish(_data({S0: 14, S1: 14}))
    assert got[-1].polls[S0].next_seq == 14  # a new baseline
    bridge._tick()
    assert list(data.sent[-1][0].polls_since_seq) == [14, 14]


def test_polls_in_reply_off_asks_get_samples_as_before(qapp):
    bridge, data, samples = _bridge()
    bridge.polls_in_reply = False
    bridge._tick()
    data.sent[-1][1].finish(_data({S0: 100}))
    bridge._tick()
    assert list(data.sent[-1][0].polls_ids) == []
    data.sent[-1][1].finish(_data({S0: 101}))
    assert [(r.id, r.since_seq, r.max_samples) for r, _ in samples.sent] == [(S0, 100, 1)]


def _fields(p: SensorPolls) -> dict:
    keys = ("first_seq", "next_seq", "dropped", "cpi", "stamp_ns", "dx", "dy", "status", "flags")
    return {k: getattr(p, k) for k in keys}


@pytest.mark.ros
@pytest.mark.parametrize("in_reply", [True, False], ids=["in-reply", "get_samples"])
def test_every_poll_once_against_a_real_node(qtbot, in_reply):
    """The real bridge at 100 Hz against mm-beagle: every reply's polls chain on from the
    previous reply's seq and add up to the totals, both with the polls in the reply (no
    get_samples at all) and with get_samples (the fallback)."""
    pytest.importorskip("rclpy")
    from mm_beagle.tools.harness import beagle_process

    bridge = RosBridge("/mm_beagle", 100.0, node_name=f"mm_monitor_polls_{int(in_reply)}")
    bridge.polls_in_reply = in_reply
    got = []
    bridge.data_received.connect(got.extend)
    params = {"backend": "sim", "sim_trajectory": "figure_eight"}
    with beagle_process(params, env=dict(os.environ)):
        bridge.start()
        try:
            qtbot.waitUntil(lambda: len(got) > 150, timeout=30_000)
        finally:
            bridge.stop()
    replies = [r for r in got if r.readings]
    first = {r.id: r for r in replies[0].readings}
    sums = {d: [0, 0] for d in first}
    for prev, reply in itertools.pairwise(replies):
        before = {r.id: r for r in prev.readings}
        for r in reply.readings:
            p = reply.polls[r.id]
            assert p is not None and p.dropped == 0
            assert p.first_seq == before[r.id].seq and p.next_seq == r.seq
            assert len(p.dx) == r.seq - before[r.id].seq
            sums[r.id][0] += sum(p.dx)
            sums[r.id][1] += sum(p.dy)
    for r in replies[-1].readings:
        assert sums[r.id] == [
            r.x_total_counts - first[r.id].x_total_counts,
            r.y_total_counts - first[r.id].y_total_counts,
        ]
    assert any(v[1] for v in sums.values())  # the robot moved
    if in_reply:
        assert bridge.poll_fetches == 0
    else:
        assert bridge.poll_fetches >= len(replies) - 1
