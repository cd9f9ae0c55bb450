"""One poll as the ring buffer stores it: its fields, in order, and their machine types.

The one definition of the record: the shared state's ring arrays
(:class:`~mm_beagle.poller.shared_state.SharedState`), the link's batch frames
(:mod:`mm_beagle.link.link`: the ring's own bytes, field after field) and the node's
decoding of them (:mod:`mm_beagle.link.remote`) are all derived from :data:`RING`.
Pure Python: the board's poller imports it (no numpy).
"""

from __future__ import annotations

import struct
from typing import NamedTuple


class RingField(NamedTuple):
    name: str  # the key in SharedState.samples() (and GetSamples' field)
    code: str  # struct/array type code (native order in memory, little-endian on the link)


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
#: SharedState's attribute per field (``ring_stamp`` ... ``ring_quality``)
ATTRS = tuple("ring_" + f.name.removesuffix("_ns") for f in RING)
#: bytes per poll of each field
ITEM_BYTES = tuple(struct.calcsize(f.code) for f in RING)
#: one poll across all fields
POLL_BYTES = sum(ITEM_BYTES)
#: numpy dtypes of the fields as a batch frame carries them (little-endian)
WIRE_DTYPES = tuple("<" + f.code for f in RING)
