"""mm-beagle-agent: the 1 kHz poller on the board, served over zenoh, without ROS.

A BeagleBone Black cannot run ROS 2 Jazzy, so the board runs only this: the
same :class:`~mm_beagle.poller.poller.Poller` the node spawns locally (same driver,
same conservation rules), writing into a private shared-state buffer, and
every 10 ms (between polls, on the poll thread: no locks, no second thread)
it publishes the new polls with the totals after them and answers queued
queries. ``mm-beagle --ros-args -p backend:=remote`` on any ROS machine turns
that back into the ROS services (:mod:`mm_beagle.link.remote`). Keys and frames:
:mod:`mm_beagle.link.link`. Needs only Debian's python3-spidev and python3-yaml and
the eclipse-zenoh wheel; ``--backend sim`` also needs python3-numpy. The command line
and configuration: :mod:`mm_beagle.link.agent_cli`.
"""

from __future__ import annotations

import base64
import json
import os
import random
import sys
import time
import zlib

from mm_beagle.link import link
from mm_beagle.poller import commands
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import Poller, PollerConfig

HEARTBEAT_S = 0.1  # an empty batch at least this often: the node's link watchdog
STATUS_S = 1.0


class AgentLink:
    """The agent's zenoh side: publishers, and a queryable and a subscriber read with
    ``try_recv`` on the poll thread (no callbacks, no second thread)."""

    def __init__(self, session, name: str, poller: AgentPoller) -> None:
        import zenoh

        self.keys = link.keys(name)
        self.session = session
        self.poller = poller
        self.boot_id = random.getrandbits(63) | 1
        self.number = 0
        self.pub = session.declare_publisher(self.keys["polls"])
        self.status_pub = session.declare_publisher(self.keys["status"])
        self.events_pub = session.declare_publisher(self.keys["events"])
        fifo = zenoh.handlers.FifoChannel
        self.cmd_q = session.declare_queryable(self.keys["cmd"], handler=fifo(64))
        self.history_sub = session.declare_subscriber(self.keys["history_req"], handler=fifo(64))
        self.history_pub = session.declare_publisher(
            self.keys["history"], congestion_control=zenoh.CongestionControl.BLOCK
        )
        n = len(poller.channels)
        self.sent = [0] * n  # next seq to publish, per sensor
        self.ring_bytes = [
            [poller.state.ring_bytes(f, i) for f in ss.SharedState.RING_FIELDS] for i in range(n)
        ]
        self.last_pub = 0.0
        self.next_status = 0.0
        self.t0 = time.monotonic()
        self.cpu_last = (os.times(), time.monotonic())
        self.cpu_percent = float("nan")
        self.bytes_sent = 0

    # --- between polls ---

    def service(self) -> None:
        now = time.monotonic()
        blocks = [self._block(ch, self.sent[ch.i], ch.seq) for ch in self.poller.channels]
        if any(b.count for b in blocks) or now - self.last_pub >= HEARTBEAT_S:
            self.publish_batch(blocks)
            for ch in self.poller.channels:
                self.sent[ch.i] = ch.seq
            self.last_pub = now
        self._answer(self.cmd_q, self.answer_command)
        while (sample := self.history_sub.try_recv()) is not None:
            self.history_pub.put(self.answer_history(sample.payload.to_bytes()))
        if now >= self.next_status:
            self.next_status = now + STATUS_S
            self.publish_status(now)

    def _block(self, ch, first: int, end: int) -> link.Block:
        n = ch.n
        first = max(first, end - n, 0)
        count = end - first
        arrays = []
        a = first % n
        for mv, item in zip(self.ring_bytes[ch.i], link.ARRAY_ITEM, strict=True):
            if a + count <= n:
                arrays.append(mv[a * item : (a + count) * item])
            else:
                arrays.append([mv[a * item :], mv[: (a + count - n) * item]])
        return link.Block(ch.i, first, count, ch.ints.tobytes(), ch.floats.tobytes(), arrays)

    def publish_batch(self, blocks: list[link.Block]) -> None:
        self.number += 1
        frame = link.encode_batch(
            self.boot_id, self.number, self.poller.state.glob_view.tobytes(), blocks
        )
        self.bytes_sent += len(frame)
        self.pub.put(frame)

    def _answer(self, queryable, answer) -> None:
        while True:
            query = queryable.try_recv()
            if query is None:
                return
            payload = query.payload.to_bytes() if query.payload is not None else b""
            try:
                reply = answer(payload)
            except (link.LinkError, commands.CommandRefusedError) as exc:  # nothing changed
                reply = json.dumps({"status": "invalid", "payload": str(exc)}).encode()
            except Exception as exc:  # never let one request stop the polls
                reply = json.dumps({"status": "error", "payload": f"agent failed: {exc!r}"})
                reply = reply.encode()
            query.reply(query.key_expr, reply)
            query.drop()

    def answer_command(self, payload: bytes) -> bytes:
        """One command (JSON) -> {"status", "payload", "seq"}: checked against the command
        table (:mod:`~mm_beagle.poller.commands`), then the poller's own answer."""
        msg = link.parse_request(payload, "command")
        poller = self.poller
        cmd, i, args = commands.from_link(msg, poller.cfg.devices)
        if cmd.name == "info":  # the agent's own configuration
            status, body = commands.OK, self.info()
        else:
            if cmd.name == "load_patch":
                args = (self._patch_words(*args),)
            status, body = poller.serve_command((cmd.name, i, *args))
        seqs = [ch.seq for ch in poller.channels]
        return json.dumps({"status": status, "payload": body, "seq": seqs}).encode()

    def _patch_words(self, name: str) -> list[int]:
        """The words of patch file ``name`` in this agent's patch_dir.

        A peer names a file; it never sends a path elsewhere or the code itself."""
        from mm_beagle.poller.patches import PatchPathError, resolve_patch_file
        from pln2033.errors import PatchError
        from pln2033.pln2033 import read_patch_file

        try:
            return read_patch_file(resolve_patch_file(self.poller.cfg.patch_dir, name))
        except (PatchPathError, PatchError) as exc:
            raise commands.CommandRefusedError(str(exc)) from None

    def answer_history(self, payload: bytes) -> bytes:
        """Polls ``since`` onwards of one sensor (at most ``max``): a batch frame numbered
        by the request's ``id``, or JSON saying why not."""
        rid = None
        try:
            msg = link.parse_request(payload, "history")
            rid = msg.get("id")
            n = len(self.poller.channels)
            rid, i, since, most = commands.history_request(msg, n, link.MAX_HISTORY)
            ch = self.poller.channels[i]
            if since > ch.seq:
                raise commands.CommandRefusedError(commands.history_ahead(since, ch.seq))
        except (link.LinkError, commands.CommandRefusedError) as exc:
            rid = rid if isinstance(rid, int) and not isinstance(rid, bool) else None
            return json.dumps({"id": rid, "status": "invalid", "payload": str(exc)}).encode()
        end = min(ch.seq, since + min(most, link.MAX_HISTORY))
        block = self._block(ch, since, end)
        return link.encode_batch(self.boot_id, rid, self.poller.state.glob_view.tobytes(), [block])

    def info(self) -> dict:
        cfg = self.poller.cfg
        return {
            "devices": cfg.devices,
            "backend": cfg.backend,
            "boot_id": self.boot_id,
            "ring_size": cfg.ring_size,
            "poll_rate": cfg.poll_rate,
            "cpi": cfg.cpi,
            "cpi_range": [self.poller.regmap.cpi_min, self.poller.regmap.cpi_max],
            "cpi_step": self.poller.regmap.cpi_step,
            "chips": self.poller.chips,
            "chip_cpi": [
                [ch.info.cpi.min, ch.info.cpi.max, ch.info.cpi.step] for ch in self.poller.channels
            ],
        }

    # --- status and events ---

    def publish_status(self, now: float) -> None:
        times, wall = os.times(), time.monotonic()
        last, last_wall = self.cpu_last
        if wall > last_wall:
            busy = (times.user + times.system) - (last.user + last.system)
            self.cpu_percent = 100.0 * busy / (wall - last_wall)
        self.cpu_last = (times, wall)
        hist_z = zlib.compress(self.poller.state.hist_view.tobytes(), 1)
        chans = self.poller.channels
        status = {
            "boot_id": self.boot_id,
            "uptime_s": round(now - self.t0, 3),
            "devices": self.poller.cfg.devices,
            "chips": self.poller.chips,
            "states": [ss.STATE_NAMES.get(ch.ints[ss.I_STATE], "?") for ch in chans],
            "last_errors": [ch.last_error for ch in chans],
            "cpu_percent": round(self.cpu_percent, 2),
            "rss_mb": round(rss_mb(), 2),
            "bytes_sent": self.bytes_sent,
            "hist_z": base64.b64encode(hist_z).decode(),
        }
        self.status_pub.put(json.dumps(status).encode())

    def event(self, kind: str, args: tuple) -> None:
        device = str(args[0]) if kind in ("up", "down") else ""
        text = str(args[-1]) if args else ""
        self.events_pub.put(json.dumps({"kind": kind, "device": device, "text": text}).encode())

    def close(self) -> None:
        for entity in (
            self.cmd_q,
            self.history_sub,
            self.history_pub,
            self.pub,
            self.status_pub,
            self.events_pub,
        ):
            entity.undeclare()


class AgentPoller(Poller):
    """The poller with its link served every 10 ms instead of a pipe to a node."""

    service_period = 0.01

    def __init__(self, cfg: PollerConfig, state: ss.SharedState) -> None:
        # no pipes: their only users, emit and service, are overridden below
        super().__init__(cfg, state, None, None)  # type: ignore[arg-type]
        self.link: AgentLink | None = None

    def emit(self, kind: str, *args: object) -> None:
        text = " ".join(str(a) for a in args)
        print(f"mm-beagle-agent: {kind}: {text}", file=sys.stderr, flush=True)
        if self.link is not None:
            self.link.event(kind, args)

    def service(self) -> None:
        if self.link is not None:
            self.link.service()


class StubMotionBus:
    """Benchmarks: an emulated sensor whose motion bursts get a constant reply.

    Bring-up and commands reach the emulator; the 1 kHz motion burst costs
    nothing but the Python around it (3 and 5 counts of motion, every poll).
    """

    def __init__(self, emulator, regmap) -> None:
        a = regmap.addresses
        self.emulator = emulator
        self.status_addr, self.dx_addr = a["status"], a["delta_x_disp"]
        m = regmap.status_motion
        self.reply = [0, m >> 8, m & 0xFF, 0, 0, 3, 0, 0, 5]
        self.burst: list[int] | None = None

    def xfer2(self, data: list[int]) -> list[int]:
        if data is self.burst:  # the driver's own motion-burst list, once it is known
            return self.reply[:]  # a new list each time, as spidev returns
        if len(data) == 9 and data[0] == self.status_addr and data[3] == self.dx_addr:
            self.burst = data
            return self.reply[:]
        return self.emulator.xfer2(data)

    def close(self) -> None:
        self.emulator.close()


def rss_mb() -> float:
    """Resident memory of this process (MB): /proc, or the peak where /proc is absent."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):
        import resource  # a chroot without /proc (the armhf check): the peak instead

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def make_state(cfg: PollerConfig) -> ss.SharedState:
    """A private shared-state buffer for the agent's poller (nobody else maps it)."""
    n = len(cfg.devices)
    return ss.SharedState(bytearray(ss.SharedState.size(n, cfg.ring_size)), n, cfg.ring_size)
