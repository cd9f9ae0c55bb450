"""The board link: key names, frame layout and zenoh set-up shared by agent and node.

The agent (:mod:`mm_beagle.link.agent`) serves under ``mm/<name>/``:

  polls     put, every ~10 ms: a batch frame (below) with each sensor's new polls
            and its totals after them; an empty batch at least every 100 ms
  status    put, every second: JSON (state, errors, poll statistics, CPU, RSS,
            the period histogram zlib-compressed)
  events    put: JSON {"kind", "device", "text"} when a sensor comes up or goes down
  cmd       queryable: JSON {"cmd": name, "sensor": device, <argument>: value}, the
            commands of :data:`mm_beagle.poller.commands.COMMANDS`; the reply is JSON
            {"status", "payload", "seq"}
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
"""

from __future__ import annotations

import ipaddress
import json
import os
import secrets
import stat
import struct
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


def decode_batch(data: bytes, n_sensors: int) -> Batch:
    """Parse and check a frame; LinkError names what is wrong."""
    if len(data) < HEADER.size + GLOB_BYTES:
        raise LinkError(f"batch frame of {len(data)} bytes is shorter than its header")
    magic, version, nblocks, _r, boot_id, number = HEADER.unpack_from(data, 0)
    if magic != MAGIC or version != VERSION:
        raise LinkError(f"not a version-{VERSION} batch frame (magic {magic!r}, v{version})")
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


def parse_request(payload: bytes, what: str) -> dict:
    """A JSON object from a query payload, or LinkError."""
    if len(payload) > 1 << 20:
        raise LinkError(f"{what} request of {len(payload)} bytes is too large")
    try:
        msg = json.loads(payload.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        raise LinkError(f"{what} request is not JSON") from None
    if not isinstance(msg, dict):
        raise LinkError(f"{what} request must be a JSON object")
    return msg


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


def zenoh_config(
    *,
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    credentials: str = "",
):
    """A zenoh.Config: no multicast scouting, no gossip, only the endpoints given.

    The agent listens (peer mode); the node connects as a client and keeps
    retrying every 0.1-1 s. With ``credentials`` both sides authenticate with
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
        cfg["connect"] = {
            "endpoints": connect,
            "timeout_ms": -1,
            "exit_on_failure": False,
            "retry": {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2},
        }
    if credentials:
        user, password = load_credentials(credentials)
        auth = {"user": user, "password": password}
        if listen:
            auth["dictionary_file"] = str(Path(credentials).resolve())
        cfg["transport"] = {"auth": {"usrpwd": auth}}
    return zenoh.Config.from_json5(json.dumps(cfg))
