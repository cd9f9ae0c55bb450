"""The link's bounded decoders and frame MAC, and the remote feeder's refusals, without
processes (issue 27): each hostile input gives a LinkError with one line, never a
RecursionError, zlib.error or a bomb's memory; the feeder counts and survives it."""

from __future__ import annotations

import base64
import json
import time
import zlib

import numpy as np
import pytest

from mm_beagle.link import link, link_auth, link_decode
from mm_beagle.link.remote import RemoteAgent
from mm_beagle.link.remote_feed import RING_DTYPES
from mm_beagle.poller import shared_state as ss
from mm_beagle.poller.poller import PollerConfig

S0, S1 = "/dev/spidev1.0", "/dev/spidev1.1"
HIST = ss.HIST_BINS


def status(**changes) -> bytes:
    hist_z = base64.b64encode(zlib.compress(np.zeros(HIST, np.int64).tobytes())).decode()
    msg = {
        "boot_id": 77,
        "uptime_s": 1.0,
        "devices": [S0, S1],
        "chips": ["pln2033", "pln2033"],
        "states": ["up", "up"],
        "last_errors": ["", ""],
        "cpu_percent": 3.0,
        "rss_mb": 20.0,
        "bytes_sent": 5,
        "hist_z": hist_z,
        **changes,
    }
    return json.dumps(msg).encode()


@pytest.mark.parametrize(
    "payload, why",
    [
        (b"[" * 100_000, "nests deeper"),
        (b'{"a": ' * 20 + b"1" + b"}" * 20, "nests deeper"),
        (b"[" * 300_000, "too large"),
        (b"\xff\xfe", "not JSON"),
        (b'{"a": NaN}', "not JSON"),
        (b"1" * 5000, "not JSON"),  # an int of 5000 digits
    ],
)
def test_json_is_decoded_only_when_small_and_shallow(payload, why):
    t0 = time.perf_counter()
    with pytest.raises(link.LinkError, match=why):
        link_decode.decode_json_bounded(payload, 200_000, 8)
    assert time.perf_counter() - t0 < 0.05


def test_brackets_inside_strings_are_no_nesting():
    assert link_decode.decode_json_bounded(b'{"a": "[[[[[[[[[[[[[[[["}', 100, 2) == {"a": "[" * 16}


def test_a_zlib_bomb_stops_at_the_output_limit_and_junk_is_no_zlib():
    bomb = zlib.compress(b"\0" * 300_000_000, 9)  # 291 kB
    with pytest.raises(link.LinkError, match="inflates beyond 160000"):
        link_decode.decompress_bounded(bomb, 160_000)
    with pytest.raises(link.LinkError, match="not zlib"):
        link_decode.decompress_bounded(b"this is not zlib", 160_000)
    good = zlib.compress(b"x" * 1000)
    assert link_decode.decompress_bounded(good, 1000) == b"x" * 1000
    with pytest.raises(link.LinkError, match="after its zlib stream"):
        link_decode.decompress_bounded(good + b"tail", 2000)


@pytest.mark.parametrize(
    "changes, why",
    [
        ({"hist_z": base64.b64encode(b"not zlib at all").decode()}, "not zlib"),
        ({"hist_z": "!!!"}, "not base64"),
        ({"hist_z": base64.b64encode(zlib.compress(b"\0" * 10_000_000)).decode()}, "beyond"),
        ({"hist_z": base64.b64encode(zlib.compress(b"\0" * 80)).decode()}, "holds 80 bytes"),
        ({"boot_id": "77"}, "boot_id"),
        ({"boot_id": True}, "boot_id"),
        ({"boot_id": 0}, "out of range"),
        ({"states": ["up"]}, "states"),
        ({"last_errors": [1, 2]}, "last_errors"),
        ({"devices": "/dev/x"}, "devices"),
        ({"chips": ["a"]}, "chips"),
        ({"uptime_s": "long"}, "uptime_s"),
    ],
)
def test_a_status_is_checked_field_by_field(changes, why):
    assert link_decode.decode_status(status(), 2, HIST)["hist"] == bytes(8 * HIST)
    with pytest.raises(link.LinkError, match=why):
        link_decode.decode_status(status(**changes), 2, HIST)


def test_events_and_replies_are_checked():
    up = b'{"kind": "up", "device": "d", "text": "t"}'
    assert link_decode.decode_event(up) == ("up", "d", "t")
    for bad in (b'{"kind": "up"}', b'{"kind": 1, "device": "", "text": ""}', b"[" * 100):
        with pytest.raises(link.LinkError):
            link_decode.decode_event(bad)
    ok = json.dumps({"status": "ok", "payload": 800, "seq": [1, 2], "boot_id": 5}).encode()
    assert link_decode.decode_command_reply(ok, 2) == ("ok", 800, [1, 2], 5)
    for bad in (
        {"status": "fine", "payload": 1},
        {"status": "ok"},
        {"status": "ok", "payload": 1, "seq": [1]},
        {"status": "ok", "payload": 1, "seq": [1, -2]},
        {"status": "ok", "payload": 1, "boot_id": "5"},
    ):
        with pytest.raises(link.LinkError):
            link_decode.decode_command_reply(json.dumps(bad).encode(), 2)


def test_the_frame_mac_needs_the_credentials_and_the_kind(tmp_path):
    creds = link_auth.make_credentials(str(tmp_path / "c"))
    auth = link_auth.FrameAuth.from_credentials(creds, "mm_beagle")
    other = link_auth.FrameAuth.from_credentials(creds, "other_agent")
    none = link_auth.FrameAuth.from_credentials("", "mm_beagle")
    body = b"MMB1 a frame"
    tag = auth.tag("polls", body)
    assert tag is not None and len(tag) == link_auth.TAG_BYTES and none.tag("polls", body) is None
    auth.check("polls", body, tag)
    none.check("polls", body, None)  # no credentials: nothing to check
    for kind, b, t, why in (
        ("polls", body, None, "no authentication tag"),
        ("polls", body + b"x", tag, "fails authentication"),
        ("status", body, tag, "fails authentication"),  # a polls frame replayed as status
        ("polls", body, other.tag("polls", body), "fails authentication"),
    ):
        with pytest.raises(link.LinkError, match=why):
            auth.check(kind, b, t)


def test_the_drop_log_says_one_line_per_kind_and_reason_per_interval():
    log = link_decode.DropLog(interval=5.0)
    lines = [log.drop("status", f"status of {n} bytes is too large") for n in range(100)]
    assert sum(line is not None for line in lines) == 1 and log.counts == {"status": 100}
    assert log.drop("status", "status hist_z is not zlib data") is not None  # another reason
    assert log.drop("polls", "x") is not None and log.counts["polls"] == 1 and log.total == 102


def frame(
    boot: int, number: int, first: int, dy: list[int], y_before: int, ahead_ns: int = 0
) -> bytes:
    blocks = []
    for i in (0, 1):
        ints = np.zeros(ss.N_INT, np.int64)
        ints[ss.I_SEQ] = first + len(dy)
        ints[ss.I_Y_TOTAL] = y_before + sum(dy)
        ints[ss.I_STATE] = ss.STATE_UP
        ints[ss.I_STAMP_NS] = time.time_ns() + ahead_ns
        k = len(dy)
        fields = (
            [time.time_ns() + ahead_ns] * k,
            [0] * k,
            dy,
            [0] * k,
            [1600] * k,
            [0] * k,
            [100] * k,
        )
        arrays = tuple(np.array(f, dt).tobytes() for f, dt in zip(fields, RING_DTYPES, strict=True))
        records = link.records_of(arrays)
        blocks.append(link.Block(i, first, k, ints.tobytes(), bytes(8 * ss.N_FLOAT), records))
    return link.encode_batch(boot, number, bytes(8 * ss.N_GLOBAL), blocks)


def feed(remote: RemoteAgent, kind: str, data: bytes, tag: bytes | None = None) -> None:
    """One input through the feeder's own path (what _feed does with a queue item)."""
    remote._handle(kind, data, time.time_ns(), tag, len(data))


def test_the_feeder_refuses_forged_frames_and_keeps_the_real_totals(tmp_path):
    creds = link_auth.make_credentials(str(tmp_path / "c"))
    auth = link_auth.FrameAuth.from_credentials(creds, link.DEFAULT_NAME)
    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=4096), credentials=creds)

    def real(kind: str, data: bytes) -> None:
        feed(remote, kind, data, auth.tag(kind, data))

    st = status(boot_id=77)
    feed(remote, "status", st)  # untagged: refused
    assert remote.boot is None and remote.refused == 1
    real("status", st)
    assert remote.boot == 77
    real("polls", frame(77, 1, 0, [1, 2, 3], 0))  # first contact: counts start after it
    real("polls", frame(77, 2, 3, [4, 5], 6))
    assert remote.state.snapshot(0).y_total == 9 and remote.state.snapshot(0).seq == 2
    bad = remote.bad_frames
    feed(remote, "polls", frame(77, 3, 5, [1000], 15))  # untagged
    real("polls", frame(77, 3, 5 + 10**9, [7], 15))  # seq + 10^9
    real("polls", frame(78, 3, 5, [7], 15))  # another boot while 77 is alive
    real("polls", frame(77, 3, 5, [7], 15 + 10**6))  # totals that do not add up
    real("status", status(boot_id=79))  # a new boot while 77 is alive
    real("status", status(boot_id=77, devices=["/dev/evil", S1]))  # devices changed
    real("events", b"[" * 100_000)
    real("events", json.dumps({"kind": "down", "device": "/dev/evil", "text": "x"}).encode())
    assert remote.bad_frames == bad + 8 and remote.boot == 77 and not remote.mismatch
    real("polls", frame(77, 3, 5, [7], 15))
    t = remote.state.snapshot(0)
    assert (t.seq, t.y_total) == (3, 16)  # only the real polls, none forged
    assert "polls" in remote.link_values()["link_dropped_by_kind"]


def test_a_consistent_forgery_holds_a_sensor_back_for_2_s_at_most(monkeypatch):
    """Without a secret a forged block with the next seq and totals that add up to its own
    polls passes; the agent's own blocks then fail the totals check. After RESYNC_S of
    nothing taken the node follows the agent again: its totals are the agent's (the
    forged counts gone), not frozen for good."""
    import mm_beagle.link.remote_feed as remote_feed

    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=4096))
    feed(remote, "status", status(boot_id=77))
    feed(remote, "polls", frame(77, 1, 0, [1, 2, 3], 0))
    feed(remote, "polls", frame(77, 2, 3, [4, 5], 6))
    feed(remote, "polls", frame(77, 3, 5, [30000], 15))  # forged, consistent
    assert remote.state.snapshot(0).y_total == 30009
    feed(remote, "polls", frame(77, 3, 5, [1, 1], 15))  # the agent's own: refused
    assert remote.state.snapshot(0).y_total == 30009 and remote.refused == 1
    monkeypatch.setattr(remote_feed, "RESYNC_S", 0.0)
    feed(remote, "polls", frame(77, 4, 5, [1, 1], 15))  # ... until the node follows it again
    t = remote.state.snapshot(0)
    assert (t.seq, t.y_total) == (4, 11) and remote.resyncs >= 1
    feed(remote, "polls", frame(77, 5, 7, [2], 17))
    assert remote.state.snapshot(0).y_total == 13


@pytest.mark.parametrize(
    "payload",
    [b'"\\' * 50_000, b'"' * 100_001, b"[" * 100_000, b'["' + b"x" * 200_000 + b'"]'],
)
def test_the_depth_check_is_linear_and_needs_no_memory(payload):
    """A regex over strings took 38 s on '"\\' x 50 000 and 15 MB of stack for one 130 kB
    string; the scan is linear (well under 0.5 s here) and allocates nothing per byte."""
    import resource

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    link_decode.json_depth_ok(payload, 8)
    assert time.perf_counter() - t0 < 0.5
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 4096  # kB


def test_a_refused_block_does_not_move_the_clock_offset():
    """A forged block stamped an hour ahead would have set the offset estimate (the
    smallest delay) an hour back for every later poll, even though it was refused."""
    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=4096))
    feed(remote, "status", status(boot_id=77))
    feed(remote, "polls", frame(77, 1, 0, [1, 2, 3], 0))
    feed(remote, "polls", frame(77, 2, 3, [4, 5], 6))
    offset = remote._offset_ns
    feed(remote, "polls", frame(77, 3, 5, [1], 15 + 10**6, ahead_ns=3600 * 10**9))
    assert remote.refused == 1 and abs(remote._offset_ns - offset) < 50_000_000
