"""One poll as the ring buffer stores it: one packed little-endian record per poll.

The one definition of the record: the shared state's ring (one :data:`RECORD` per slot,
written by one ``pack_into`` per poll: :class:`~mm_beagle.poller.shared_state.SharedState`,
:mod:`mm_beagle.poller.channel`), the link's batch frames (:mod:`mm_beagle.link.link`: the
ring's records as they are) and the node's decoding of them
(:mod:`mm_beagle.link.remote_feed`: :data:`DTYPE`) are all derived from :data:`RING`.
Pure Python: the board's poller imports it (no numpy).
"""

from __future__ import annotations

import struct
from typing import NamedTuple


class RingField(NamedTuple):
    name: str  # the key in SharedState.samples() (and GetSamples' field)
    code: str  # struct/array type code of the field (little-endian, in memory and on the link)


RING = (
    RingField("stamp_ns", "q"),  # poll time, ns since the Unix epoch (system clock)
    RingField("dx", "h"),  # counts, sensor X
    RingField("dy", "h"),  # counts, sensor Y
    RingField("status", "H"),  # the raw status register
    RingField("cpi", "H"),  # the Y resolution in force at that poll
    RingField("flags", "B"),  # mm_pc.core.poll_flags bits
    RingField("quality", "h"),  # the chip's quality figure (-1: none)
)

NAMES = tuple(f.name for f in RING)
#: SharedState's attribute per field (``ring_stamp`` ... ``ring_quality``: numpy views)
ATTRS = tuple("ring_" + f.name.removesuffix("_ns") for f in RING)
#: one poll, all fields in RING order: little-endian, packed (no padding)
RECORD = struct.Struct("<" + "".join(f.code for f in RING))
#: bytes per poll of each field
ITEM_BYTES = tuple(struct.calcsize("<" + f.code) for f in RING)
#: each field's byte offset in a record
OFFSETS = tuple(sum(ITEM_BYTES[:k]) for k in range(len(RING)))
#: one poll across all fields (a record)
POLL_BYTES = RECORD.size
#: numpy dtypes of the fields (little-endian)
WIRE_DTYPES = tuple("<" + f.code for f in RING)
#: the record as a numpy structured dtype: ``numpy.dtype(DTYPE)`` (packed, POLL_BYTES long)
DTYPE = [(f.name, dt) for f, dt in zip(RING, WIRE_DTYPES, strict=True)]

assert sum(ITEM_BYTES) == POLL_BYTES  # packed: the link's and numpy's record agree
