"""The board link: key names, frame layout and zenoh set-up shared by agent and node.

The agent (:mod:`mm_beagle.link.agent`) serves under ``mm/<name>/``:

  polls     put, every ~10 ms: a batch frame (below) with each sensor's new polls
            and its totals after them; an empty batch at least every 100 ms
  status    put, every second: JSON (state, errors, poll statistics, CPU, RSS,
            the period histogram zlib-compressed)
  events    put: JSON {"kind", "device", "text"} when a sensor comes up or goes down
  cmd       queryable: JSON {"cmd": name, "sensor": device, <argument>: value}, the
            commands of :data:`mm_beagle.poller.commands.COMMANDS`; the reply is JSON
            {"status", "payload", "seq", "boot_id"} (the node takes no reply of
            another boot)
  history_req  subscribed: JSON {"id": k, "sensor": i, "since": seq, "max": n}; the
            answer is put on ``history``: a batch frame numbered k, or JSON
            {"id": k, "status": "invalid", "payload": why}. (Pub/sub, not a query:
            zenoh 1.10 queries can end at once with no reply right after a
            reconnection, eclipse-zenoh/zenoh#2767, exactly when a gap is fetched.)

Batch frame, little-endian: header ``<4sBBHQQ`` (magic, version, sensor blocks,
reserved, boot id, batch number), the poller-wide counters (N_GLOBAL int64), then
per block ``<BxxxIQ`` (sensor index, poll count, first seq), the sensor's int64
and float64 fields and its polls as one array per ring field
(:data:`mm_beagle.poller.ring_layout.RING`: stamp q, dx h, dy h, status H, cpi H,
flags B, quality h). The arrays are the shared-state ring's own bytes, so neither
side touches single polls in Python. No numpy here: the agent runs without it.

Everything a peer sends is decoded bounded here (issue 27): size first, JSON only when
it nests at most MAX_DEPTH deep, zlib with an output limit, field by field
(:func:`decode_json_bounded`, :func:`decode_status`, ...). With credentials every
message of the agent carries an HMAC tag as its zenoh attachment (:class:`FrameAuth`);
the agent's session refuses peers' puts and queryables on its keys (:func:`agent_acl`).
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import ipaddress
import json
import os
import re
import secrets
import stat
import struct
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

from mm_beagle.poller import ring_layout
from mm_beagle.poller import shared_state as ss

MAGIC = b"MMB1"
VERSION = 3  # 2: four lift-estimate variances (N_FLOAT 10); 3: quality per poll, N_INT 20,
# N_FLOAT 16 (the chip's own pose)
HEADER = struct.Struct("<4sBBHQQ")
BLOCK = struct.Struct("<BxxxIQ")
GLOB_BYTES = 8 * ss.N_GLOBAL
INTS_BYTES = 8 * ss.N_INT
FLOATS_BYTES = 8 * ss.N_FLOAT
POLL_BYTES = ring_layout.POLL_BYTES  # one poll across the ring fields
ARRAY_ITEM = ring_layout.ITEM_BYTES  # bytes per poll, in SharedState.RING_FIELDS order

DEFAULT_PORT = 7447
DEFAULT_ENDPOINT = f"tcp/127.0.0.1:{DEFAULT_PORT}"
DEFAULT_NAME = "mm_beagle"
MAX_HISTORY = 16384  # polls per history reply
MAX_BLOCK_POLLS = 1 << 21  # polls in one block (35 min at 1 kHz: more than any agent ring)
NODE_RX_MAX_BYTES = 8 << 20  # the node's zenoh drops larger messages (a gap is fetched)
CREDENTIALS_HELP = "see docs/hardware-setup.md, 'Credentials'"


class LinkError(ValueError):
    """A frame, request or set-up that cannot be used; the message says why."""


def keys(name: str) -> dict[str, str]:
    """The agent's key expressions under ``mm/<name>``."""
    if not name or any(c in name for c in "/*$?#") or name.strip() != name:
        raise LinkError(f"agent name '{name}' must be one non-empty key chunk (no / * $ ? #)")
    base = f"mm/{name}"
    names = ("polls", "status", "events", "cmd", "history", "history_req")
    return {k: f"{base}/{k}" for k in names}


# --- frames ------------------------------------------------------------------------------


@dataclass
class Block:
    """One sensor's part of a batch: polls ``first_seq`` .. ``first_seq + count``."""

    index: int
    first_seq: int
    count: int
    ints: bytes  # N_INT int64: the sensor's totals after these polls
    floats: bytes  # N_FLOAT float64
    arrays: tuple[bytes, ...]  # the ring fields, ``count`` items each


@dataclass
class Batch:
    boot_id: int
    number: int
    glob: bytes
    blocks: list[Block]


def encode_batch(boot_id: int, number: int, glob: bytes, blocks: list[Block]) -> bytes:
    """One frame; ``blocks[i].arrays`` may be lists of byte pieces (a wrapped ring)."""
    parts = [HEADER.pack(MAGIC, VERSION, len(blocks), 0, boot_id, number), glob]
    for b in blocks:
        parts += [BLOCK.pack(b.index, b.count, b.first_seq), b.ints, b.floats]
        for a in b.arrays:
            if isinstance(a, (list, tuple)):
                parts.extend(a)
            else:
                parts.append(a)
    return b"".join(parts)


def max_batch_bytes(n_sensors: int) -> int:
    """The largest batch frame a node of ``n_sensors`` accepts (bytes)."""
    per = BLOCK.size + INTS_BYTES + FLOATS_BYTES + MAX_BLOCK_POLLS * POLL_BYTES
    return HEADER.size + GLOB_BYTES + n_sensors * per


def decode_batch(data: bytes, n_sensors: int) -> Batch:
    """Parse and check a frame; LinkError names what is wrong."""
    if len(data) < HEADER.size + GLOB_BYTES:
        raise LinkError(f"batch frame of {len(data)} bytes is shorter than its header")
    magic, version, nblocks, _r, boot_id, number = HEADER.unpack_from(data, 0)
    if magic != MAGIC or version != VERSION:
        raise LinkError(f"not a version-{VERSION} batch frame (magic {magic!r}, v{version})")
    if nblocks > n_sensors:
        raise LinkError(f"batch frame of {nblocks} blocks; this node has {n_sensors} sensors")
    off = HEADER.size
    glob = bytes(data[off : off + GLOB_BYTES])
    off += GLOB_BYTES
    blocks = []
    for _ in range(nblocks):
        if len(data) < off + BLOCK.size + INTS_BYTES + FLOATS_BYTES:
            raise LinkError("batch frame cut short in a block header")
        index, count, first = BLOCK.unpack_from(data, off)
        off += BLOCK.size
        if index >= n_sensors:
            raise LinkError(f"batch block for sensor {index}; this node has {n_sensors}")
        if count > MAX_BLOCK_POLLS or first >= 1 << 62:
            raise LinkError(f"batch block of {count} polls from seq {first} is out of range")
        ints = bytes(data[off : off + INTS_BYTES])
        off += INTS_BYTES
        floats = bytes(data[off : off + FLOATS_BYTES])
        off += FLOATS_BYTES
        if len(data) < off + count * POLL_BYTES:
            raise LinkError(f"batch block of {count} polls is cut short")
        arrays = []
        for size in ARRAY_ITEM:
            arrays.append(bytes(data[off : off + count * size]))
            off += count * size
        blocks.append(Block(index, first, count, ints, floats, tuple(arrays)))
    if off != len(data):
        raise LinkError(f"batch frame has {len(data) - off} bytes after its last block")
    return Batch(boot_id, number, glob, blocks)


# --- bounded decoding of everything a peer sends ------------------------------------------
# Every payload from the link is size-checked before it is decoded, decoded without
# unbounded recursion, decompressed with an output limit and checked field by field.

MAX_REQUEST_BYTES = 64 * 1024  # a command or history request (they are < 200 bytes)
MAX_STATUS_BYTES = 256 * 1024  # a status (~1-3 kB: hist_z holds a compressed 160 kB array)
MAX_EVENT_BYTES = 16 * 1024
MAX_REPLY_BYTES = 256 * 1024  # a command reply (settings: a few kB)
MAX_TEXT = 4096  # characters of one text field (an error, an event's text)
MAX_DEPTH = 8  # nesting of JSON arrays/objects (ours use at most 3)
_TOKENS = re.compile(rb'["\\\[\]{}]')  # the characters that matter to nesting


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
    if len(payload) > max_bytes:
        raise LinkError(f"{what} of {len(payload)} bytes is too large (limit {max_bytes})")
    data = bytes(payload)
    if not json_depth_ok(data, max_depth):
        raise LinkError(f"{what} nests deeper than {max_depth} levels")
    try:
        return json.loads(data.decode("utf-8"), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise LinkError(f"{what} is not JSON") from None


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
    msg = decode_json_bounded(payload, MAX_STATUS_BYTES, MAX_DEPTH, what)
    if not isinstance(msg, dict):
        raise LinkError("status is not a JSON object")
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
    msg = decode_json_bounded(payload, MAX_EVENT_BYTES, 2, what)
    if not isinstance(msg, dict):
        raise LinkError("event is not a JSON object")
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
    msg = decode_json_bounded(payload, MAX_REPLY_BYTES, MAX_DEPTH, what)
    if not isinstance(msg, dict):
        raise LinkError("command reply is not a JSON object")
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
    msg = decode_json_bounded(payload, MAX_EVENT_BYTES, 2, what)
    if not isinstance(msg, dict):
        raise LinkError("history answer is not a JSON object")
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
        self._last: dict[tuple[str, str], tuple[float, int]] = {}

    def drop(self, kind: str, why: str) -> str | None:
        """Count one dropped ``kind`` input; the line to log now, or None (rate-limited)."""
        self.total += 1
        n = self.counts[kind] = self.counts.get(kind, 0) + 1
        now = time.monotonic()
        key = (kind, " ".join(re.sub(r"[0-9]", "", why).split()[:3]))
        last = self._last.get(key, (-1e9, 0))[0]
        if now - last < self.interval:
            return None
        if len(self._last) > 256:  # bounded: forget the reasons seen
            self._last.clear()
        self._last[key] = (now, n)
        return f"dropped a {kind} input from the link: {why[:300]} ({n} so far)"


# --- frame authentication (with credentials) ----------------------------------------------

TAG_BYTES = 16  # HMAC-SHA256 truncated: 128 bits


class FrameAuth:
    """A MAC over every message the agent sends, keyed by the shared credential.

    Without credentials (``key`` None) there is no tag and :meth:`check` passes. With them
    the agent sends ``TAG_BYTES`` of HMAC-SHA256(key, kind | body) as the zenoh
    attachment of each message (the payload is unchanged) and the node refuses anything
    without a valid tag. ``kind`` (polls, status, events, history, reply) is in the MAC, so
    one kind cannot be replayed as another; the boot id and sequence numbers are inside
    the body, and the node's boot and sequence rules refuse replays. The key is
    HMAC-SHA256(password, "mm-link-v1/" + user + "/" + agent name).
    """

    def __init__(self, key: bytes | None) -> None:
        self.key = key

    @classmethod
    def from_credentials(cls, path: str, name: str) -> FrameAuth:
        if not path:
            return cls(None)
        user, password = load_credentials(path)
        info = f"mm-link-v1/{user}/{name}".encode()
        return cls(hmac.new(password.encode(), info, hashlib.sha256).digest())

    def tag(self, kind: str, body: bytes) -> bytes | None:
        """The attachment to send with ``body`` on ``kind`` (None without credentials)."""
        if self.key is None:
            return None
        mac = hmac.new(self.key, kind.encode() + b"|", hashlib.sha256)
        mac.update(body)
        return mac.digest()[:TAG_BYTES]

    def check(self, kind: str, body: bytes, attachment: bytes | None) -> None:
        """LinkError unless ``attachment`` is the tag of ``body`` (always fine without a key)."""
        if self.key is None:
            return
        if attachment is None or len(attachment) != TAG_BYTES:
            raise LinkError(f"{kind} message has no authentication tag (forged, or an old agent)")
        if not hmac.compare_digest(attachment, self.tag(kind, body) or b""):
            raise LinkError(f"{kind} message fails authentication (forged, or other credentials)")


def attachment_bytes(sample) -> bytes | None:
    """A zenoh sample's attachment as bytes (None: none, or longer than a tag could be)."""
    att = getattr(sample, "attachment", None)
    if att is None:
        return None
    data = att.to_bytes()
    return data if len(data) <= 64 else None


# --- endpoints, credentials, zenoh configuration -----------------------------------------


def endpoint_host(endpoint: str) -> str:
    """``tcp/127.0.0.1:7447`` -> ``127.0.0.1``; LinkError for anything else."""
    proto, _, rest = endpoint.partition("/")
    if proto not in ("tcp", "tls", "quic", "udp") or not rest or ":" not in rest:
        raise LinkError(
            f"endpoint '{endpoint}' is not PROTO/HOST:PORT (e.g. {DEFAULT_ENDPOINT}, "
            "tcp/192.168.7.2:7447)"
        )
    host, _, port = rest.rpartition(":")
    port = port.split("#", 1)[0]
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise LinkError(f"endpoint '{endpoint}' has no valid port")
    return host.strip("[]")


def is_loopback(endpoint: str) -> bool:
    host = endpoint_host(endpoint)
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def load_credentials(path: str) -> tuple[str, str]:
    """(user, password) from a ``user:password`` file only its owner can read."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise LinkError(f"cannot read credentials file {p}: {exc.strerror or exc}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise LinkError(
            f"credentials file {p} can be read by others (mode {stat.filemode(mode)}); "
            f"run: chmod 600 {p}"
        )
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    if len(lines) != 1 or ":" not in lines[0]:
        raise LinkError(f"credentials file {p} must hold one line 'user:password'")
    user, password = lines[0].split(":", 1)
    if not user or len(password) < 12:
        raise LinkError(f"credentials file {p}: needs a user and a password of 12+ characters")
    return user, password


def make_credentials(path: str, user: str = "mm") -> str:
    """Write a new ``user:password`` file (mode 600); refuses to overwrite one."""
    p = Path(path)
    if p.exists():
        raise LinkError(f"{p} exists; remove it first to make new credentials")
    p.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(f"{user}:{secrets.token_urlsafe(24)}\n")
    return str(p)


AGENT_KEYS = ("polls", "status", "events", "history", "cmd")  # what only the agent sends


def agent_acl() -> dict:
    """zenoh access control for the agent's session: no peer may put on the keys only the
    agent publishes (polls, status, events, history), nor declare a queryable on ``cmd``
    or reply to a query there. Every connected peer is such a subject (zenoh's subject
    with no criteria matches all): nodes only put history requests and query ``cmd``.
    The node is a client of the agent's session, so everything it receives passes here."""
    rule = {
        "id": "only-the-agent-speaks",
        "permission": "deny",
        "flows": ["ingress"],
        "messages": ["put", "delete", "declare_queryable", "reply"],
        "key_exprs": [f"mm/*/{k}" for k in AGENT_KEYS],
    }
    return {
        "enabled": True,
        "default_permission": "allow",
        "rules": [rule],
        "subjects": [{"id": "every-peer"}],
        "policies": [{"rules": [rule["id"]], "subjects": ["every-peer"]}],
    }


def zenoh_config(
    *,
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    credentials: str = "",
):
    """A zenoh.Config: no multicast scouting, no gossip, only the endpoints given.

    The agent listens (peer mode, with :func:`agent_acl`); the node connects as a
    client and keeps retrying every 0.1-1 s. With ``credentials`` both sides authenticate with
    zenoh's user/password scheme: a listener then refuses peers without them.
    ``RUST_LOG`` (e.g. ``zenoh=debug``) turns on zenoh's own log on stderr.
    """
    import zenoh

    zenoh.try_init_log_from_env()

    cfg: dict = {
        "mode": "peer" if listen else "client",
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
    }
    if listen:
        cfg["listen"] = {"endpoints": listen}
    if connect:
        # The node: no shared memory (a local peer's large message maps its 16 MB segment
        # into the node), and no message over NODE_RX_MAX_BYTES is reassembled (a larger
        # live batch is dropped and its polls fetched as a gap, 4096 per history reply).
        cfg["transport"] = {
            "shared_memory": {"enabled": False},
            "link": {"rx": {"max_message_size": NODE_RX_MAX_BYTES}},
        }
        cfg["connect"] = {
            "endpoints": connect,
            "timeout_ms": -1,
            "exit_on_failure": False,
            "retry": {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2},
        }
    if listen:
        cfg["access_control"] = agent_acl()
    if credentials:
        user, password = load_credentials(credentials)
        auth = {"user": user, "password": password}
        if listen:
            auth["dictionary_file"] = str(Path(credentials).resolve())
        cfg.setdefault("transport", {})["auth"] = {"usrpwd": auth}
    return zenoh.Config.from_json5(json.dumps(cfg))
