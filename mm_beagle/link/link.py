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
and float64 fields and its polls, one packed record each
(:data:`mm_beagle.poller.ring_layout.RECORD` ``<qhhHHBh``: stamp, dx, dy, status, cpi,
flags, quality; 19 bytes). The records are the shared-state ring's own bytes
(:func:`ring_block`), so neither side touches single polls in Python. No numpy here: the
agent runs without it.

Around the frames: what a peer sends is decoded bounded in :mod:`~mm_beagle.link.link_decode`,
the credentials and the MAC on each message are in :mod:`~mm_beagle.link.link_auth`, and the
zenoh sessions' configuration (endpoints, access control) in :mod:`~mm_beagle.link.zenoh_config`.
"""

from __future__ import annotations

import array
import struct
import sys
from dataclasses import dataclass

from mm_beagle.poller import ring_layout
from mm_beagle.poller import shared_state as ss

MAGIC = b"MMB1"
VERSION = 4  # 2: four lift-estimate variances (N_FLOAT 10); 3: quality per poll, N_INT 20,
# N_FLOAT 16 (the chip's own pose); 4: the polls as records (ring_layout.RECORD), not arrays
HEADER = struct.Struct("<4sBBHQQ")
BLOCK = struct.Struct("<BxxxIQ")
GLOB_BYTES = 8 * ss.N_GLOBAL
INTS_BYTES = 8 * ss.N_INT
FLOATS_BYTES = 8 * ss.N_FLOAT
POLL_BYTES = ring_layout.POLL_BYTES  # one poll: a ring record
ARRAY_ITEM = ring_layout.ITEM_BYTES  # bytes of each field of a record, in RING order

DEFAULT_PORT = 7447
DEFAULT_ENDPOINT = f"tcp/127.0.0.1:{DEFAULT_PORT}"
DEFAULT_NAME = "mm_beagle"
MAX_HISTORY = 16384  # polls per history reply
MAX_BLOCK_POLLS = 1 << 21  # polls in one block (35 min at 1 kHz: more than any agent ring)
NODE_RX_MAX_BYTES = 8 << 20  # the node's zenoh drops larger messages (a gap is fetched)


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
    records: bytes | list  # ``count`` ring records (or byte pieces of them: a wrapped ring)

    @property
    def arrays(self) -> tuple[bytes, ...]:
        """The polls as one little-endian array per ring field (RING order), for tools and
        tests: pure Python, a loop per poll (the node decodes ``records`` with numpy)."""
        pieces = self.records if isinstance(self.records, (list, tuple)) else [self.records]
        data = b"".join(pieces)
        rows = list(ring_layout.RECORD.iter_unpack(data))
        out = []
        for k, f in enumerate(ring_layout.RING):
            column = array.array(f.code, [r[k] for r in rows])
            if sys.byteorder != "little":
                column.byteswap()
            out.append(column.tobytes())
        return tuple(out)


@dataclass
class Batch:
    boot_id: int
    number: int
    glob: bytes
    blocks: list[Block]


def records_of(arrays: tuple[bytes, ...] | list[bytes]) -> bytes:
    """Per-field little-endian arrays (RING order, as :attr:`Block.arrays` gives them) as
    ring records: what a block carries. Pure Python, a loop per poll (tests and tools)."""
    columns = []
    for f, data in zip(ring_layout.RING, arrays, strict=True):
        column = array.array(f.code, bytes(data))
        if sys.byteorder != "little":
            column.byteswap()
        columns.append(column)
    if len({len(c) for c in columns}) > 1:
        raise LinkError("the fields' arrays differ in length")
    return b"".join(ring_layout.RECORD.pack(*row) for row in zip(*columns, strict=True))


def ring_block(
    index: int, ring: memoryview, first: int, end: int, ints: bytes, floats: bytes
) -> Block:
    """Sensor ``index``'s polls ``first`` .. ``end`` from its ring's bytes
    (:meth:`~mm_beagle.poller.shared_state.SharedState.ring_bytes`), as the newest ring
    slots hold them (older polls were overwritten: the block starts later); no copy
    until the frame is joined."""
    n = len(ring) // POLL_BYTES
    first = max(first, end - n, 0)
    count = end - first
    a = first % n * POLL_BYTES
    b = a + count * POLL_BYTES
    records: bytes | list = ring[a:b] if b <= len(ring) else [ring[a:], ring[: b - len(ring)]]
    return Block(index, first, count, ints, floats, records)


def encode_batch(boot_id: int, number: int, glob: bytes, blocks: list[Block]) -> bytes:
    """One frame; ``blocks[i].records`` may be a list of byte pieces (a wrapped ring)."""
    parts = [HEADER.pack(MAGIC, VERSION, len(blocks), 0, boot_id, number), glob]
    for b in blocks:
        parts += [BLOCK.pack(b.index, b.count, b.first_seq), b.ints, b.floats]
        if isinstance(b.records, (list, tuple)):
            parts.extend(b.records)
        else:
            parts.append(b.records)
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
        records = bytes(data[off : off + count * POLL_BYTES])
        off += count * POLL_BYTES
        blocks.append(Block(index, first, count, ints, floats, records))
    if off != len(data):
        raise LinkError(f"batch frame has {len(data) - off} bytes after its last block")
    return Batch(boot_id, number, glob, blocks)
