"""The remote node's per-batch records stay bounded over a long run (mm-bench soak).

A node on the remote backend applies about 100 batches a second; every container it
appends to per batch must have a bound, or its RSS grows for as long as it runs (the
soak of issue 27: +0.24 MB/min, 100 000 kept apply latencies).
"""

from __future__ import annotations

import collections

from test_remote_feed import S0, S1, FakeAgent, first_contact

from mm_beagle.link import link
from mm_beagle.link.remote import LATENCIES_KEPT, RemoteAgent
from mm_beagle.poller.poller import PollerConfig


def test_latencies_kept_per_batch_are_bounded():
    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=4096))
    agent = FakeAgent()
    first_contact(remote, agent)
    batches = LATENCIES_KEPT + 2000  # well past the bound: 100 s of batches at 100/s
    for _ in range(batches):
        frame, recv_ns = agent.batch(1, 0.5)
        remote._on_batch(link.decode_batch(frame, 2), recv_ns)
    assert remote.polls_lost == 0 and remote.bad_frames == 0
    assert remote.state.snapshot(0).seq == batches  # every batch applied
    assert len(remote.apply_latency_ms) == LATENCIES_KEPT
    assert len(remote.latency_ms) <= LATENCIES_KEPT
    assert LATENCIES_KEPT <= 10_000  # a bound that is small: 10 000 floats ~ 0.3 MB


def test_every_deque_the_node_appends_to_has_a_bound():
    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=4096))
    unbounded = [
        k
        for k, v in vars(remote).items()
        if isinstance(v, collections.deque) and (v.maxlen is None or v.maxlen > 10_000)
    ]
    assert unbounded == []
