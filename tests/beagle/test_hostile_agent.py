"""mm-beagle-agent under hostile peers (issue 27): nothing ends it, nothing holds up its poll.

A real agent on emulated sensors and loopback zenoh sessions. Each attack is checked for
survival (the agent answers 'info' after it), the refusal counted in its status, the
longest gap between two polls of the attack's window (read back from the agent's ring)
and the counts lost (emulator truth minus totals). The gap bound asserted here is a
generous one for a loaded 2-core machine; the figures themselves come from
``mm-bench agent`` (its ``hostile`` part).
"""

from __future__ import annotations

import json
import time

import pytest
from fakes import scaled, wait_until

zenoh = pytest.importorskip("zenoh")

from mm_beagle.link import link, zenoh_config  # noqa: E402
from mm_beagle.tools.harness import agent_process, free_port  # noqa: E402
from mm_beagle.tools.hostile_peer import (  # noqa: E402
    PollWatch,
    flood,
    peak_rss_mb,
    stuck_reader,
)

S0 = "/dev/spidev1.0"
GAP_BOUND_MS = 400.0  # asserted; the goal is 50 ms (see mm-bench agent's figures)
KEYS = link.keys(link.DEFAULT_NAME)


@pytest.fixture(scope="module")
def agent(tmp_path_factory):
    """(process, watch, log path) of one agent with a patch_dir holding ok.patch (2 words),
    full.patch (the PLN2033's whole 4096-word patch RAM) and big.patch (1 MiB)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    logs = tmp_path_factory.mktemp("agent")
    patches = tmp_path_factory.mktemp("patches")
    (patches / "ok.patch").write_text("0x12, 0x34, 0xAB, 0xCD\n")
    (patches / "full.patch").write_bytes(bytes(range(256)) * 32)  # 8192 bytes: 4096 words
    (patches / "big.patch").write_bytes(b"\x12\x34" * (1 << 19))  # 1 MiB
    opts = {"backend": "sim", "listen": [endpoint], "patch_dir": str(patches)}
    log = logs / "agent.log"
    with agent_process(opts, str(log)) as proc:
        watch = PollWatch(endpoint)
        wait_until(lambda: watch.command(timeout=0.5, cmd="info"), 60, "the agent's 'info'",
                   interval=0.1)  # fmt: skip
        watch.wait_status(lambda s: "requests_refused" in s, scaled(10))
        yield proc, watch, log
        watch.close()


def _window(watch: PollWatch) -> list[int]:
    wait_until(lambda: all(watch.seq(i) > 0 for i in range(2)), 10, "polls")
    return [watch.seq(i) for i in range(2)]


def _alive(proc, watch: PollWatch) -> None:
    assert proc.poll() is None, "the agent ended"
    reply = watch.command(cmd="info")
    assert reply is not None and reply["status"] == "ok"


def _refused(watch: PollWatch) -> int:
    return int(watch.status.get("requests_refused", 0))


def test_deep_brackets_on_the_request_keys_are_refused_and_counted(agent):
    proc, watch, log = agent
    before = _refused(watch)
    start = _window(watch)
    for size in (100_000, 60_000, 4000):  # zenoh drops the first, the agent refuses the rest
        flood(watch.session, KEYS["history_req"], [b"[" * size], query=False)
        flood(watch.session, KEYS["cmd"], [b"[" * size], query=True)
    status = watch.wait_status(lambda s: s["requests_refused"] >= before + 4, scaled(10))
    assert status["refused_by_key"]["history"] >= 2 and status["refused_by_key"]["command"] >= 2
    _alive(proc, watch)
    text = log.read_text()
    assert "refused a command request" in text and "refused a history request" in text
    assert "RecursionError" not in text and "Traceback" not in text
    end = _window(watch)
    assert watch.longest_gap_ms(start, end) < GAP_BOUND_MS
    assert watch.counts_lost() == 0


def test_patch_floods_and_a_1_mib_patch_file_never_hold_up_the_poll(agent):
    proc, watch, _log = agent
    start = _window(watch)
    before = _refused(watch)
    reply = watch.command(cmd="load_patch", sensor=S0, file="big.patch")
    assert reply["status"] == "invalid" and "refused unread" in reply["payload"]
    # 100 loads of the whole patch RAM at once: rate-limited, queued, written in steps
    flood(watch.session, KEYS["cmd"],
          [json.dumps({"cmd": "load_patch", "sensor": S0, "file": "full.patch"}).encode()] * 100,
          query=True)  # fmt: skip
    time.sleep(3.0)
    reply = watch.command(cmd="load_patch", sensor=S0, file="full.patch", timeout=scaled(20))
    assert reply["status"] == "ok" and reply["payload"] == 4096
    status = watch.wait_status(lambda s: s["requests_refused"] > before, scaled(10))
    assert status["refused_by_key"]["command"] > 0
    _alive(proc, watch)
    end = _window(watch)
    gap = watch.longest_gap_ms(start, end)
    assert gap < GAP_BOUND_MS, f"longest poll gap {gap:.1f} ms"
    assert watch.counts_lost() == 0


def test_a_history_reader_that_stops_reading_is_dropped_not_waited_for(agent):
    proc, watch, _log = agent
    start = _window(watch)
    stuck = stuck_reader(_endpoint(proc), link.DEFAULT_NAME, 6.0)
    try:
        assert stuck.stdout.readline().strip() == "stuck"
        time.sleep(6.0)
    finally:
        stuck.kill()
        stuck.wait(10)
    _alive(proc, watch)  # (while it asked, its requests took the command worker's turns)
    end = _window(watch)
    gap = watch.longest_gap_ms(start, end)
    assert gap < GAP_BOUND_MS, f"longest poll gap {gap:.1f} ms"
    assert watch.counts_lost() == 0


def test_a_200_mb_command_is_refused_and_memory_stays_bounded(agent):
    proc, watch, _log = agent
    rss0, peak0 = peak_rss_mb(proc.pid)
    start = _window(watch)
    replies = list(watch.session.get(KEYS["cmd"], payload=b"x" * 200_000_000, timeout=5.0))
    assert not [r for r in replies if r.ok is not None], "a 200 MB command was answered"
    _alive(proc, watch)
    rss1, peak1 = peak_rss_mb(proc.pid)
    # no shared-memory transport, messages over 64 KiB dropped by zenoh: a few MB at most
    assert peak1 - peak0 < 30, f"peak RSS {peak0:.1f} -> {peak1:.1f} MB"
    assert rss1 - rss0 < 30
    end = _window(watch)
    assert watch.longest_gap_ms(start, end) < GAP_BOUND_MS
    assert watch.counts_lost() == 0


def _endpoint(proc) -> str:
    """The agent's --listen endpoint, from its command line."""
    args = proc.args
    return args[args.index("--listen") + 1]


def test_request_parsing_is_bounded_and_field_by_field():
    from mm_beagle.link.agent_requests import COMMAND_KEYS, Refusals, TokenBucket, parse_request

    for payload, expect in (
        (b"[" * 100_000, "too large"),
        (b"[" * 4000, "nests deeper"),
        (b'{"cmd": "info", "x": 1}', "unknown keys"),
        (b'{"cmd": "info", "sensor": "' + b"a" * 2000 + b'"}', "longer than"),
        (b"\xff", "not JSON"),
        (b"[]", "JSON object"),
    ):
        with pytest.raises(link.LinkError, match=expect):
            parse_request(payload, "command", COMMAND_KEYS)
    assert parse_request(b'{"cmd": "info"}', "command", COMMAND_KEYS) == {"cmd": "info"}
    bucket = TokenBucket(1.0, 3)
    assert [bucket.allow() for _ in range(5)] == [True, True, True, False, False]
    import io

    out = io.StringIO()
    r = Refusals(stream=out)
    for _ in range(5):
        r.refuse("command", "size", "too large\nsecond line")
    lines = out.getvalue().splitlines()
    assert len(lines) == 1 and "too large second line" in lines[0]  # one line per second
    assert r.status()["requests_refused"] == 5 and r.status()["refused_by_reason"] == {"size": 5}


def test_a_peer_with_wrong_credentials_is_logged_by_the_agent(tmp_path):
    import subprocess
    import sys
    import threading

    good = tmp_path / "agent.credentials"
    made = subprocess.run(
        [sys.executable, "-m", "mm_beagle.link.agent_cli", "--make-credentials", str(good)],
        capture_output=True, text=True, timeout=30,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    wrong = tmp_path / "wrong.credentials"
    wrong.write_text("mm:not-the-password-at-all\n")
    wrong.chmod(0o600)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    log = tmp_path / "agent.log"
    opts = {"backend": "sim", "listen": [endpoint], "credentials": str(good)}
    with agent_process(opts, str(log)):
        opened: list = []

        def connect() -> None:  # never returns: the agent refuses the session
            opened.append(zenoh.open(zenoh_config.zenoh_config(connect=[endpoint],
                                                       credentials=str(wrong))))  # fmt: skip

        threading.Thread(target=connect, daemon=True).start()
        wait_until(lambda: "Invalid password" in log.read_text(), 30,
                   "the agent's log line for the refused peer")  # fmt: skip
        assert not opened  # and zenoh's own line on the agent said why


def test_patch_files_are_size_checked_unread_and_loaded_in_steps(tmp_path):
    from mm_beagle.poller.patches import (
        PatchPathError,
        check_patch_file_size,
        max_patch_file_bytes,
        patch_load_steps,
    )
    from pln2033.errors import PatchError
    from pln2033.pln2033 import PLN2033
    from pln2033.pln2033.emulator import EmulatedPLN2033

    assert max_patch_file_bytes(4096) == 65536
    big = tmp_path / "big.patch"
    big.write_bytes(b"\x00" * (65536 + 1))
    with pytest.raises(PatchPathError, match=r"65537 bytes.*refused unread"):
        check_patch_file_size(str(big), 4096)
    with pytest.raises(PatchPathError, match="not a regular file"):
        check_patch_file_size(str(tmp_path), 4096)
    check_patch_file_size(str(big), 4097 * 8)  # a larger RAM takes it

    emu = EmulatedPLN2033()
    driver = PLN2033(emu)
    words = [(7 * k) & 0xFFFF for k in range(100)]
    steps = sum(1 for _ in patch_load_steps(driver, words, step=32))
    assert steps == 8  # 4 write steps of 32 words, 4 verify steps, then the enable
    assert emu.ram[:100] == words and emu.patch_enabled

    class Flaky(EmulatedPLN2033):
        def _read_memory(self) -> int:  # the read-back differs at word 40
            value = super()._read_memory()
            return value ^ 1 if self._mem_ptr == 41 else value

    bad = Flaky()
    with pytest.raises(PatchError, match="verify failed at word 40"):
        for _ in patch_load_steps(PLN2033(bad), words, step=32):
            pass
    assert not bad.patch_enabled
