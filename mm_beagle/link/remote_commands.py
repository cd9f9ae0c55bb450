"""Commands sent to the agent from the node (backend:=remote).

A command is a zenoh query on ``cmd`` (:func:`mm_beagle.poller.commands.to_link`); every
queryable is asked and every reply waited for (until the query ends or its timeout). A
reply that fails its tag, does not decode, names another boot or a seq behind the polls
the node had applied when it asked (a recorded reply replayed: the agent's seq after a
command is never behind what it published before) is refused and counted; good replies
that disagree are none believed (a responder on the path answering before the agent: it
knows the boot id without credentials). The command returns once the feeder has applied
the polls up to the seq its reply names. Part of :class:`~mm_beagle.link.remote.RemoteAgent`.
"""

from __future__ import annotations

import json
import time

from mm_beagle.link import link, link_auth, link_decode
from mm_beagle.link.remote_feed import Refused
from mm_beagle.poller import commands
from mm_beagle.poller.poller_client import PollerError

COMMAND_TIMEOUT_S = 2.0
CONFLICT = "conflicting replies:"


class CommandClient:
    """RemoteAgent's command client (its session and state set up by RemoteAgent)."""

    def command(self, kind: str, i: int, *args: object, timeout: float = COMMAND_TIMEOUT_S):
        """One agent command: ("ok"|"invalid"|"error", payload), once its effect is here."""
        problem = self.unavailable()
        if problem or self.session is None:
            raise PollerError(problem or f"agent at {self.endpoint} not connected")
        msg = commands.to_link(kind, self.cfg.devices[i], *args)  # load_patch: a file name
        reply = self._query(self.keys["cmd"], json.dumps(msg).encode(), timeout)
        if reply is None and self.query_error.startswith(CONFLICT):
            raise PollerError(f"agent at {self.endpoint}: {self.query_error}")
        if reply is None:
            raise PollerError(
                f"agent at {self.endpoint} did not answer {kind!r} within {timeout:g} s"
                f" ({self.query_error})"
            )
        status, payload, seqs, _boot = reply
        self._wait_applied(seqs, deadline=time.monotonic() + 1.0)
        return status, payload

    def _query(self, key: str, payload: bytes, timeout: float) -> tuple | None:
        """The good command reply of the agent's boot: (status, payload, seqs, boot_id), or
        None (``self.query_error`` says why). A reply that fails its tag, does not decode,
        names another boot id or a seq behind what was applied is refused and counted;
        good replies that disagree are none taken."""
        session = self.session
        if session is None:
            self.query_error = "not connected"
            return None
        floor = list(self.next_agent)  # the agent's seqs after the command are not behind
        t0 = time.monotonic()
        deadline = t0 + timeout
        while True:
            replies, refused, errors, good = 0, [], [], []
            try:
                # BLOCK: the reply inherits it (zenoh's default drops under load). Every
                # queryable is asked, no reply merged away and all are waited for: a
                # foreign responder's that passes every check (without credentials it
                # knows the boot id) then contradicts the agent's instead of being taken
                # for it because it came first.
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
                        checked = self._reply(reply.ok, floor)
                        if isinstance(checked, tuple):
                            good.append(checked)
                        else:
                            refused.append(checked)
                    elif reply.err is not None:
                        errors.append(str(reply.err.payload.to_string())[:200])
            except Exception as exc:  # a session closing under us
                self.query_error = f"query failed: {exc}"
                return None
            if good:
                return self._agreed(good)
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

    def _agreed(self, good: list[tuple]) -> tuple | None:
        """The one reply ``good`` replies agree on (status and payload), or None."""
        answers = {json.dumps(r[:2], sort_keys=True, default=repr) for r in good}
        if len(answers) == 1:
            return max(good, key=lambda r: sum(r[2]))  # the newest seqs of equal replies
        self.refused += len(good)
        self.query_error = (
            f"{CONFLICT} {len(answers)} different replies to one command (a foreign responder on "
            "the link; set agent_credentials): none believed, the agent may have applied it"
        )
        self._dropped("reply", self.query_error)
        return None

    def _reply(self, sample, floor: list | None = None) -> tuple | str:
        """One command reply checked (tuple), or why it was refused (str, counted).
        ``floor``: per sensor the next seq the node expected when it asked (None: unknown)."""
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
            behind = [
                (s, f) for s, f in zip(reply[2], floor or [], strict=False)
                if f is not None and s < f
            ]  # fmt: skip
            if behind:
                raise Refused(
                    f"a command reply at seq {behind[0][0]}, behind seq {behind[0][1]} the node "
                    "had when it asked (a recorded reply replayed)"
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
