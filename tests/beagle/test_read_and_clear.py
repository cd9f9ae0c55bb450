"""Per-client read-and-clear cursors (mm_beagle.poller.read_and_clear), without ROS.

A fake sensor whose totals grow by a known step per "poll"; the intervals a
client is served must add up to its totals whatever replies it loses.
"""

from __future__ import annotations

import dataclasses
import random

from mm_beagle.poller.read_and_clear import AckedReader, ClientCursors
from mm_beagle.poller.shared_state import Totals


class FakeSensors:
    def __init__(self, n: int) -> None:
        self.now = [Totals.zero() for _ in range(n)]

    def poll(self, i: int, dx: int, dy: int) -> None:
        t = self.now[i]
        self.now[i] = dataclasses.replace(
            t, seq=t.seq + 1, x_total=t.x_total + dx, y_total=t.y_total + dy
        )

    def snapshot(self, i: int) -> Totals:
        return self.now[i]


def interval(pair):
    a, b = pair
    return (b.seq, b.x_total - a.x_total, b.y_total - a.y_total)


def test_a_lost_reply_is_served_again_and_an_ack_moves_on():
    s = FakeSensors(2)
    cur = ClientCursors(2, Totals.zero())
    s.poll(0, 5, 7)
    s.poll(1, 1, 2)
    first, why = cur.serve("a", [0, 1], [], s.snapshot)
    assert why == "" and [interval(p) for p in first] == [(1, 5, 7), (1, 1, 2)]
    s.poll(0, 100, 100)
    again, why = cur.serve("a", [0, 1], [0, 0], s.snapshot)  # the reply was lost
    assert why == "" and [interval(p) for p in again] == [(1, 5, 7), (1, 1, 2)]
    nxt, why = cur.serve("a", [0, 1], [1, 1], s.snapshot)  # received, acked
    assert why == "" and [interval(p) for p in nxt] == [(2, 100, 100), (1, 0, 0)]


def test_each_client_has_its_own_cursor_and_the_old_request_is_separate():
    s = FakeSensors(1)
    cur = ClientCursors(1, Totals.zero())
    s.poll(0, 3, 4)
    (a,), _ = cur.serve("a", [0], [0], s.snapshot, one_id=True)
    (b,), _ = cur.serve("b", [0], [0], s.snapshot, one_id=True)
    assert interval(a) == interval(b) == (1, 3, 4)  # b's request took nothing from a


def test_sums_equal_the_totals_with_random_lost_replies():
    rng = random.Random(13)
    s = FakeSensors(2)
    cur = ClientCursors(2, Totals.zero())
    readers = [AckedReader(f"c{k}", ["s0", "s1"]) for k in range(3)]
    sums = [[0, 0, 0, 0] for _ in readers]
    lost = 0
    for _ in range(2000):
        s.poll(rng.randrange(2), rng.randint(-50, 50), rng.randint(-50, 50))
        k = rng.randrange(len(readers))
        r = readers[k]
        pairs, why = cur.serve(r.client, [0, 1], r.fields("")["ack_seq"], s.snapshot)
        assert why == ""
        if rng.random() < 0.2:  # DDS dropped the reply
            lost += 1
            continue
        for i, p in enumerate(pairs):
            _, dx, dy = interval(p)
            sums[k][2 * i] += dx
            sums[k][2 * i + 1] += dy
            r.acks[r.devices[i]] = p[1].seq
    # final reads, every reply arrives: the first may repeat a lost interval, the
    # second then covers the rest up to now
    for k, r in enumerate(readers):
        for _ in range(2):
            pairs, _ = cur.serve(r.client, [0, 1], r.fields("")["ack_seq"], s.snapshot)
            for i, p in enumerate(pairs):
                _, dx, dy = interval(p)
                sums[k][2 * i] += dx
                sums[k][2 * i + 1] += dy
                r.acks[r.devices[i]] = p[1].seq
    want = [s.now[0].x_total, s.now[0].y_total, s.now[1].x_total, s.now[1].y_total]
    assert lost > 100
    assert all(total == want for total in sums)


def test_bad_acks_are_refused_and_change_nothing():
    s = FakeSensors(2)
    cur = ClientCursors(2, Totals.zero())
    s.poll(0, 9, 9)
    s.poll(1, 9, 9)
    cur.serve("a", [0, 1], [], s.snapshot)
    cases = [
        ("a", [0, 1], [5, 0], False, "ahead of the newest poll"),
        ("a", [0, 1], [0], False, "needs 2"),
        ("a", [0], [0, 0], True, "needs 1"),
        ("zz", [0, 1], [1, 1], False, "unknown client 'zz'"),
        ("", [0, 1], [0, 0], False, "client token"),
        ("x\n", [0, 1], [0, 0], False, "client token"),
        ("x" * 200, [0, 1], [0, 0], False, "client token"),
    ]
    for client, wanted, acks, one, text in cases:
        pairs, why = cur.serve(client, wanted, acks, s.snapshot, one_id=one)
        assert pairs == [] and text in why, (client, acks, why)
    s.poll(0, 1, 1)
    s.poll(0, 1, 1)  # seq 3 now; the client was served up to 1 and acked 0
    _, why = cur.serve("a", [0, 1], [2, 1], s.snapshot)
    assert "not the seq of a reply" in why and "[0, 1]" in why
    assert len(cur) == 1
    again, _ = cur.serve("a", [0, 1], [0, 0], s.snapshot)  # state unchanged: same interval
    assert [interval(p) for p in again] == [(1, 9, 9), (1, 9, 9)]


def test_clients_beyond_the_limit_are_forgotten_least_recent_first():
    s = FakeSensors(1)
    cur = ClientCursors(1, Totals.zero(), max_clients=4)
    s.poll(0, 1, 1)
    for k in range(6):
        cur.serve(f"c{k}", [0], [], s.snapshot)
    assert len(cur) == 4 and cur.forgotten == 2
    _, why = cur.serve("c0", [0], [1], s.snapshot, one_id=True)
    assert "unknown client 'c0'" in why and "4 most recent" in why
    _, why = cur.serve("c5", [0], [1], s.snapshot, one_id=True)
    assert why == ""
