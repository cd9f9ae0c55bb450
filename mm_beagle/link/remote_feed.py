"""The node's side of the link applying what the agent sends (backend:=remote).

Batches are applied in order into the node's shared state: each block's polls into the
ring, its totals published after them. What cannot be the agent's is refused
(:class:`Refused`, counted apart from undecodable input): a batch of another boot (a new
boot is followed only from its status, once the old one fell silent for
:data:`BOOT_SILENCE_S`), a seq further ahead than time allows (:data:`SEQ_RATE_MARGIN`,
:data:`SEQ_SLACK`), totals that do not add up to the node's plus the block's polls, a
status whose devices changed within its boot. A sensor whose live blocks were all refused
for :data:`RESYNC_S` follows the agent again. A restarted agent continues the node's totals
and sequence numbers; a boot announced by a status is left again, as if never followed, when
the old boot's polls go on while it sent none (:meth:`Feed._follow_back`: a forged status
in a pause of the agent's frames). Part of :class:`~mm_beagle.link.remote.RemoteAgent`.
"""

from __future__ import annotations

import time

import numpy as np

from mm_beagle.link import link, link_decode
from mm_beagle.poller import chip_config, ring_layout
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.options import OPTIONS

RING_DTYPES = ring_layout.WIRE_DTYPES  # the fields of a batch block's records, in RING order
RECORD = np.dtype(ring_layout.DTYPE)  # one poll of a batch block (the ring's own record)
XY = (ss.I_X_TOTAL, ss.I_Y_TOTAL)
# Plausibility of what the link says (docs/hardware-setup.md, "What a local process can do"):
# a sensor's seq may advance at most SEQ_RATE_MARGIN x the highest poll rate an agent
# accepts, per second since its last block that brought new polls, plus SEQ_SLACK polls.
# Anything beyond is refused, not applied.
MAX_POLL_RATE = float(OPTIONS["poll_rate"].hi or 2000.0)
SEQ_RATE_MARGIN = 1.5
# A burst of frames late from an outage (zenoh's and TCP's buffers) brings seconds of
# polls at once: 65 536 (the default ring, 65 s at 1 kHz) covers it. A forged jump within
# it is caught by the gap fetch: the agent's ring has no polls that far (refused).
SEQ_SLACK = 65_536
GLOB_HOLD_S = 1.0
# A new boot id is followed only when its status arrives after the current boot's frames
# stopped for this long (a restarted agent is silent for seconds: import, bring-up).
BOOT_SILENCE_S = 0.5
RESYNC_S = 2.0  # live blocks refused or stale this long, none taken: follow the agent again
CREDENTIALS_PROBE_S = 3.0  # TCP reaches the agent but zenoh does not open for this long


class Refused(link.LinkError):
    """A well-formed input refused: failed authentication, another boot, an implausible
    sequence number or totals that do not add up. Counted apart from undecodable ones."""


class Feed:
    """RemoteAgent's applying of statuses, events and batches (its state is set up by
    RemoteAgent; gaps are fetched by :class:`~mm_beagle.link.remote_history.HistoryFetch`,
    stamps mapped by :class:`~mm_beagle.link.remote_clock.StampClock`)."""

    _left: dict | None = None  # the boot left for an announced one, until that one sends polls
    false_boots = 0  # boots announced by a status and left again: the old one sent polls

    def _on_batch(self, batch: link.Batch, recv_ns: int) -> None:
        left = self._left
        if left is not None and batch.boot_id == left["boot"] and batch.boot_id != self.boot:
            self._follow_back(batch, left)
        if self.mismatch:
            return
        if self.boot is None or (
            batch.boot_id != self.boot and time.monotonic() - self.boot_heard >= BOOT_SILENCE_S
        ):
            self.unannounced += 1  # a (re)started agent before its status: not yet followed
            return
        if batch.boot_id != self.boot:
            raise Refused(
                f"a batch of boot {batch.boot_id:#x}, not of the agent's boot {self.boot:#x} "
                "(a new boot is followed only after its status, once the old one fell silent)"
            )
        now = time.monotonic()
        self._check_blocks(batch, now)
        self.boot_heard = now
        self.last_heard = now
        self._left = None  # the boot followed sends polls: the one before is not coming back
        if not self.link_up:
            self.link_up = self.ever_up = True
            self.since_wall = time.time()
            self._emit("log", f"link to the agent at {self.endpoint} up")
        # a frame overtaken by a newer one (the subscriber's callbacks may run on several
        # threads): its polls are skipped as already applied, its older counters too. A
        # number far ahead (forged) holds the counters back for GLOB_HOLD_S at most.
        if batch.number > self.batch_number or now - self._batch_t > GLOB_HOLD_S:
            self.batch_number, self._batch_t = batch.number, now
            self.state.glob[:] = np.frombuffer(batch.glob, np.int64)
        newest = max(
            (int(np.frombuffer(b.ints, np.int64)[ss.I_STAMP_NS]) for b in batch.blocks if b.count),
            default=0,
        )
        clock = (self._offset_ns, self._offset_t)
        if newest:  # before applying: the very first polls get an offset too
            self._clock(recv_ns, newest)
        for k, block in enumerate(batch.blocks):
            before = self.next_agent[block.index]
            try:
                self._apply(block, fetch_gaps=True)
            except Refused:
                if k == 0:  # nothing of it applied: its stamp must not move the clock either
                    self._offset_ns, self._offset_t = clock
                raise
            self._seq_reference(block, before, now)
            if not self.origin_ns and np.frombuffer(block.ints, np.int64)[ss.I_STAMP_NS] > 0:
                self.origin_ns = int(self.state.ints[block.index][ss.I_STAMP_NS])
        # a gap fetch can take seconds: frames that kept arriving meanwhile mean the link is
        # up (else the feeder would call it lost the moment the fetch returns)
        self.last_heard = max(self.last_heard, self.last_rx)
        if newest:
            self.apply_latency_ms.append((time.time_ns() - newest) / 1e6)

    def _check_blocks(self, batch: link.Batch, now: float) -> None:
        """Refuse a live batch whose sequence numbers cannot be the agent's: a seq beyond
        what the time since the sensor's last block allows, totals whose seq is not the
        block's end (counts that do not add up: :meth:`_apply`)."""
        seen = set()
        for b in batch.blocks:
            i = b.index
            if i in seen:
                raise Refused(f"batch names sensor {i} twice")
            seen.add(i)
            ints = np.frombuffer(b.ints, np.int64)
            end = b.first_seq + b.count
            if int(ints[ss.I_SEQ]) != end:
                raise Refused(
                    f"block of sensor {i}: totals at seq {int(ints[ss.I_SEQ])}, not {end}"
                )
            expected = self.next_agent[i]
            if expected is None:
                continue
            ref = self._seq_ref[i]
            if ref is not None:
                elapsed = now - ref[0]
                most = elapsed * MAX_POLL_RATE * SEQ_RATE_MARGIN + SEQ_SLACK
                if end - ref[1] > most:
                    raise Refused(
                        f"sensor {i}'s seq {end} is {end - ref[1]} polls past seq {ref[1]} "
                        f"of {elapsed:.2f} s ago (at most {most:.0f})"
                    )

    def _seq_reference(self, block: link.Block, before: int | None, now: float) -> None:
        """(now, end) becomes sensor i's seq reference when ``block`` brought new polls."""
        end = block.first_seq + block.count
        if before is None or self.next_agent[block.index] != before:
            self._seq_ref[block.index] = (now, end)

    def _follow_back(self, batch: link.Batch, left: dict) -> None:
        """A batch of the boot left for a new one announced by a status, continuing its
        polls while the new boot has sent none: the agent never restarted (the status was
        forged, or came during a pause of its frames). Back to the boot left, as it was;
        the announced boot is never followed again."""
        ahead = [
            b for b in batch.blocks
            if b.count and b.first_seq + b.count > (left["next_agent"][b.index] or 0)
        ]  # fmt: skip
        if not ahead:
            return  # a late frame of the old boot's last polls (already applied)
        announced = self.boot
        for key, value in left.items():
            setattr(self, key, value)
        self.boots_seen.discard(self.boot)
        if announced is not None:
            self.boots_seen.add(announced)
        self._left = None
        self.boot_heard = time.monotonic()
        self.false_boots += 1
        self._emit(
            "log",
            f"the agent's boot {self.boot:#x} sends polls again after boot {announced:#x} was "
            "announced without any: not a restart (a forged status?); following "
            f"{self.boot:#x} again, {announced:#x} never",
        )

    def _new_boot(self, boot_id: int, uptime_s: float = 0.0) -> None:
        if self.boot is not None:  # a restarted agent: continue from what we had
            # what to go back to if the old boot turns out alive (:meth:`_follow_back`)
            self._left = {
                "boot": self.boot,
                "boot_devices": self.boot_devices,
                "mismatch": self.mismatch,
                "restarts": self.restarts,
                "batch_number": self.batch_number,
                "next_agent": list(self.next_agent),
                "_seq_ref": list(self._seq_ref),
                "base_i": self.base_i.copy(),
                "base_f": self.base_f.copy(),
                "agent_i": self.agent_i.copy(),
                "agent_f": self.agent_f.copy(),
            }
            self.restarts += 1
            self.base_i[:, self._mono] += self.agent_i[:, self._mono]
            self.base_f += self.agent_f
            self.agent_i[:] = 0
            self.agent_f[:] = 0
            self.next_agent = [0] * self.n  # its polls since it started: fetch what we missed
            self._emit("log", "the agent restarted: totals and sequence numbers continue")
            self.boots_seen.add(self.boot)
        self.boot = boot_id
        self.boot_devices = None
        now = time.monotonic()
        self.boot_heard = now
        self.batch_number = 0
        self._batch_t = now
        # its polls since it started are to come: the seq check counts from its start
        up = min(max(uptime_s, 0.0), 1e6) if uptime_s == uptime_s else 0.0
        self._seq_ref = [(now - up, 0)] * self.n

    def _apply(self, block: link.Block, fetch_gaps: bool, totals: bool = True) -> None:
        """Write a block's new polls into the ring and, with ``totals``, publish its totals.

        A history reply (``totals=False``) carries the agent's newest totals, not those
        after its polls: published, they would serve a seq beyond the polls written (old
        ring slots) that steps back with the next batch. Its polls stay unseen until the
        live batch after the gap publishes its own totals.
        """
        i = block.index
        first, count = block.first_seq, block.count
        end = first + count
        expected = self.next_agent[i]
        check = totals  # a live block right after known polls: its counts must add up
        if expected is None:  # first contact: the node's totals and ring start after it
            if not totals:
                return
            self._zero_at(i, block)
            expected = self.next_agent[i] = end
            self.state.ints[i][ss.I_RING_FROM] = self.base_i[i][ss.I_SEQ] + end
            check = False
        elif end < expected or (end == expected and count):
            if not (totals and self._resync_due(i, block)):
                return  # already applied (a history reply overlapping the live stream)
            expected, check = self._resync(i, block, "are behind the node's"), False
        if first > expected:
            if fetch_gaps:
                self._fill_gap(i, expected, first)
                expected = self.next_agent[i]
            if first > expected:  # what the agent's ring no longer holds
                check = False
                self._pending[i] = [0, 0]
                self.polls_lost += first - expected
                self._emit(
                    "log",
                    f"{first - expected} single polls of {self.cfg.devices[i]} "
                    f"({expected}..{first}) are lost: the agent did not send them "
                    f"({self.query_error}); the totals are exact",
                )
                self.state.ints[i][ss.I_RING_FROM] = self.base_i[i][ss.I_SEQ] + first
                expected = first
        skip = expected - first
        ints = np.frombuffer(block.ints, np.int64)
        floats = np.frombuffer(block.floats, np.float64)
        records = np.frombuffer(block.records, RECORD)
        sums = [0, 0]
        if count > skip:
            sums = [int(records[k][skip:].sum()) for k in ("dx", "dy")]
        if check:
            have = [int(self.agent_i[i][k]) + p for k, p in zip(XY, self._pending[i], strict=True)]
            got = [int(ints[k]) for k in XY]
            if [h + d for h, d in zip(have, sums, strict=True)] != got:
                if not self._resync_due(i, block):
                    raise Refused(f"sensor {i}'s totals {got} are not {have} + its polls {sums}")
                expected = self._resync(i, block, "do not add up to the node's")
                skip = 0
                sums = [int(records[k].sum()) for k in ("dx", "dy")]
            self._pending[i] = [0, 0]
        elif not totals:  # a history reply: its counts are in the next live block's totals
            self._pending[i] = [p + d for p, d in zip(self._pending[i], sums, strict=True)]
        sync = self.clock_sync and self._offset_ns is not None
        st = self.state.ints[i]
        st[ss.I_VERSION] += 1  # odd: writing
        if count > skip:
            node_first = int(self.base_i[i][ss.I_SEQ]) + expected
            slots = np.arange(node_first, node_first + count - skip) % self.state.ring_size
            self.state.ring[i][slots] = records[skip:]
            if sync:
                stamps = self._rings[i][0]
                stamps[slots] += self._stamp_offsets(i, stamps[slots])
        if end >= expected and totals:
            self.agent_i[i] = ints
            self.agent_f[i] = floats
            # every field but the lock word (never the agent's version, even for a moment:
            # a reader would take a half-written snapshot) and the node's own ring start
            fields = ints.copy()
            fields[self._mono] += self.base_i[i][self._mono]
            if sync:  # the newest poll's stamp, as its ring slot has it
                off = self._stamp_off[i]
                fields[ss.I_STAMP_NS] += self._offset_ns if off is None else off
            st[1 : ss.I_RING_FROM] = fields[1 : ss.I_RING_FROM]
            st[ss.I_RING_FROM + 1 :] = fields[ss.I_RING_FROM + 1 :]
            self.state.floats[i] = floats
            self.state.floats[i][: ss.N_TOTAL_FLOAT] += self.base_f[i][: ss.N_TOTAL_FLOAT]
        if end >= expected:
            self.next_agent[i] = end
            if totals:
                self._accepted_t[i] = time.monotonic()
        st[ss.I_VERSION] += 1  # even: consistent

    def _zero_at(self, i: int, block: link.Block) -> None:
        """The node's counts start after ``block``, its first contact with sensor i: the
        agent's totals before it (its whole uptime) are not this node's, or the first
        read-and-clear interval (from the node's start) would carry them."""
        ints = np.frombuffer(block.ints, np.int64)
        floats = np.frombuffer(block.floats, np.float64)
        zero = [k for k in self._mono if k != ss.I_REINITS]
        self.base_i[i][zero] = -ints[zero]
        self.base_f[i][: ss.N_TOTAL_FLOAT] = -floats[: ss.N_TOTAL_FLOAT]

    def _resync_due(self, i: int, block: link.Block) -> bool:
        """Live blocks of sensor i have been refused or skipped as already applied for
        RESYNC_S while none was accepted: the node took a forged one before (consistent
        enough to pass) and now refuses the agent's own. Time to follow the agent again."""
        return bool(block.count) and time.monotonic() - self._accepted_t[i] >= RESYNC_S

    def _resync(self, i: int, block: link.Block, why: str) -> int:
        """Follow the agent's ``block`` again: its polls overwrite the node's from its first
        seq on and its totals replace what a forged block had put there."""
        self.resyncs += 1
        self._pending[i] = [0, 0]
        self._emit(
            "log",
            f"{self.cfg.devices[i]}: the agent's polls {why} for {RESYNC_S:g} s (a forged "
            f"frame was taken before): following the agent's own again from its seq "
            f"{block.first_seq}; the totals are the agent's",
        )
        self.next_agent[i] = block.first_seq
        return block.first_seq

    def _on_status(self, data: bytes) -> None:
        """A status, checked. Its boot id is how a new agent boot is followed: only when
        the current boot fell silent for BOOT_SILENCE_S and the id was never seen before.
        Devices and chips never change within a boot: a status that says otherwise is
        refused, so a forged one cannot make the services fail."""
        status = link_decode.decode_status(data, self.n, ss.HIST_BINS)
        boot = status["boot_id"]
        if boot != self.boot:
            if boot in self.boots_seen:
                raise Refused(f"a status of the agent's earlier boot {boot:#x}")
            if self.boot is not None:
                silent = time.monotonic() - self.boot_heard
                if silent < BOOT_SILENCE_S:
                    raise Refused(
                        f"a status of boot {boot:#x} while the agent's boot {self.boot:#x} "
                        f"was heard {silent:.2f} s ago"
                    )
            self._new_boot(boot, status["uptime_s"])
        devices = (tuple(status["devices"]), tuple(status["chips"] or ()))
        if self.boot_devices is None:
            self.boot_devices = devices
            self._check_devices(status)
        elif devices != self.boot_devices:
            raise Refused("a status whose devices or chips differ from its boot's first status")
        if self.mismatch:
            return
        first = not self.agent_status
        self.agent_status = status
        if status["hist"] is not None:
            self.state.hist[:] = np.frombuffer(status["hist"], np.int64)
        if first:
            for dev, state, err in zip(
                self.cfg.devices, status["states"], status["last_errors"], strict=True
            ):
                if state == "down":
                    self._emit("down", dev, err)

    def _check_devices(self, status: dict) -> None:
        """Set ``mismatch`` when the agent serves other devices or chips than expected."""
        self.mismatch = ""
        if status["devices"] != self.cfg.devices:
            self.mismatch = (
                f"the agent at {self.endpoint} serves {status['devices']}, this node "
                f"expects {self.cfg.devices}: set the node's 'devices' parameter to match"
            )
        else:
            chips = status["chips"]  # an agent from before issue 15 polls PLN2033s only
            expected = chip_config.resolve_chips(self.cfg.chips, self.cfg.devices)
            if (chips or ["pln2033"] * len(expected)) != expected:
                self.mismatch = (
                    f"the agent at {self.endpoint} polls chips {chips}, this node expects "
                    f"{expected}: set the node's 'chips' parameter to match the agent's --chips"
                )
        if self.mismatch:
            self._emit("log", self.mismatch)

    def _on_event(self, data: bytes) -> None:
        kind, device, text = link_decode.decode_event(data)
        if kind in ("up", "down"):
            if device not in self.cfg.devices:
                raise link.LinkError(f"an event for unknown device {device[:80]!r}")
            self._emit(kind, device, text)
        else:
            self._emit("log", f"agent: {text}")
