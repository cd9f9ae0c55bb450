"""The remote backend's feeder, fed batch frames directly (no zenoh, no agent process).

What it serves must hold however the frames arrive, at every moment: each sensor's
polls exactly once, in sequence order, with stamps strictly increasing, and totals that
belong to the served sequence number. Two ways it did not, both seen under load:

- the link's delay varies, so the clock offset estimate (the smallest delay seen) steps
  down now and then; it was added to the stamps at once, which put a poll's stamp up to
  several ms before its predecessor's (1 ms apart at 1 kHz);
- a history reply (a gap being fetched) carries the agent's newest totals, not those at
  the end of its polls; applied as the node's totals they served a sequence number
  beyond the polls written (old ring slots), which then stepped back with the next batch.
"""

from __future__ import annotations

import random
import threading

import numpy as np
import pytest
from fakes import wait_until

from mm_beagle.link import link
from mm_beagle.link.remote import RemoteAgent
from mm_beagle.link.remote_clock import CLOCK_SLEW
from mm_beagle.link.remote_feed import RING_DTYPES
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import PollerConfig

S0, S1 = "/dev/spidev1.0", "/dev/spidev1.1"
MS = 1_000_000


class FakeAgent:
    """Two sensors polled about every 1 ms on the agent's clock, served as the agent does."""

    def __init__(self, seed: int = 1) -> None:
        self.rng = random.Random(seed)
        self.boot = 4242
        self.number = 0
        self.stamp: list[int] = []  # one stamp per poll loop, shared by both sensors
        self.dx: list[list[int]] = [[], []]
        self.dy: list[list[int]] = [[], []]
        self.sent = 0

    def poll(self, k: int) -> None:
        t = self.stamp[-1] if self.stamp else 1_700_000_000 * 10**9
        for _ in range(k):
            t += MS + self.rng.randint(-300_000, 300_000)  # a loaded poll loop jitters
            self.stamp.append(t)
            for i in (0, 1):
                self.dx[i].append(self.rng.randint(-40, 40))
                self.dy[i].append(self.rng.randint(0, 9))

    def block(self, i: int, first: int, end: int, totals_at: int | None = None) -> link.Block:
        """Polls first..end of sensor i, with the totals after poll ``totals_at`` (end)."""
        at = end if totals_at is None else totals_at
        ints = np.zeros(ss.N_INT, np.int64)
        ints[ss.I_SEQ] = at
        ints[ss.I_X_TOTAL] = sum(self.dx[i][:at])
        ints[ss.I_Y_TOTAL] = sum(self.dy[i][:at])
        ints[ss.I_STAMP_NS] = self.stamp[at - 1] if at else 0
        ints[ss.I_STATE] = ss.STATE_UP
        k = end - first
        fields = (
            self.stamp[first:end],
            self.dx[i][first:end],
            self.dy[i][first:end],
            [0] * k,
            [1600] * k,
            [0] * k,
            [100] * k,
        )
        arrays = tuple(np.array(f, dt).tobytes() for f, dt in zip(fields, RING_DTYPES, strict=True))
        records = link.records_of(arrays)
        return link.Block(i, first, k, ints.tobytes(), np.zeros(ss.N_FLOAT).tobytes(), records)

    def glob(self, polls: int) -> bytes:
        glob = np.zeros(ss.N_GLOBAL, np.int64)
        glob[ss.G_POLLS] = polls
        return glob.tobytes()

    def batch(self, k: int, delay_ms: float) -> tuple[bytes, int]:
        """k new polls as the next batch frame, and when it arrives on the node's clock."""
        self.poll(k)
        end = len(self.stamp)
        self.number += 1
        blocks = [self.block(i, self.sent, end) for i in (0, 1)]
        self.sent = end
        frame = link.encode_batch(self.boot, self.number, self.glob(end), blocks)
        return frame, self.stamp[-1] + round(delay_ms * MS)

    def history(self, i: int, since: int, most: int) -> bytes:
        """As AgentLink.answer_history: the polls asked for, with the newest totals."""
        now = len(self.stamp)
        end = min(now, since + most)
        block = self.block(i, since, end, totals_at=now)
        return link.encode_batch(self.boot, 0, self.glob(now), [block])


def first_contact(remote: RemoteAgent, agent: FakeAgent) -> None:
    """The agent's status names its boot (the node follows no batch before one), then a
    batch of no polls: the node's counts start at the agent's seq 0 (a real node's start
    after its first contact, issue 27)."""
    remote._new_boot(agent.boot)
    blocks = [agent.block(i, 0, 0) for i in (0, 1)]
    remote._on_batch(
        link.decode_batch(link.encode_batch(agent.boot, 0, agent.glob(0), blocks), 2), 0
    )


def loaded_delays(rng: random.Random, n: int) -> list[float]:
    """Link delays (ms) of a loaded machine: late at start, then anything from 0.1 to 20 ms
    with a new smallest one now and then, and a steady tail at the smallest."""
    head = [40.0, 33.0, 12.0, 25.0, 4.0]
    middle = [rng.choice((rng.uniform(0.1, 3.0), rng.uniform(2.0, 20.0))) for _ in range(n)]
    return head + middle + [min(head + middle)] * 60


def consistent(remote: RemoteAgent, agent: FakeAgent, cursors: list[list]) -> None:
    """What a reader gets now continues its previous read (``cursors``: per sensor the next
    seq and the last stamp): no poll twice or missing, stamps strictly increasing, totals
    that belong to the served seq."""
    for i in (0, 1):
        since, last = cursors[i]
        first, end, dropped, a = remote.state.samples(i, since, 0)
        t = remote.state.snapshot(i)  # after: the feeder may have gone on meanwhile
        assert (first, dropped) == (since, 0) and end >= first, (i, since, first, end, dropped)
        assert end <= t.seq and t.seq <= len(agent.stamp), (i, end, t.seq)
        assert a["dx"].tolist() == agent.dx[i][first:end], f"sensor {i}: polls {first}..{end}"
        stamps = np.concatenate(([last], a["stamp_ns"]))
        assert (np.diff(stamps) > 0).all(), f"sensor {i}: stamps of polls {first}..{end}"
        assert (t.x_total, t.y_total) == (sum(agent.dx[i][: t.seq]), sum(agent.dy[i][: t.seq]))
        cursors[i] = [end, int(stamps[-1])]


def served(remote: RemoteAgent, agent: FakeAgent) -> None:
    """Every poll once, in order, stamps strictly increasing and close to the agent's."""
    n = len(agent.stamp)
    raw = np.array(agent.stamp, np.int64)
    for i in (0, 1):
        first, end, dropped, a = remote.state.samples(i, 0, 0)
        assert (first, end, dropped) == (0, n, 0)
        assert a["dx"].tolist() == agent.dx[i] and a["dy"].tolist() == agent.dy[i]
        stamps = a["stamp_ns"]
        steps = np.diff(stamps)
        back = np.flatnonzero(steps <= 0)
        assert not len(back), (
            f"sensor {i}: {len(back)} stamps not after their predecessor, first at seq "
            f"{back[0] + 1 if len(back) else None} ({steps[back[:3]] / 1e3} us)"
        )
        # the offset moves slewed: no interval shrinks by more than CLOCK_SLEW
        assert (steps >= np.diff(raw) * (1 - CLOCK_SLEW) - 1).all()
        # and has caught up with the estimate by the end (a steady tail of batches)
        assert stamps[-1] - raw[-1] == remote._offset_ns
        t = remote.state.snapshot(i)
        assert (t.seq, t.x_total, t.y_total) == (n, sum(agent.dx[i]), sum(agent.dy[i]))
        assert t.stamp_ns == stamps[-1]  # the totals' stamp is the newest poll's, as served
    assert remote.polls_lost == 0
    assert int(remote.state.glob[ss.G_POLLS]) == n  # the newest batch's counters


def test_a_smaller_link_delay_never_puts_a_stamp_before_its_predecessor():
    rng = random.Random(7)
    agent = FakeAgent()
    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=8192))
    first_contact(remote, agent)
    for delay in loaded_delays(rng, 200):
        frame, recv_ns = agent.batch(10, delay)
        remote._on_batch(link.decode_batch(frame, 2), recv_ns)
    served(remote, agent)


def test_without_clock_sync_the_agents_stamps_are_served_as_they_are():
    agent = FakeAgent()
    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=8192), clock_sync=False)
    first_contact(remote, agent)
    for delay in loaded_delays(random.Random(3), 50):
        frame, recv_ns = agent.batch(10, delay)
        remote._on_batch(link.decode_batch(frame, 2), recv_ns)
    for i in (0, 1):
        assert remote.state.samples(i, 0, 0)[3]["stamp_ns"].tolist() == agent.stamp
        assert remote.state.snapshot(i).stamp_ns == agent.stamp[-1]


def test_a_fetched_gap_serves_only_the_polls_written_with_totals_that_belong_to_them():
    agent = FakeAgent()
    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=8192))
    remote._history = agent.history
    remote._running = True  # (no threads: it only lets a gap be fetched)
    first_contact(remote, agent)
    frames = [agent.batch(10, 1.0) for _ in range(8)]
    agent.poll(25)  # the agent polls on while the node asks for the gap
    cursors = [[0, 0], [0, 0]]
    applied: list[int] = []
    apply = remote._apply

    def apply_and_read(block: link.Block, *args, **kwargs) -> None:
        apply(block, *args, **kwargs)
        applied.append(block.first_seq)
        consistent(remote, agent, cursors)  # a reader between any two writes

    remote._apply = apply_and_read
    for k in (0, 1, 4, 5, 7):  # frames 2, 3 and 6 lost on the link
        frame, recv_ns = frames[k]
        remote._on_batch(link.decode_batch(frame, 2), recv_ns)
    assert sorted(set(applied)) == [0, 10, 20, 40, 50, 60, 70]  # 20..40 and 60..70 fetched
    assert remote.polls_lost == 0
    assert [c[0] for c in cursors] == [80, 80]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_frames_overtaking_each_other_on_several_threads_serve_every_poll_once(seed):
    """The subscriber's callbacks may run on several threads at once: frames reach the
    feeder's queue out of order, some twice, an overtaken one last of all. A frame ahead
    of its predecessor has its gap fetched from the agent's history; the late one is
    then skipped, its older poll counter too."""
    rng = random.Random(seed)
    agent = FakeAgent(seed)
    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=8192))
    asked: list[tuple[int, int, int]] = []

    def history(i: int, since: int, most: int) -> bytes:
        asked.append((i, since, most))
        return agent.history(i, since, most)

    remote._history = history  # the agent's ring, without a link
    first_contact(remote, agent)
    items = []
    for d in loaded_delays(rng, 150):
        frame, recv_ns = agent.batch(rng.randint(1, 20), d)
        items.append(("polls", frame, recv_ns, None, len(frame)))
    first, rest = items[0], items[1:]  # first contact: the node's ring starts there
    shares = [rest[k::4] for k in range(4)]
    for share in shares:  # some frames twice
        share += rng.sample(share, 5)
    remote._running = True
    feeder = threading.Thread(target=remote._feed, name="mm_link_feed", daemon=True)
    feeder.start()
    gate = threading.Barrier(len(shares))

    def deliver(share: list) -> None:
        gate.wait()
        for item in share:
            remote._queue.put(item)

    threads = [threading.Thread(target=deliver, args=(s,)) for s in shares]
    cursors = [[0, 0], [0, 0]]
    reads = []
    read_errors: list[BaseException] = []

    def read() -> None:  # a client chaining get_samples meanwhile
        try:
            while remote._running:
                consistent(remote, agent, cursors)
                reads.append(1)
        except BaseException as exc:  # reported by the test's thread
            read_errors.append(exc)

    reader = threading.Thread(target=read, name="reader", daemon=True)
    try:
        remote._queue.put(first)
        wait_until(lambda: remote.next_agent[1] is not None, what="the first frame applied")
        reader.start()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        remote._queue.put(items[-2])  # overtaken by the newest frame, and arriving last
        n = len(agent.stamp)
        wait_until(
            lambda: remote._queue.empty() and remote.next_agent == [n, n],
            timeout=20,
            what="the feeder to apply every frame",
        )
    finally:
        remote._running = False
        feeder.join(5)
        reader.join(5)
    assert not feeder.is_alive()
    if read_errors:
        raise read_errors[0]
    assert len(reads) > 10
    assert asked, "no frame overtook another: the test delivered in order"
    served(remote, agent)
