"""The agent's request workers: command queries and history requests from peers.

One worker thread per key takes requests from its :class:`~mm_beagle.link.agent_queues.Inbox`,
refuses what is too frequent (:data:`COMMAND_RATE`, :data:`HISTORY_RATE`), too large or
malformed (:mod:`mm_beagle.link.agent_requests`), runs the rest on the poll thread as a
:class:`~mm_beagle.link.agent_queues.Job` and sends the reply itself, so a peer that stops
reading blocks at most its worker. Part of :class:`~mm_beagle.link.agent.AgentLink`.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Generator

from mm_beagle.link import link, link_decode
from mm_beagle.link.agent_queues import Inbox, Job, Lane, once
from mm_beagle.link.agent_requests import (
    COMMAND_KEYS,
    HISTORY_KEYS,
    MAX_REQUEST_BYTES,
    parse_request,
)
from mm_beagle.poller import commands

JOB_TIMEOUT_S = 10.0  # a worker gives up on a job the poll thread has not finished by then
COMMAND_RATE = (50.0, 50)  # commands per second and burst, all peers together (<= 100/s run)
HISTORY_RATE = (100.0, 50)  # history requests per second and burst, all peers together


class RequestWorkers:
    """AgentLink's worker side: its inboxes, lanes, rate limits, ``refusals``, ``auth`` and
    ``poller`` are set up by AgentLink."""

    def _worker(self, inbox: Inbox, answer: Callable[[object], None]) -> None:
        """Take requests from ``inbox`` until it is closed; never raise."""
        while (request := inbox.get()) is not None:
            try:
                answer(request)
            except Exception as exc:  # a reply that could not be sent (peer gone)
                self.refusals.refuse("reply", "reply failed", f"{exc!r}")

    def _job(self, lane: Lane, gen: Generator[None, None, object]) -> object:
        """Run ``gen`` on the poll thread and wait for its answer (exceptions returned)."""
        job = Job(gen)
        if not lane.submit(job):
            gen.close()
            raise commands.CommandRefusedError("the agent is busy with other requests; try again")
        if not job.done.wait(JOB_TIMEOUT_S):
            job.cancelled = True
            return RuntimeError(f"the poll thread did not answer within {JOB_TIMEOUT_S:g} s")
        return job.result

    def _command_query(self, query) -> None:
        """One command query: checked here, run on the poll thread, answered from here."""
        try:
            try:
                reply = self.answer_command(query.payload)
            except Exception as exc:  # a bug: still an answer, and the worker goes on
                self.refusals.refuse("command", "failed", repr(exc))
                reply = self._reply(commands.ERROR, f"agent failed: {exc!r}", [])
            query.reply(query.key_expr, reply, attachment=self.auth.tag("reply", reply))
        finally:
            query.drop()

    def answer_command(self, payload) -> bytes:
        """A command (ZBytes or bytes of JSON) -> reply JSON {"status", "payload", "seq"}."""
        try:
            if not self.command_rate.allow():
                raise _RefusedError("rate", f"more than {COMMAND_RATE[0]:g} commands/s; try again")
            msg = parse_request(_bounded_bytes(payload, "command"), "command", COMMAND_KEYS)
            cmd, i, args = commands.from_link(msg, self.poller.cfg.devices)
            if cmd.name == "info":  # the agent's own configuration: nothing on the poll thread
                seqs = [ch.seq for ch in self.poller.channels]
                return self._reply(commands.OK, self.info(), seqs)
            if cmd.name == "load_patch":
                gen = self.load_patch(i, self._patch_words(*args))
            else:
                gen = once(self.run_command, cmd.name, i, args)
            result = self._job(self.command_lane, gen)
        except (
            _RefusedError,
            link.LinkError,
            commands.CommandRefusedError,
        ) as exc:  # nothing changed
            reason = exc.reason if isinstance(exc, _RefusedError) else type(exc).__name__
            self.refusals.refuse("command", reason, str(exc))
            return self._reply(commands.INVALID, str(exc), [])
        if isinstance(result, Exception):
            self.refusals.refuse("command", "failed", repr(result))
            return self._reply(commands.ERROR, f"agent failed: {result!r}", [])
        status, body, seqs = result  # type: ignore[misc]
        return self._reply(status, body, seqs)

    def _reply(self, status: str, body: object, seqs: list) -> bytes:
        """A command reply: its status, payload, the seq after it, the boot that answers."""
        msg = {"status": status, "payload": body, "seq": seqs, "boot_id": self.boot_id}
        return json.dumps(msg).encode()

    def _patch_words(self, name: str) -> list[int]:
        """The words of patch file ``name`` in this agent's patch_dir, read on the worker
        thread: a file the chip's patch RAM cannot hold is refused unread.

        A peer names a file; it never sends a path elsewhere or the code itself."""
        from mm_beagle.poller.patches import (
            PatchPathError,
            check_patch_file_size,
            resolve_patch_file,
        )
        from pln2033.errors import PatchError
        from pln2033.pln2033 import read_patch_file

        try:
            path = resolve_patch_file(self.poller.cfg.patch_dir, name)
            check_patch_file_size(
                path, self.poller.regmap.memory_words - self.poller.regmap.patch_start
            )
            return read_patch_file(path)
        except (PatchPathError, PatchError) as exc:
            raise commands.CommandRefusedError(str(exc)) from None

    def _history_request(self, sample) -> None:
        reply = self.answer_history(sample.payload)
        if reply is not None:
            self.history_pub.put(reply, attachment=self.auth.tag("history", reply))

    def answer_history(self, payload) -> bytes | None:
        """Polls ``since`` onwards of one sensor (at most ``max``): a batch frame numbered
        by the request's ``id``, JSON saying why not, or None (rate limited: no answer)."""
        if not self.history_rate.allow():
            self.refusals.refuse(
                "history", "rate", f"more than {HISTORY_RATE[0]:g} history requests/s"
            )
            return None
        rid = None
        try:
            msg = parse_request(_bounded_bytes(payload, "history"), "history", HISTORY_KEYS)
            rid = msg.get("id")
            n = len(self.poller.channels)
            rid, i, since, most = commands.history_request(msg, n, link.MAX_HISTORY)
            result = self._job(self.history_lane, once(self.history_frame, rid, i, since, most))
            if isinstance(result, commands.CommandRefusedError):
                raise result
        except (_RefusedError, link.LinkError, commands.CommandRefusedError) as exc:
            self.refusals.refuse("history", type(exc).__name__, str(exc))
            rid = rid if isinstance(rid, int) and not isinstance(rid, bool) else None
            return json.dumps({"id": rid, "status": "invalid", "payload": str(exc)}).encode()
        if isinstance(result, Exception):
            self.refusals.refuse("history", "failed", repr(result))
            return json.dumps({"id": rid, "status": "error", "payload": repr(result)}).encode()
        return result  # type: ignore[return-value]

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


class _RefusedError(Exception):
    """A request refused before it was parsed (``reason``: rate, size)."""

    def __init__(self, reason: str, text: str) -> None:
        super().__init__(text)
        self.reason = reason


def _bounded_bytes(payload, what: str) -> bytes:
    """A request's bytes (ZBytes or bytes), its size checked before it is copied."""
    if payload is None:
        return b""
    try:
        return link_decode.payload_bytes(payload, MAX_REQUEST_BYTES, f"{what} request")
    except link.LinkError as exc:
        raise _RefusedError("size", str(exc)) from None
