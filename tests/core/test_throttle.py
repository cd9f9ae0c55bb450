"""mm_pc.core.throttle: one message per key and period, the rest counted, bounded keys."""

from mm_pc.core.throttle import WarnThrottle


def test_warn_throttle_counts_what_it_holds_back():
    now = [0.0]
    w = WarnThrottle(5.0, clock=lambda: now[0])
    assert w("a") == 0
    assert w("a") is None and w("a") is None
    assert w("b") == 0
    now[0] = 5.0
    assert w("a") == 2


def test_warn_throttle_remembers_at_most_max_keys():
    now = [0.0]
    w = WarnThrottle(5.0, clock=lambda: now[0], max_keys=100)
    for k in range(10_000):  # made-up keys, one per message (a peer varying its input)
        now[0] = k * 0.001
        assert w(f"key {k}") == 0
    assert len(w._last) <= 100
    assert len(w._held) <= 100
    # a recent key is still throttled, with its count
    assert w("key 9999") is None
    now[0] = 20.0
    assert w("key 9999") == 1


def test_warn_throttle_forgets_expired_keys_first():
    now = [0.0]
    w = WarnThrottle(1.0, clock=lambda: now[0], max_keys=3)
    assert w("old") == 0
    now[0] = 5.0
    for k in "abc":
        assert w(k) == 0
    assert set(w._last) == {"a", "b", "c"}  # "old" (period over) went, not "a"
    assert w("a") is None
