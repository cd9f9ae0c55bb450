"""Commands sent to the agent from the node (backend:=remote).

A command is a zenoh query on ``cmd`` (:func:`mm_beagle.poller.commands.to_link`); every
queryable is asked and the first good reply of the agent's boot taken (one that fails its
tag, does not decode or names another boot is refused and counted); the command returns
once the feeder has applied the polls up to the seq its reply names. Part of
:class:`~mm_beagle.link.remote.RemoteAgent`.
"""

from __future__ import annotations

import json
import time

from mm_beagle.link import link, link_auth, link_decode
from mm_beagle.link.remote_feed import Refused
from mm_beagle.poller import commands
from mm_beagle.poller.poller_client import PollerError

COMMAND_TIMEOUT_S = 2.0


class CommandClient:
    """RemoteAgent's command client (its session and state set up by RemoteAgent)."""

    def command(self, kind: str, i: int, *args: object, timeout: float = COMMAND_TIMEOUT_S):
        """One agent command: ("ok"|"invalid"|"error", payload), once its effect is here."""
        problem = self.unavailable()
        if problem or self.session is None:
            raise PollerError(problem or f"agent at {self.endpoint} not connected")
        msg = commands.to_link(kind, self.cfg.devices[i], *args)  # load_patch: a file name
        reply = self._query(self.keys["cmd"], json.dumps(msg).encode(), timeout)
        if reply is None:
            raise PollerError(
                f"agent at {self.endpoint} did not answer {kind!r} within {timeout:g} s"
                f" ({self.query_error})"
            )
        status, payload, seqs, _boot = reply
        self._wait_applied(seqs, deadline=time.monotonic() + 1.0)
        return status, payload

    def _query(self, key: str, payload: bytes, timeout: float) -> tuple | None:
        """The first good command reply of the agent's boot: (status, payload, seqs,
        boot_id), or None (``self.query_error`` says why). A reply that fails its tag,
        does not decode or names another boot id is refused and counted."""
        session = self.session
        if session is None:
            self.query_error = "not connected"
            return None
        t0 = time.monotonic()
        deadline = t0 + timeout
        while True:
            replies, refused, errors = 0, [], []
            try:
                # BLOCK: the reply inherits it (zenoh's default drops under load). Every
                # queryable is asked and no reply merged away: the first good one is taken
                # as it arrives, a foreign responder's are refused (it cannot answer first).
                for reply in session.get(
                    key,
                    payload=payload,
                    timeout=max(0.1, deadline - time.monotonic()),
                    congestion_control=self._block_cc,
                    target=self._target_all,
                    consolidation=self._no_consolidation,
                ):
                    replies += 1
                    if reply.ok is not None:
                        good = self._reply(reply.ok)
                        if isinstance(good, tuple):
                            return good
                        refused.append(good)
                    elif reply.err is not None:
                        errors.append(str(reply.err.payload.to_string())[:200])
            except Exception as exc:  # a session closing under us
                self.query_error = f"query failed: {exc}"
                return None
            if refused:
                self.query_error = "; ".join(refused[:3])
                return None
            elapsed = time.monotonic() - t0
            self.query_error = f"{replies} replies in {elapsed:.2f} s, errors: {errors}"
            # A query that ends at once with no reply never reached the agent (zenoh
            # 1.10 right after a reconnection, eclipse-zenoh/zenoh#2767): ask again.
            if replies or time.monotonic() > deadline - 0.1:
                return None
            time.sleep(0.05)

    def _reply(self, sample) -> tuple | str:
        """One command reply checked (tuple), or why it was refused (str, counted)."""
        try:
            data = link_decode.payload_bytes(
                sample.payload, link_decode.MAX_REPLY_BYTES, "command reply"
            )
            try:
                self.auth.check("reply", data, link_auth.attachment_bytes(sample))
            except link.LinkError as exc:
                raise Refused(str(exc)) from None
            reply = link_decode.decode_command_reply(data, self.n)
            if reply[3] != self.boot:
                raise Refused(
                    f"a command reply from boot {reply[3]}, not the agent's boot {self.boot}"
                )
            return reply
        except Refused as exc:
            self.refused += 1
            self._dropped("reply", str(exc))
            return f"refused a reply: {exc}"
        except Exception as exc:
            self._dropped("reply", f"{type(exc).__name__}: {str(exc)[:200]}")
            return f"a malformed reply: {exc}"

    def _wait_applied(self, seqs: list, deadline: float) -> None:
        """Until the feeder has applied the agent's polls up to ``seqs`` (its reply's)."""
        if not isinstance(seqs, list) or len(seqs) != self.n:
            return
        while time.monotonic() < deadline:
            if all(
                nxt is not None and isinstance(s, int) and nxt >= s
                for nxt, s in zip(self.next_agent, seqs, strict=True)
            ):
                return
            time.sleep(0.002)
