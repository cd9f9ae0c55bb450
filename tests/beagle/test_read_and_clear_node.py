"""Read-and-clear that survives a lost reply, on a real mm-beagle process.

A "lost" reply is one the client throws away: it then asks again with the same
``ack_seq``, exactly what it would do after a timeout (docs/beagle-node.md §3.1).
"""

from __future__ import annotations

import os
import time

import pytest
from fakes import scaled, wait_until

rclpy = pytest.importorskip("rclpy")

from mm_beagle.poller.read_and_clear import AckedReader  # noqa: E402
from mm_beagle.tools.harness import beagle_process  # noqa: E402

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def devices(client, tmp_path_factory):
    log = tmp_path_factory.mktemp("node") / "mm_beagle.log"
    params = {"backend": "sim", "sim_trajectory": "figure_eight", "sim_duration": 4.0}
    with beagle_process(params, env=dict(os.environ), log_path=str(log)):
        assert client.wait(scaled(60)), f"services did not come up; log:\n{log.read_text()}"

        def both_up() -> bool:
            res = client.call("get_sensor_data", id="", timeout=scaled(30))
            return res.success and len(res.data) == 2 and not res.message

        wait_until(both_up, 60, "a reply serving both sensors", interval=0.1)
        yield client.get_parameters("devices")[0]


def key(d):
    return (d.id, d.seq, d.x_counts, d.y_counts, d.samples, d.stamp.sec, d.stamp.nanosec)


def test_a_lost_reply_is_served_again_then_the_next_interval(client, devices):
    reader = AckedReader("lossy", devices)
    first = client.call("get_sensor_data", **reader.fields(""))
    assert first.success, first.message
    assert [d.id for d in first.data] == devices
    time.sleep(0.05)  # on purpose: the node polls on, yet the lost interval is served again
    again = client.call("get_sensor_data", **reader.fields(""))  # "first" was lost
    assert [key(d) for d in again.data] == [key(d) for d in first.data]
    reader.received(again)
    # a poll of each sensor after "again" (get_samples reads and clears nothing)
    wait_until(
        lambda: all(
            len(client.call("get_samples", id=d.id, since_seq=d.seq, max_samples=1).dx) == 1
            for d in again.data
        ),
        30,
        "a poll of each sensor after the reply served again",
    )
    nxt = client.call("get_sensor_data", **reader.fields(""))
    assert nxt.success
    for a, b in zip(again.data, nxt.data, strict=True):
        assert b.seq > a.seq and b.samples == b.seq - a.seq  # starts where "again" ended
        assert b.x_total_counts - a.x_total_counts == b.x_counts


def test_one_sensor_at_a_time_and_other_clients_take_nothing(client, devices):
    reader = AckedReader("single", devices)
    s0 = devices[0]
    sums = [0, 0]
    last = None
    for k in range(40):
        if k % 4 == 1:  # an old-style client and another token read in between
            assert client.call("get_sensor_data", id="").success
            assert client.call("get_sensor_data", id="", client="other").success
        res = client.call("get_sensor_data", **reader.fields(s0))
        assert res.success, res.message
        if k % 3 == 2:
            continue  # lost
        reader.received(res)
        (d,) = res.data
        sums[0] += d.x_counts
        sums[1] += d.y_counts
        last = d
        time.sleep(0.01)  # pacing: the 40 reads spread over a few hundred polls
    assert sums == [last.x_total_counts, last.y_total_counts]  # since the node started


def test_sums_equal_the_totals_over_a_run_with_lost_replies(client, devices):
    reader = AckedReader("run", devices)
    sums = {d: [0, 0] for d in devices}
    lost = 0
    end = time.monotonic() + 5.0  # the sim stops moving after 4 s of node time
    n = 0
    while time.monotonic() < end:
        n += 1
        res = client.call("get_sensor_data", **reader.fields(""))
        assert res.success, res.message
        if n % 5 == 0:
            lost += 1
            continue
        reader.received(res)
        for d in res.data:
            sums[d.id][0] += d.x_counts
            sums[d.id][1] += d.y_counts
        time.sleep(0.005)  # pacing
    for _ in range(2):  # the first may repeat a lost interval, the second ends now
        res = client.call("get_sensor_data", **reader.fields(""))
        reader.received(res)
        for d in res.data:
            sums[d.id][0] += d.x_counts
            sums[d.id][1] += d.y_counts
    assert lost > 5
    for d in res.data:
        assert sums[d.id] == [d.x_total_counts, d.y_total_counts]
        assert d.y_total_counts != 0  # the robot did move


def test_bad_acks_are_refused_and_change_nothing(client, devices):
    reader = AckedReader("strict", devices)
    served = client.call("get_sensor_data", **reader.fields(""))
    assert served.success
    ahead = [d.seq + 10**9 for d in served.data]
    cases = [
        ({"client": "strict", "ack_seq": ahead}, "ahead of the newest poll"),
        ({"client": "strict", "ack_seq": [served.data[0].seq]}, "needs 2"),
        ({"client": "strict", "ack_seq": [1, 1]}, "not the seq of a reply"),
        ({"client": "never_seen", "ack_seq": [5, 5]}, "unknown client 'never_seen'"),
        ({"client": "", "ack_seq": [0, 0]}, "client token"),
        ({"client": "bad\ttoken", "ack_seq": []}, "client token"),
    ]
    for fields, text in cases:
        res = client.call("get_sensor_data", id="", **fields)
        assert not res.success and text in res.message, (fields, res.message)
        assert not res.data
    res = client.call("get_sensor_data", id=devices[0], client="strict", ack_seq=[0, 0])
    assert not res.success and "needs 1" in res.message
    # nothing moved: the un-acked interval is still the one served
    again = client.call("get_sensor_data", **reader.fields(""))
    assert [key(d) for d in again.data] == [key(d) for d in served.data]
    nobody = client.call("get_sensor_data", id="", client="never_seen", ack_seq=[])
    assert nobody.success  # a refused request created no state: it starts fresh now
