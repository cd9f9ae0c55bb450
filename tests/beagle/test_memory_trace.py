"""MM_BEAGLE_TRACEMALLOC: the node's debug dump of where its Python memory grows."""

from __future__ import annotations

import io
import tracemalloc

from mm_beagle.node import memory_trace


def test_period_from_env_off_unless_a_positive_number():
    assert memory_trace.period_from_env({}) is None
    for text in ("", "0", "-5", "nan", "inf", "abc", "1e9"):
        assert memory_trace.period_from_env({memory_trace.ENV: text}) is None, text
    assert memory_trace.period_from_env({memory_trace.ENV: " 30 "}) == 30.0
    assert memory_trace.start({}, io.StringIO()) is None


def test_growth_lines_name_the_growing_site_first():
    tracemalloc.start(5)
    try:
        base = tracemalloc.take_snapshot()
        kept = [bytearray(1000) for _ in range(500)]  # ~500 kB at this line
        lines = memory_trace.growth_lines(base, tracemalloc.take_snapshot(), top=3)
    finally:
        tracemalloc.stop()
    assert len(kept) == 500
    assert len(lines) == 3
    kib, blocks, site = lines[0].split(maxsplit=4)[0::2]
    assert site.endswith("test_memory_trace.py:23")  # the list comprehension above
    assert 480 < float(kib) < 560
    assert int(blocks) >= 500  # each bytearray: its object and its buffer
