"""The single polls come inside the get_sensor_data reply (one round trip a reply), and the
bridge falls back to one get_samples per sensor where a node answers without them.

The first tests replace the rclpy clients by recorders (what is asked, in which order);
the last one runs the real bridge against a real mm-beagle process both ways.
"""

from __future__ import annotations

import itertools
import os
import time
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


def _baseline(bridge, data, got, seq: int = 100) -> None:
    bridge._tick()
    data.sent[-1][1].finish(_data({S0: seq, S1: seq}))
    assert len(got) == 1 and bridge._poll_cursor == {S0: seq, S1: seq}


def test_before_the_first_reply_only_one_request_is_out(qapp):
    """Without cursors a second request would ask for no polls (a get_samples each)."""
    bridge, data, _samples = _bridge()
    bridge._tick()
    bridge._tick()
    assert len(data.sent) == 1 and bridge.skipped_ticks == 1


def test_two_in_flight_each_poll_once_in_the_order_asked(qapp):
    """Two requests out from the same cursor; the later reply comes first and waits; its
    polls are cut at the cursor the earlier one left: every poll once, none lost, in
    order, no get_samples. A third tick while both are out is owed, asked when one is done."""
    bridge, data, samples = _bridge()
    got = []
    bridge.data_received.connect(got.extend)
    _baseline(bridge, data, got)
    bridge._tick()
    bridge._tick()  # at once: closer than half a period after the first, owed
    assert len(data.sent) == 2 and bridge.skipped_ticks == 1
    time.sleep(0.006)  # half a period at 100 Hz
    bridge._tick()
    assert len(data.sent) == 3 and bridge.overlapped_requests == 1
    (req_a, fut_a), (req_b, fut_b) = data.sent[1:]
    assert list(req_a.polls_since_seq) == list(req_b.polls_since_seq) == [100, 100]
    time.sleep(0.006)
    bridge._tick()
    assert len(data.sent) == 3 and bridge.skipped_ticks == 2  # both out: owed
    fut_b.finish(_data({S0: 105, S1: 104}, [_polls(S0, 100, 105), _polls(S1, 100, 104)]))
    assert len(got) == 1 and len(data.sent) == 3  # b waits for a
    fut_a.finish(_data({S0: 103, S1: 101}, [_polls(S0, 100, 103), _polls(S1, 100, 101)]))
    assert len(got) == 3 and not samples.sent and bridge.poll_fetches == 0
    a, b = got[1:]
    assert [r.seq for r in a.readings] == [103, 101] and [r.seq for r in b.readings] == [105, 104]
    for p, first, nxt in ((a.polls[S0], 100, 103), (b.polls[S0], 103, 105),
                          (a.polls[S1], 100, 101), (b.polls[S1], 101, 104)):  # fmt: skip
        assert (p.first_seq, p.next_seq, p.dropped) == (first, nxt, 0)
        assert list(p.stamp_ns) == list(range(first - 100, nxt - 100))  # the polls, once
        assert len(p.dx) == len(p.dy) == len(p.status) == len(p.flags) == nxt - first
    assert len(data.sent) == 4  # the owed request, now that there is room
    assert list(data.sent[-1][0].polls_since_seq) == [105, 104]


def test_a_lost_request_before_one_that_came_is_dropped_and_the_later_keeps_its_polls(qapp):
    """The earlier request never answers: the later reply waits until the watchdog gives the
    earlier one up, then is handed on with all the polls since the cursor (nothing lost)."""
    bridge, data, _samples = _bridge()
    bridge.timeout_s = 0.05
    got = []
    bridge.data_received.connect(got.extend)
    _baseline(bridge, data, got)
    bridge._tick()
    time.sleep(0.006)
    bridge._tick()
    (_, _fut_a), (_, fut_b) = data.sent[1:]
    data.remove_pending_request = lambda f: None
    fut_b.finish(_data({S0: 105, S1: 104}, [_polls(S0, 100, 105), _polls(S1, 100, 104)]))
    assert len(got) == 1
    bridge._watchdog()  # not old yet
    assert len(got) == 1 and bridge.dropped_requests == 0
    time.sleep(0.06)
    bridge._watchdog()
    assert bridge.dropped_requests == 1 and len(got) == 2
    p = got[-1].polls
    assert (p[S0].first_seq, p[S0].next_seq, len(p[S0].dx)) == (100, 105, 5)
    assert (p[S1].first_seq, p[S1].next_seq, len(p[S1].dx)) == (100, 104, 4)


def test_a_second_reply_served_in_the_same_poll_is_not_handed_on(qapp):
    """Both requests reached the node in the same poll (it was held up): the later reply
    brings the same seqs, nothing new; it is counted, not handed on. A reply with the same
    seqs a period later (a stopped poller) is handed on: the window still sees the node."""
    bridge, data, samples = _bridge()
    got = []
    bridge.data_received.connect(got.extend)
    _baseline(bridge, data, got)
    bridge._tick()
    time.sleep(0.006)
    bridge._tick()
    (_, fut_a), (_, fut_b) = data.sent[1:]
    fut_a.finish(_data({S0: 103, S1: 103}, [_polls(S0, 100, 103), _polls(S1, 100, 103)]))
    fut_b.finish(_data({S0: 103, S1: 103}, [_polls(S0, 100, 103), _polls(S1, 100, 103)]))
    assert len(got) == 2 and bridge.duplicate_replies == 1 and bridge.replies == 2
    assert not samples.sent
    time.sleep(0.011)  # a period at 100 Hz
    bridge._tick()
    time.sleep(0.006)
    bridge._tick()
    (_, fut_c), (_, fut_d) = data.sent[3:]
    fut_c.finish(_data({S0: 103, S1: 103}))
    time.sleep(0.011)
    fut_d.finish(_data({S0: 103, S1: 103}))
    assert len(got) == 4 and bridge.duplicate_replies == 1 and bridge.replies == 4
    assert [len(r.polls[S0].dx) for r in got[2:]] == [0, 0]  # nothing new, said so


def test_polls_after_cuts_at_the_cursor_and_counts_what_left_the_ring():
    from mm_pc.monitor.ros_bridge import polls_after

    p = _polls(S0, 100, 110)
    p.poll_cpi = [800] * 10
    q = polls_after(p, 104)
    assert (q.first_seq, q.next_seq, q.dropped) == (104, 110, 0)
    assert list(q.stamp_ns) == [4, 5, 6, 7, 8, 9] and list(q.poll_cpi) == [800] * 6
    assert list(q.quality) == []  # an empty per-poll array (old node) stays empty
    lost = _polls(S0, 103, 106)
    lost.dropped = 3  # asked from 100, 100..102 had left the ring
    q = polls_after(lost, 101)  # the reply before ended at 101: 101, 102 are lost
    assert (q.first_seq, q.dropped, len(q.dx)) == (103, 2, 3)


def _fields(p: SensorPolls) -> dict:
    keys = ("first_seq", "next_seq", "dropped", "cpi", "stamp_ns", "dx", "dy", "status", "flags")
    return {k: getattr(p, k) for k in keys}


@pytest.mark.ros
@pytest.mark.parametrize(
    ("in_reply", "rate"), [(True, 100.0), (False, 100.0), (True, 500.0)],
    ids=["in-reply", "get_samples", "in-reply-500hz"],
)  # fmt: skip
def test_every_poll_once_against_a_real_node(qtbot, in_reply, rate):
    """The real bridge at 100 Hz against mm-beagle: every reply's polls chain on from the
    previous reply's seq and add up to the totals, both with the polls in the reply (no
    get_samples at all) and with get_samples (the fallback); at 500 Hz with two requests
    in flight as well (no poll lost or twice, the replies in order)."""
    pytest.importorskip("rclpy")
    from mm_beagle.tools.harness import beagle_process

    bridge = RosBridge("/mm_beagle", rate, node_name=f"mm_monitor_polls_{int(in_reply)}")
    bridge.polls_in_reply = in_reply
    got = []
    bridge.data_received.connect(got.extend)
    params = {"backend": "sim", "sim_trajectory": "figure_eight"}
    with beagle_process(params, env=dict(os.environ)):
        bridge.start()
        try:
            qtbot.waitUntil(lambda: len(got) > (1500 if rate > 100 else 150), timeout=30_000)
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
    if rate > 100:
        assert bridge.overlapped_requests > 0  # two were out at once
    if in_reply:
        assert bridge.poll_fetches == 0
    else:
        assert bridge.poll_fetches >= len(replies) - 1
