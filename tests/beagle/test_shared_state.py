"""SharedState: layout, the sequence lock, the ring buffer reader, period percentiles.

The writer side used here is the poller's own :class:`mm_beagle.poller.channel.Channel`
(its ``record`` is the only writer in production), or a hand-written writer
that follows the same version protocol.
"""

from __future__ import annotations

import math
import sys
import threading
import time

import numpy as np
import pytest
from fakes import scaled, wait_until
from hypothesis import given, settings
from hypothesis import strategies as st

from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.channel import Channel
from pln2033 import INCH_M, Motion


def make_state(n: int = 2, ring: int = 64) -> ss.SharedState:
    return ss.SharedState(bytearray(ss.SharedState.size(n, ring)), n, ring)


def motion(dx: int, dy: int = 0, lifted: bool = False, overflow: bool = False) -> Motion:
    return Motion(dx, dy, 0x80 if (dx or dy) else 0, lifted, bool(dx or dy), overflow)


def channel(state: ss.SharedState, i: int = 0, cpi: int = 1600) -> Channel:
    ch = Channel(i, f"/dev/spidev1.{i}", state, state.ring_size)
    ch.set_cpi_cache(cpi, cpi)
    return ch


def write_polls(ch: Channel, count: int) -> None:
    """Poll number s carries dx = s % 1000 and stamp = s: every slot names its poll."""
    for _ in range(count):
        s = ch.seq
        ch.record(s, motion(s % 1000, 1))


# --- layout -------------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 5), ring=st.integers(1, 3000))
def test_layout_fits_the_size_it_asks_for(n, ring):
    size = ss.SharedState.size(n, ring)
    state = ss.SharedState(bytearray(size), n, ring)
    assert state.nbytes <= size
    # every array really lives in the buffer, without overlapping another
    arrays = [
        state.ints,
        state.floats,
        state.glob,
        state.hist,
        state.ring_stamp,
        state.ring_dx,
        state.ring_dy,
        state.ring_status,
        state.ring_cpi,
        state.ring_flags,
        state.ring_quality,
    ]
    for a in arrays:
        a.fill(0)
    last = [(-1,) * a.ndim for a in arrays]  # each array's last item (ints/floats: strided)
    for k, a in enumerate(arrays):
        a[last[k]] = 1
        assert sum(int(b[at]) for b, at in zip(arrays, last, strict=True)) == 1, k
        assert sum(int(np.count_nonzero(b)) for b in arrays) == 1, k
        a[last[k]] = 0


def test_ring_record_is_defined_once_and_every_derivation_agrees():
    """ring_layout.RING is the record; the shared state's arrays, the link's item sizes
    and the remote's dtypes are derived from it and agree field by field."""
    from mm_beagle.link import link, remote_feed
    from mm_beagle.poller import ring_layout

    state = ss.SharedState(bytearray(ss.SharedState.size(2, 8)), 2, 8)
    assert ss.SharedState.RING_FIELDS == ring_layout.ATTRS
    assert ring_layout.ATTRS == (
        "ring_stamp", "ring_dx", "ring_dy", "ring_status", "ring_cpi", "ring_flags",
        "ring_quality",
    )  # fmt: skip
    arrays = [getattr(state, attr) for attr in ss.SharedState.RING_FIELDS]
    wire = [np.dtype(dt) for dt in remote_feed.RING_DTYPES]
    assert [a.dtype.itemsize for a in arrays] == list(link.ARRAY_ITEM) == [w.itemsize for w in wire]
    assert [a.dtype.kind for a in arrays] == [w.kind for w in wire] == list("iiiuuui")
    assert sum(link.ARRAY_ITEM) == link.POLL_BYTES == 19
    assert all(w.byteorder in ("<", "|", "=") for w in wire)  # the frame is little-endian
    # samples() hands back the fields under ring_layout's names, in its order
    ch = channel(state, 0)
    ch.record(5, motion(3, -4))
    _first, _end, _dropped, got = state.samples(0, 0, 0)
    assert tuple(got) == ring_layout.NAMES
    assert [got[k].dtype for k in ring_layout.NAMES] == [a.dtype for a in arrays]
    assert (int(got["stamp_ns"][0]), int(got["dx"][0]), int(got["dy"][0])) == (5, 3, -4)
    # the ring's bytes are records: ring_layout.RECORD, numpy's DTYPE and the link's
    # POLL_BYTES read them alike, and a block of the link decodes into the ring's fields
    assert ring_layout.RECORD.size == np.dtype(ring_layout.DTYPE).itemsize == link.POLL_BYTES
    raw = state.ring_bytes(0)
    assert len(raw) == 8 * link.POLL_BYTES
    assert ring_layout.RECORD.unpack_from(raw, 0) == (5, 3, -4, 0x80, 1600, ss.FLAG_MOTION, -1)
    block = link.ring_block(0, raw, 0, 1, b"", b"")
    assert bytes(block.records) == bytes(raw[: link.POLL_BYTES])
    records = np.frombuffer(block.records, remote_feed.RECORD)
    for name, w, a in zip(ring_layout.NAMES, wire, arrays, strict=True):
        assert records[name].dtype == w
        assert np.array_equal(records[name], a[0][:1])
    for field_bytes, w, a in zip(block.arrays, wire, arrays, strict=True):  # the tools' view
        assert np.array_equal(np.frombuffer(field_bytes, w), a[0][:1])


def test_two_views_of_one_buffer_see_each_other():
    buf = bytearray(ss.SharedState.size(2, 16))
    a, b = ss.SharedState(buf, 2, 16), ss.SharedState(buf, 2, 16)
    ch = channel(a, 1)
    ch.record(123, motion(7, -3))
    t = b.snapshot(1)
    assert (t.seq, t.x_total, t.y_total, t.stamp_ns, t.cpi_x) == (1, 7, -3, 123, 1600)
    assert b.snapshot(0) == ss.Totals.zero()  # the other sensor's slice is untouched


def test_totals_zero():
    z = ss.Totals.zero(42)
    assert z.stamp_ns == 42
    assert z.seq == z.x_total == z.reinits == 0
    assert z.x_total_m == z.y_est_m == 0.0


# --- the sequence lock ---------------------------------------------------------------------


def test_snapshot_reads_every_field_in_order():
    state = make_state(2, 8)
    ints, floats = state.ints[1], state.floats[1]
    ints[:] = np.arange(ss.N_INT) * 2  # version 0: even
    floats[:] = np.arange(ss.N_FLOAT) + 0.5
    t = state.snapshot(1)
    assert t.seq == 2 * ss.I_SEQ and t.x_total == 2 * ss.I_X_TOTAL
    assert t.lift_lost_y == 2 * ss.I_LIFT_LOST_Y and t.reinits == 2 * ss.I_REINITS
    assert t.cpi_y == 2 * ss.I_CPI_Y and t.stamp_ns == 2 * ss.I_STAMP_NS
    assert t.x_total_m == ss.F_X_TOTAL_M + 0.5 and t.y_est_m == ss.F_Y_EST_M + 0.5
    assert t.x_est_counts == ss.F_X_EST_COUNTS + 0.5


def test_snapshot_says_busy_while_the_version_stays_odd():
    state = make_state(2, 8)
    state.ints[0, ss.I_VERSION] = 7  # a writer that stopped mid-write
    t0 = time.monotonic()
    with pytest.raises(ss.PollerBusyError, match="poller busy") as info:
        state.snapshot(0, timeout_s=0.05)
    # not an OSError: the node's main would report that as bad configuration (exit 2)
    assert not isinstance(info.value, OSError)
    with pytest.raises(ss.PollerBusyError):
        state.samples(0, 0, 0)
    assert 0.04 <= time.monotonic() - t0 < 2.0
    assert state.snapshot(1).seq == 0  # the other sensor is not affected
    state.ints[0, ss.I_VERSION] = 8
    assert state.snapshot(0, timeout_s=0.05).seq == 0


def test_snapshot_is_consistent_while_a_thread_writes():
    """Writer: version odd, x, (yield), y = 2x, metres = x/2, version even."""
    state = make_state(2, 8)
    ints, floats = state.ints[0], state.floats[0]
    stop = threading.Event()
    written = [0]

    def writer() -> None:
        x = 0
        while not stop.is_set():
            x += 1
            ints[ss.I_VERSION] += 1
            ints[ss.I_X_TOTAL] = x
            time.sleep(0)  # give the reader the torn state on purpose
            ints[ss.I_Y_TOTAL] = 2 * x
            floats[ss.F_X_TOTAL_M] = x / 2
            ints[ss.I_SEQ] = x
            ints[ss.I_VERSION] += 1
            written[0] = x
            if x % 4 == 0:
                time.sleep(50e-6)  # a poller rests between polls; so the reader gets through

    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)
    th = threading.Thread(target=writer, daemon=True)
    th.start()
    torn = 0  # unlocked reads that saw a half-written state: proof the race was on
    last_seq = 0
    n = 0

    def read_on() -> bool:
        """100 checked snapshots in a row (a pause after each would change the race); True
        after 3000 over 100 writes, one read torn (a busy machine gives the writer less
        time than the reader: it reads on)."""
        nonlocal torn, last_seq, n
        for _ in range(100):
            t = state.snapshot(0, timeout_s=2.0)
            assert t.y_total == 2 * t.x_total
            assert t.x_total_m == t.x_total / 2
            assert t.seq == t.x_total
            assert t.seq >= last_seq
            last_seq = t.seq
            raw = ints[[ss.I_X_TOTAL, ss.I_Y_TOTAL]].tolist()
            torn += raw[1] != 2 * raw[0]
            n += 1
        return n >= 3000 and written[0] > 100 and torn > 0

    try:
        wait_until(read_on, 30, "3000 reads over more than 100 writes, one of them torn",
                   interval=0)
    finally:
        stop.set()
        th.join(scaled(30))
        sys.setswitchinterval(old)
    assert n >= 200
    assert written[0] > 100
    assert torn > 0, "the writer never exposed a torn state: the test proved nothing"


# --- the ring buffer -------------------------------------------------------------------------


def seqs_of(arrays: dict[str, np.ndarray]) -> list[int]:
    return arrays["stamp_ns"].tolist()


def test_samples_fields_match_what_was_recorded():
    state = make_state(2, 32)
    ch = channel(state, 1, cpi=3200)
    ch.record(1000, motion(5, -7))
    ch.record(2000, motion(0, 0, lifted=True))
    ch.record(3000, motion(-3, 2, overflow=True))
    ch.record(4000, None)  # an SPI error
    first, nxt, dropped, a = state.samples(1, 0, 0)
    assert (first, nxt, dropped) == (0, 4, 0)
    assert a["stamp_ns"].tolist() == [1000, 2000, 3000, 4000]
    assert a["dx"].tolist() == [5, 0, -3, 0]
    assert a["dy"].tolist() == [-7, 0, 2, 0]
    assert a["cpi"].tolist() == [3200] * 4
    assert a["flags"].tolist() == [
        ss.FLAG_MOTION,
        ss.FLAG_LIFT,
        ss.FLAG_MOTION | ss.FLAG_OVERFLOW,
        ss.FLAG_SPI_ERROR,
    ]
    t = state.snapshot(1)
    assert (t.x_total, t.y_total, t.lift_total, t.overflows) == (2, -5, 1, 1)
    assert t.x_total_m == pytest.approx(2 * INCH_M / 3200)
    # sensor 0 untouched
    assert state.samples(0, 0, 0)[:3] == (0, 0, 0)


@pytest.mark.parametrize("ring", [16, 64])
def test_chaining_next_seq_returns_every_poll_exactly_once(ring):
    state = make_state(1, ring)
    ch = channel(state)
    rng = np.random.default_rng(3)
    got: list[int] = []
    since = 0
    for _ in range(400):
        write_polls(ch, int(rng.integers(0, ring // 2)))  # the reader keeps up
        first, nxt, dropped, a = state.samples(0, since, int(rng.integers(0, ring + 5)))
        assert dropped == 0
        assert first == since
        assert nxt == first + len(a["stamp_ns"])
        got += seqs_of(a)
        assert a["dx"].tolist() == [s % 1000 for s in seqs_of(a)]
        since = nxt
    # drain what is left
    while True:
        first, nxt, dropped, a = state.samples(0, since, 7)
        got += seqs_of(a)
        if nxt == since:
            break
        since = nxt
    assert got == list(range(ch.seq))


def test_dropped_counts_polls_that_left_the_ring():
    state = make_state(1, 16)
    ch = channel(state)
    write_polls(ch, 100)
    first, nxt, dropped, a = state.samples(0, 0, 0)
    assert (first, nxt, dropped) == (84, 100, 84)
    assert seqs_of(a) == list(range(84, 100))
    # a reader 50 behind with a cap: the cap applies after the drop
    first, nxt, dropped, a = state.samples(0, 50, 5)
    assert (first, nxt, dropped) == (84, 89, 34)
    assert seqs_of(a) == list(range(84, 89))
    # an up-to-date reader gets nothing and loses nothing
    assert state.samples(0, 100, 0)[:3] == (100, 100, 0)


def test_max_samples_caps():
    state = make_state(1, 64)
    ch = channel(state)
    write_polls(ch, 50)
    for cap, want in [(1, 1), (10, 10), (50, 50), (1000, 50), (0, 50), (-3, 50)]:
        first, nxt, dropped, a = state.samples(0, 0, cap)
        assert (first, nxt, dropped) == (0, want, 0), cap
        assert seqs_of(a) == list(range(want))
    # never more than the ring holds
    write_polls(ch, 200)
    first, nxt, dropped, a = state.samples(0, 0, 10_000)
    assert len(seqs_of(a)) == 64 and (first, nxt) == (186, 250)


class WriterDuringCopy(ss.SharedState):
    """The poller writes ``burst`` polls right after the reader looked at I_SEQ."""

    def __init__(self, *a, **kw) -> None:
        super().__init__(*a, **kw)
        self.ch: Channel | None = None
        self.burst = 0
        self.calls = 0

    def snapshot(self, i, timeout_s=0.05):
        t = super().snapshot(i, timeout_s)
        self.calls += 1
        if self.calls == 1 and self.ch is not None:
            write_polls(self.ch, self.burst)  # lands in slots the reader is about to copy
        return t


@pytest.mark.parametrize("burst", [1, 5, 15, 16, 40])
def test_samples_cut_the_slots_overwritten_during_the_copy(burst):
    ring = 16
    state = WriterDuringCopy(bytearray(ss.SharedState.size(1, ring)), 1, ring)
    ch = channel(state)
    write_polls(ch, 30)
    state.ch, state.burst = ch, burst
    first, nxt, dropped, a = state.samples(0, 0, 0)
    s = seqs_of(a)
    # only slots that still hold the poll they claim to hold
    assert s == list(range(first, nxt))
    assert a["dx"].tolist() == [q % 1000 for q in s]
    assert nxt == 30
    assert first == min(30, 30 - ring + burst)
    assert dropped == first


def test_since_seq_ahead_of_the_poller_returns_nothing():
    state = make_state(1, 16)
    write_polls(channel(state), 5)
    _first, nxt, dropped, a = state.samples(0, 9, 0)
    assert len(a["dx"]) == 0 and dropped == 0
    assert nxt == 5  # the reader resynchronises on the poller's count


# --- period percentiles -----------------------------------------------------------------------


def test_period_percentiles_on_a_synthetic_histogram():
    state = make_state(1, 8)
    assert all(math.isnan(v) for v in state.period_percentiles(0.5, 0.99))
    state.hist[1000] = 90
    state.hist[1500] = 9
    state.hist[5000] = 1
    assert state.period_percentiles(0.5, 0.9, 0.91, 0.99, 0.995, 1.0) == [
        1000.0,
        1000.0,
        1500.0,
        1500.0,
        5000.0,
        5000.0,
    ]
    assert state.period_percentiles(1e-9) == [1000.0]


def test_period_percentiles_last_bin_takes_the_long_tail():
    state = make_state(1, 8)
    state.hist[999] = 1
    state.hist[ss.HIST_BINS - 1] = 3
    assert state.period_percentiles(0.25, 0.5) == [999.0, float(ss.HIST_BINS - 1)]


def test_period_percentile_zero_is_the_minimum():
    state = make_state(1, 8)
    state.hist[1000] = 90
    state.hist[5000] = 10
    assert state.period_percentiles(0.0) == [1000.0]


def test_late_reply_is_not_taken_for_the_next_commands_answer():
    """A reply that arrives after its command timed out must not answer the next one."""
    from mm_beagle.poller.poller import PollerConfig
    from mm_beagle.poller.poller_client import PollerClient, PollerError

    client = PollerClient(PollerConfig(devices=["/dev/spidev1.0"], ring_size=1024))
    poller_end = client._child_ends[0]
    client.process = type("Alive", (), {"is_alive": lambda self: True})()  # no real process
    with pytest.raises(PollerError, match="did not answer 'settings'"):
        client.command("settings", 0, timeout=0.05)
    poller_end.recv()
    poller_end.send(("ok", "late settings"))  # the late answer to the first command
    poller_end.send(("ok", 800))  # the answer to the second
    assert client.command("set_cpi", 0, 800, timeout=1.0) == ("ok", 800)
    assert poller_end.recv() == ("set_cpi", 0, 800)
