"""The agent's fast poll publishes seq, totals, stamp and metres at each service, not per
poll (issue 27 item 8): nobody reads its private shared state in between, the link sends
it then. What the link sends must be exactly what per-poll publishing gave: every count in
the ring is in the totals, each poll's metres at the CPI it was counted at."""

from __future__ import annotations

import pytest

from mm_beagle.link import agent_cli
from mm_beagle.link.agent import AgentPoller, StubMotionBus, make_state
from mm_beagle.poller import ring_layout
from mm_beagle.poller import shared_state as ss
from pln2033 import INCH_M, SensorError

ARGS = ["--listen", "tcp/127.0.0.1:7447", "--realtime-priority", "0", "--backend", "sim"]


def _stub_poller() -> AgentPoller:
    """An agent's poller (no link) whose motion bursts get the benchmark's constant reply
    (3 and 5 counts a poll): the production fast poll, no emulator truth."""
    cfg = agent_cli.config_from_args(agent_cli.build_parser().parse_args(ARGS))
    poller = AgentPoller(cfg.poller, make_state(cfg.poller))
    for dev, bus in list(poller.sim_buses.items()):
        poller.sim_buses[dev] = StubMotionBus(bus, poller.regmap)
    for ch in poller.channels:
        poller.try_init(ch, 0.0)
        assert ch.ok and ch.deferred
    poller.service()  # what the bring-up recorded
    return poller


def _ring(poller: AgentPoller, i: int) -> list[tuple]:
    """Sensor ``i``'s ring records, oldest first (the ring has not wrapped here)."""
    seq = poller.state.snapshot(i).seq
    data = bytes(poller.state.ring_bytes(i)[: seq * ring_layout.POLL_BYTES])
    return list(ring_layout.RECORD.iter_unpack(data))


def test_polls_reach_the_shared_state_at_the_next_service() -> None:
    poller = _stub_poller()
    ch = poller.channels[0]
    before = poller.state.snapshot(0)
    for _ in range(7):
        ch.poll(1000)
    assert poller.state.snapshot(0) == before  # not published yet: nobody reads it now
    poller.service()
    t = poller.state.snapshot(0)
    assert (t.seq, t.x_total, t.y_total) == (before.seq + 7, before.x_total + 21,
                                             before.y_total + 35)  # fmt: skip
    newest = _ring(poller, 0)[-1]
    assert (newest[1], newest[2]) == (3, 5)
    assert t.stamp_ns == newest[0]  # the newest poll's stamp (its clock + 1000 ns)
    assert t.x_total_m == pytest.approx(before.x_total_m + 21 * INCH_M / 1600, rel=1e-12)
    assert t.y_total_m == pytest.approx(before.y_total_m + 35 * INCH_M / 1600, rel=1e-12)
    assert ch.ints[ss.I_VERSION] % 2 == 0
    assert ch.seq == t.seq
    poller.service()  # nothing new: nothing written
    assert poller.state.snapshot(0) == t


def test_commands_between_services_keep_every_count_at_its_cpi() -> None:
    """A settings read (its counts go into the totals) and a CPI change between two
    services: the totals are the ring's sums, the metres each poll's counts at its CPI."""
    poller = _stub_poller()
    ch = poller.channels[1]
    for _ in range(5):
        ch.poll(0)
    assert poller.serve_command(("settings", 1))[0] == "ok"
    for _ in range(4):
        ch.poll(0)
    assert poller.serve_command(("set_cpi", 1, 800)) == ("ok", 800)
    for _ in range(6):
        ch.poll(0)
    ch.set_cpi_cache(1200, 1200)  # as after a failed command: the CPI taken as it is, no drain
    for _ in range(2):
        ch.poll(0)
    poller.service()
    t = poller.state.snapshot(1)
    rows = _ring(poller, 1)
    assert len(rows) == t.seq
    assert sum(r[1] for r in rows) == t.x_total and sum(r[2] for r in rows) == t.y_total
    assert [r[4] for r in rows[-8:]] == [800] * 6 + [1200] * 2
    assert (t.cpi_x, t.cpi_y) == (1200, 1200)
    assert [r[1:3] for r in rows[-8:]] == [(3, 5)] * 8
    want_x = sum(r[1] * INCH_M / r[4] for r in rows)
    want_y = sum(r[2] * INCH_M / r[4] for r in rows)
    assert t.x_total_m == pytest.approx(want_x, rel=1e-12)
    assert t.y_total_m == pytest.approx(want_y, rel=1e-12)
    assert ch.ints[ss.I_VERSION] % 2 == 0


def test_a_run_ends_published_and_a_reinitialised_sensor_carries_on() -> None:
    """run() publishes at its last service; a sensor brought up again (its fast poll made
    anew) continues from the published totals."""
    poller = _stub_poller()
    poller.run(max_polls=300, paced=False)
    t = [poller.state.snapshot(i) for i in range(2)]
    for i in range(2):
        rows = _ring(poller, i)
        assert len(rows) == t[i].seq >= 300
        assert sum(r[1] for r in rows) == t[i].x_total
        assert t[i].stamp_ns == rows[-1][0]
    ch = poller.channels[0]
    ch.poll(0)
    poller.mark_down(ch, 0.0, "test")  # publishes what the old fast poll held
    assert poller.state.snapshot(0).seq == t[0].seq + 1
    poller.try_init(ch, 0.0)
    for _ in range(3):
        ch.poll(0)
    poller.service()
    after = poller.state.snapshot(0)
    rows = _ring(poller, 0)  # (the bring-up's read is dropped, not recorded)
    assert after.seq == len(rows) == t[0].seq + 4
    assert (after.x_total, after.y_total) == (t[0].x_total + 12, t[0].y_total + 20)
    assert after.x_total == sum(r[1] for r in rows) and after.stamp_ns == rows[-1][0]


class _FlakyStub(StubMotionBus):
    """The benchmark's stub bus whose motion bursts number ``fail`` raise (no reply)."""

    def __init__(self, bus, regmap, fail: set[int]) -> None:
        super().__init__(bus, regmap)
        self.fail, self.bursts = fail, 0

    def xfer2(self, data: list[int]) -> list[int]:
        if data is self.burst:
            self.bursts += 1
            if self.bursts in self.fail:
                raise SensorError("test: no reply")
        return super().xfer2(data)


def test_the_run_loops_common_case_leaves_and_comes_back_after_failed_polls() -> None:
    """Two failed polls in a row on sensor 0 during run(): the loop leaves its tuple of
    polls for the general case (Poller.poll: the CPI read back, the retry) for exactly the
    two ticks after them, then takes it again; every poll is in the ring and the totals."""
    cfg = agent_cli.config_from_args(agent_cli.build_parser().parse_args(ARGS))
    poller = AgentPoller(cfg.poller, make_state(cfg.poller))
    dev0, dev1 = cfg.poller.devices
    poller.sim_buses[dev0] = _FlakyStub(poller.sim_buses[dev0], poller.regmap, {100, 101})
    poller.sim_buses[dev1] = StubMotionBus(poller.sim_buses[dev1], poller.regmap)
    general = []
    poll = poller.poll

    def counted(ch, stamp_ns, now):
        general.append(ch.i)
        poll(ch, stamp_ns, now)

    poller.poll = counted  # type: ignore[method-assign]
    poller.run(max_polls=400, paced=False)
    assert general == [0, 0]  # the two ticks after each failure, sensor 0 only
    assert poller._fast_polls()  # every sensor up again: the common case
    t0, t1 = poller.state.snapshot(0), poller.state.snapshot(1)
    assert (t0.seq, t0.spi_errors, t0.state) == (400, 2, ss.STATE_UP)
    assert (t0.x_total, t0.y_total) == (3 * 398, 5 * 398)
    assert (t1.seq, t1.spi_errors, t1.x_total) == (400, 0, 3 * 400)
    flags = [r[5] for r in _ring(poller, 0)]
    errors = [k for k, f in enumerate(flags) if f & ss.FLAG_SPI_ERROR]
    assert errors == [98, 99]  # bursts 100 and 101: the first was the bring-up's read
