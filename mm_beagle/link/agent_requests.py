"""What the agent accepts from a peer: bounded request parsing, rate limits, refusals.

Any process that reaches the agent's zenoh session can send anything on the command and
history-request keys, so a request is checked here before any of it is decoded: its size
first (:data:`MAX_REQUEST_BYTES`; zenoh itself refuses messages over
:data:`RX_MAX_MESSAGE_BYTES`, see :func:`mm_beagle.link.zenoh_config.agent_zenoh_config`), then
its nesting (on the raw bytes, :func:`mm_beagle.link.link_decode.decode_json_bounded`: ``json``
never recurses), then a JSON object of the known keys, one level deep at most; the fields
themselves are checked by :mod:`mm_beagle.poller.commands`. A refused request is counted
(:class:`Refusals`, in the agent's status) and logged, one line per key at most every
:data:`LOG_EVERY_S` with how many more were refused meanwhile.

zenoh 1.10 tells a queryable or subscriber nothing about which peer sent a request (its
``source_info`` is empty unless the sender sets it, and then it is whatever the sender
says), so the rate limits are per key, for all peers together (:class:`TokenBucket`).
"""

from __future__ import annotations

import sys
import threading
import time

from mm_beagle.link import link, link_decode
from mm_beagle.poller import commands
from mm_pc.core.throttle import WarnThrottle

MAX_REQUEST_BYTES = 4096  # the largest honest request (load_patch with a long name) is ~300
MAX_TEXT = 1024  # characters of one string value
MAX_DEPTH = 2  # an object of values; a value that is an array is refused by its field check
RX_MAX_MESSAGE_BYTES = 65536  # zenoh drops anything larger before it reaches Python
LOG_EVERY_S = 1.0

#: the keys a command request may carry: its name, the sensor, every argument, and the
#: keys refused with their own message (load_patch's 'words')
COMMAND_KEYS = frozenset(
    {"cmd", "sensor"}
    | {a.name for c in commands.COMMANDS.values() for a in c.args}
    | {k for c in commands.COMMANDS.values() for k in c.forbidden}
)
HISTORY_KEYS = frozenset({"id", "sensor", "since", "max"})


def parse_request(payload: bytes, what: str, allowed: frozenset[str]) -> dict:
    """A flat JSON object of at most :data:`MAX_REQUEST_BYTES` with keys from ``allowed``
    and values checked next by :mod:`~mm_beagle.poller.commands`; LinkError says what is
    wrong. Decoded by :func:`link_decode.decode_json_bounded` (size, then nesting on the raw
    bytes: ``json`` never recurses), at most :data:`MAX_DEPTH` deep (an array in a value
    is refused by the field checks, with its own message: load_patch's 'words')."""
    msg = link_decode.decode_json_bounded(
        payload, MAX_REQUEST_BYTES, MAX_DEPTH, what=f"{what} request"
    )
    if not isinstance(msg, dict):
        raise link.LinkError(f"{what} request must be a JSON object")
    unknown = sorted(k for k in msg if k not in allowed)
    if unknown:
        raise link.LinkError(
            f"{what} request has unknown keys {unknown[:4]!r}; known: {', '.join(sorted(allowed))}"
        )
    for key, value in msg.items():
        if isinstance(value, str) and len(value) > MAX_TEXT:
            raise link.LinkError(f"{what} request field {key!r} is longer than {MAX_TEXT}")
    return msg


class TokenBucket:
    """At most ``rate`` requests per second on average, ``burst`` at once (one thread)."""

    def __init__(self, rate: float, burst: int) -> None:
        self.rate, self.burst = rate, float(burst)
        self.tokens = float(burst)
        self.t = time.monotonic()

    def allow(self) -> bool:
        now = time.monotonic()
        self.tokens = min(self.burst, self.tokens + (now - self.t) * self.rate)
        self.t = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


class Refusals:
    """Refused requests: counted per key and reason, logged at most once a second per key."""

    def __init__(self, prog: str = "mm-beagle-agent", stream=None) -> None:
        self.prog = prog
        self.stream = stream
        self.total = 0
        self.by_key: dict[str, int] = {}
        self.by_reason: dict[str, int] = {}
        self._lock = threading.Lock()
        self._gate = WarnThrottle(LOG_EVERY_S)  # per key; counts those refused quietly

    def refuse(self, key: str, reason: str, detail: str) -> None:
        """Count one refusal on ``key`` (``reason``: a short category); log ``detail``."""
        with self._lock:
            self.total += 1
            self.by_key[key] = self.by_key.get(key, 0) + 1
            self.by_reason[reason] = self.by_reason.get(reason, 0) + 1
            quiet = self._gate(key)
            if quiet is None:
                return
        more = f" ({quiet} more refused since the last line)" if quiet else ""
        detail = detail.replace("\n", " ")[:300]  # one line, whatever a peer put in it
        # one write, newline included: print writes the text and its end apart, so two
        # workers refusing at once ran their lines together ("... 38 so farmm-beagle-agent: ...")
        stream = self.stream or sys.stderr
        stream.write(f"{self.prog}: refused a {key} request: {detail}{more}; {self.total} so far\n")
        stream.flush()

    def status(self) -> dict[str, object]:
        """The counters for the agent's status message."""
        with self._lock:
            return {
                "requests_refused": self.total,
                "refused_by_key": dict(self.by_key),
                "refused_by_reason": dict(self.by_reason),
            }
