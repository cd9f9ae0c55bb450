"""Bounded decoding of everything a peer sends on the board link (issue 27).

Every payload is size-checked before it is decoded, its JSON decoded only when it nests
at most ``max_depth`` deep (checked on the raw bytes in one linear pass: ``json`` never
recurses), zlib inflated with an output limit, base64 strictly, and each message checked
field by field (:func:`decode_status`, :func:`decode_event`, :func:`decode_command_reply`,
:func:`decode_history_answer`); anything else is a one-line :class:`LinkError`.
:class:`DropLog` counts what the node drops per kind and rate-limits its log line.
The frames themselves: :func:`mm_beagle.link.link.decode_batch`. No numpy (the agent).
"""

from __future__ import annotations

import base64
import binascii
import json
import re
import zlib

from mm_beagle.link.link import LinkError
from mm_pc.core.throttle import WarnThrottle

MAX_STATUS_BYTES = 256 * 1024  # a status (~1-3 kB: hist_z holds a compressed 160 kB array)
MAX_EVENT_BYTES = 16 * 1024
MAX_REPLY_BYTES = 256 * 1024  # a command reply (settings: a few kB)
MAX_TEXT = 4096  # characters of one text field (an error, an event's text)
MAX_DEPTH = 8  # nesting of JSON arrays/objects (ours use at most 3)
_TOKENS = re.compile(rb'["\\\[\]{}]')  # the characters that matter to nesting


def payload_bytes(payload, max_bytes: int, what: str = "message") -> bytes:
    """A payload (zenoh ZBytes, bytes) as bytes, its size checked before it is copied:
    LinkError if it is longer than ``max_bytes``."""
    if len(payload) > max_bytes:
        raise LinkError(f"{what} of {len(payload)} bytes is too large (limit {max_bytes})")
    if isinstance(payload, (bytes, bytearray, memoryview)):
        return bytes(payload)
    return payload.to_bytes()


def json_depth_ok(data: bytes, max_depth: int) -> bool:
    """Whether the arrays/objects in JSON ``data`` nest at most ``max_depth`` deep.

    One pass over the quotes, backslashes and brackets only (found in C), so its time
    is linear whatever the input (a regex over strings was quadratic on '"\\' x 50 000:
    38 s); a bracket in a string is no nesting; it stops at the first bracket too deep."""
    depth = 0
    in_string = False
    skip = -1  # the character after a backslash in a string
    for m in _TOKENS.finditer(data):
        pos = m.start()
        if pos == skip:
            continue
        c = data[pos]
        if in_string:
            if c == 0x5C:  # backslash
                skip = pos + 1
            elif c == 0x22:  # quote
                in_string = False
        elif c == 0x22:
            in_string = True
        elif c in (0x5B, 0x7B):  # [ {
            depth += 1
            if depth > max_depth:
                return False
        elif c in (0x5D, 0x7D):
            depth -= 1
    return True


def decode_json_bounded(
    payload: bytes, max_bytes: int, max_depth: int = MAX_DEPTH, what: str = "message"
) -> object:
    """JSON ``payload`` decoded only if it is at most ``max_bytes`` long, nests at most
    ``max_depth`` deep and is UTF-8; LinkError (one line) otherwise. No NaN/Infinity."""
    data = payload_bytes(payload, max_bytes, what)
    if not json_depth_ok(data, max_depth):
        raise LinkError(f"{what} nests deeper than {max_depth} levels")
    try:
        return json.loads(data.decode("utf-8"), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise LinkError(f"{what} is not JSON") from None


def decode_object(payload: bytes, max_bytes: int, max_depth: int, what: str) -> dict:
    """A JSON object decoded bounded (:func:`decode_json_bounded`), or LinkError."""
    msg = decode_json_bounded(payload, max_bytes, max_depth, what)
    if not isinstance(msg, dict):
        raise LinkError(f"{what} is not a JSON object")
    return msg


def _no_constant(name: str) -> object:
    raise ValueError(f"{name} is not a number")


def decompress_bounded(data: bytes, max_out: int, what: str = "compressed field") -> bytes:
    """zlib ``data`` inflated to at most ``max_out`` bytes; LinkError for anything else
    (not zlib, longer output: a bomb stops at ``max_out``, trailing bytes)."""
    d = zlib.decompressobj()
    try:
        out = d.decompress(data, max_out)
    except zlib.error:
        raise LinkError(f"{what} is not zlib data") from None
    if d.unconsumed_tail or not d.eof:
        raise LinkError(f"{what} inflates beyond {max_out} bytes or is cut short")
    if d.unused_data:
        raise LinkError(f"{what} has bytes after its zlib stream")
    return out


def b64_bounded(text: object, max_chars: int, what: str) -> bytes:
    """Strict base64 of at most ``max_chars`` characters, or LinkError."""
    if not isinstance(text, str) or len(text) > max_chars:
        raise LinkError(f"{what} is not a base64 string of at most {max_chars} characters")
    try:
        return base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError):
        raise LinkError(f"{what} is not base64") from None


def field(msg: dict, key: str, kind: type | tuple, what: str, *, optional: bool = False):
    """``msg[key]`` if it is of ``kind`` (bool is no int), else LinkError."""
    if key not in msg:
        if optional:
            return None
        raise LinkError(f"{what} has no '{key}'")
    value = msg[key]
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if isinstance(value, bool) and bool not in kinds:
        raise LinkError(f"{what} field '{key}' is not {_kind_names(kinds)}")
    if not isinstance(value, kinds):
        raise LinkError(f"{what} field '{key}' is not {_kind_names(kinds)}")
    if isinstance(value, str) and len(value) > MAX_TEXT:
        raise LinkError(f"{what} field '{key}' is longer than {MAX_TEXT} characters")
    return value


def _kind_names(kinds: tuple) -> str:
    return " or ".join(k.__name__ for k in kinds)


def text_list(msg: dict, key: str, n: int, what: str) -> list[str]:
    """``msg[key]``: a list of ``n`` strings, or LinkError."""
    value = field(msg, key, list, what)
    if len(value) != n or not all(isinstance(v, str) and len(v) <= MAX_TEXT for v in value):
        raise LinkError(f"{what} field '{key}' is not a list of {n} texts")
    return value


def decode_status(payload: bytes, n_sensors: int, hist_bins: int) -> dict:
    """An agent status checked field by field: {"boot_id": int, "uptime_s": float,
    "devices", "chips", "states", "last_errors": lists of texts, "cpu_percent",
    "rss_mb": float, "hist": bytes (``hist_bins`` int64, inflated) or None, ...}."""
    what = "status"
    msg = decode_object(payload, MAX_STATUS_BYTES, MAX_DEPTH, what)
    boot = field(msg, "boot_id", int, what)
    if not 0 < boot < 1 << 64:
        raise LinkError("status boot_id is out of range")
    devices = field(msg, "devices", list, what)
    if len(devices) > 64 or not all(isinstance(d, str) and len(d) <= MAX_TEXT for d in devices):
        raise LinkError("status devices are not a list of names")
    out = {"boot_id": boot, "devices": devices}
    chips = field(msg, "chips", list, what, optional=True)
    out["chips"] = None if chips is None else text_list(msg, "chips", len(devices), what)
    out["states"] = text_list(msg, "states", len(devices), what)
    out["last_errors"] = text_list(msg, "last_errors", len(devices), what)
    for key in ("uptime_s", "cpu_percent", "rss_mb"):
        v = field(msg, key, (int, float), what, optional=True)
        out[key] = float("nan") if v is None else float(v)
    out["bytes_sent"] = field(msg, "bytes_sent", int, what, optional=True) or 0
    out["requests_refused"] = field(msg, "requests_refused", int, what, optional=True) or 0
    hist = None
    if "hist_z" in msg:
        raw = b64_bounded(msg["hist_z"], MAX_STATUS_BYTES, "status hist_z")
        hist = decompress_bounded(raw, 8 * hist_bins, "status hist_z")
        if len(hist) != 8 * hist_bins:
            raise LinkError(f"status hist_z holds {len(hist)} bytes, not {8 * hist_bins}")
    out["hist"] = hist
    return out


EVENT_KINDS = ("up", "down", "log", "fatal", "warn", "error", "info")


def decode_event(payload: bytes) -> tuple[str, str, str]:
    """An agent event checked: (kind, device, text), or LinkError."""
    what = "event"
    msg = decode_object(payload, MAX_EVENT_BYTES, 2, what)
    kind = field(msg, "kind", str, what)
    device = field(msg, "device", str, what)
    text = field(msg, "text", str, what)
    if not kind or len(kind) > 32 or not kind.isprintable():
        raise LinkError("event kind is not a short printable word")
    return kind, device, text


REPLY_STATUSES = ("ok", "invalid", "error")


def decode_command_reply(payload: bytes, n_sensors: int) -> tuple[str, object, list, int | None]:
    """A command reply checked: (status, payload, seqs, boot_id or None), or LinkError.

    ``seqs``: one int per sensor, or [] (a reply without them)."""
    what = "command reply"
    msg = decode_object(payload, MAX_REPLY_BYTES, MAX_DEPTH, what)
    status = field(msg, "status", str, what)
    if status not in REPLY_STATUSES:
        raise LinkError(f"command reply status {status[:40]!r} is not one of {REPLY_STATUSES}")
    if "payload" not in msg:
        raise LinkError("command reply has no 'payload'")
    seqs = field(msg, "seq", list, what, optional=True) or []
    if seqs and (
        len(seqs) != n_sensors
        or not all(isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 1 << 63
                   for s in seqs)
    ):  # fmt: skip
        raise LinkError(f"command reply seq is not a list of {n_sensors} counts")
    boot = field(msg, "boot_id", int, what, optional=True)
    return status, msg["payload"], seqs, boot


def decode_history_answer(payload: bytes) -> tuple[int | None, str]:
    """A history refusal ``{"id", "status": "invalid", "payload"}``: (id, why)."""
    what = "history answer"
    msg = decode_object(payload, MAX_EVENT_BYTES, 2, what)
    rid = field(msg, "id", int, what, optional=True)
    why = msg.get("payload")
    return rid, why[:MAX_TEXT] if isinstance(why, str) else repr(why)[:200]


class DropLog:
    """Counts dropped inputs per kind and says when to log one: at most one line per
    ``interval`` s per kind and reason (its first three words without digits: the
    checks' own wordings, so a peer cannot vary it into a flood), with the count."""

    def __init__(self, interval: float = 5.0) -> None:
        self.interval = interval
        self.counts: dict[str, int] = {}
        self.total = 0
        self._gate = WarnThrottle(interval)
        self._reasons: set[str] = set()

    def drop(self, kind: str, why: str) -> str | None:
        """Count one dropped ``kind`` input; the line to log now, or None (rate-limited)."""
        self.total += 1
        n = self.counts[kind] = self.counts.get(kind, 0) + 1
        key = kind + "|" + " ".join(re.sub(r"[0-9]", "", why).split()[:3])
        if self._gate(key) is None:
            return None
        self._reasons.add(key)
        if len(self._reasons) > 256:  # bounded: forget the reasons seen
            self._reasons = {key}
            self._gate = WarnThrottle(self.interval)
            self._gate(key)
        return f"dropped a {kind} input from the link: {why[:300]} ({n} so far)"
