"""The agent's memory (issue 27 item 2: <= 40 MB RSS on x86): what it must not import, and
the frame MAC computed without OpenSSL still equal to hmac's."""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import subprocess
import sys

import pytest

from mm_beagle.link import link_auth


@pytest.mark.parametrize("key_len", [0, 1, 16, 63, 64, 65, 200])
def test_hmac_sha256_is_hmacs(key_len: int) -> None:
    key, msg = os.urandom(key_len), os.urandom(10_000)  # past MAC_SLICE: several slices
    want = hmac.new(key, msg, hashlib.sha256).digest()
    assert link_auth.hmac_sha256(key, msg[:3], msg[3:]) == want
    assert link_auth.hmac_sha256(link_auth.hmac_pads(key), msg) == want


def test_frame_tag_unchanged_on_the_wire(tmp_path) -> None:
    """The node of an older checkout checks the same tag: HMAC-SHA256(key, kind | body)."""
    creds = tmp_path / "c"
    creds.write_text("mm:abcdefghijklmnop\n")
    creds.chmod(0o600)
    auth = link_auth.FrameAuth.from_credentials(str(creds), "mm_beagle")
    key = hmac.new(b"abcdefghijklmnop", b"mm-link-v1/mm/mm_beagle", hashlib.sha256).digest()
    assert auth.key == key
    body = b"x" * 9000
    tag = auth.tag("polls", body)
    assert tag == hmac.new(key, b"polls|" + body, hashlib.sha256).digest()[:16]
    auth.check("polls", body, tag)
    with pytest.raises(Exception, match="fails authentication"):
        auth.check("status", body, tag)


def test_agent_imports_neither_openssl_nor_numpy() -> None:
    """hashlib/hmac load libcrypto (3.7 MB RSS); the spidev agent needs no numpy."""
    code = (
        "import sys, json, mm_beagle.link.agent_cli, zenoh;"
        "print(json.dumps([m in sys.modules for m in ('_hashlib', 'hmac', 'numpy')]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert json.loads(out.stdout.strip().splitlines()[-1]) == [False, False, False]


def test_malloc_arenas_limited_unless_the_environment_says(monkeypatch) -> None:
    from mm_beagle.link import agent_cli

    monkeypatch.setenv("MALLOC_ARENA_MAX", "4")
    assert agent_cli.limit_malloc_arenas() is False  # the operator's setting stands
    monkeypatch.delenv("MALLOC_ARENA_MAX")
    glibc = bool(os.confstr("CS_GNU_LIBC_VERSION")) if hasattr(os, "confstr") else False
    assert agent_cli.limit_malloc_arenas() is glibc


def test_realtime_helpers_only_below_a_realtime_poll_thread(monkeypatch) -> None:
    """The other threads are SCHED_FIFO at HELPER_PRIORITY only when the poll thread is
    real-time above it; refused (no permission) means normal scheduling, never an error."""
    from mm_beagle.link import agent_cli

    calls = []
    monkeypatch.setattr(agent_cli.os, "sched_setscheduler", lambda *a: calls.append(a))
    assert agent_cli.realtime_helpers(0) is False
    assert agent_cli.realtime_helpers(agent_cli.HELPER_PRIORITY) is False
    assert calls == []
    assert agent_cli.realtime_helpers(50) is True
    assert calls[0][1] == os.SCHED_FIFO
    assert calls[0][2].sched_priority == agent_cli.HELPER_PRIORITY

    def refuse(*a):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(agent_cli.os, "sched_setscheduler", refuse)
    assert agent_cli.realtime_helpers(50) is False


def test_an_oversize_request_is_refused_before_it_waits() -> None:
    """What waits for a worker holds at most MAX_REQUEST_BYTES each (zenoh delivers up to
    64 KiB): a larger payload is counted and dropped in zenoh's callback."""
    import io
    import types

    from mm_beagle.link.agent_queues import Inbox
    from mm_beagle.link.agent_requests import MAX_REQUEST_BYTES, Refusals

    log = io.StringIO()
    refusals = Refusals(stream=log)
    inbox = Inbox("history", refusals)
    inbox.put(types.SimpleNamespace(payload=b"{" * (MAX_REQUEST_BYTES + 1)))
    assert inbox.queue.qsize() == 0
    status = refusals.status()
    assert status["requests_refused"] == 1 and status["refused_by_reason"] == {"size": 1}
    assert f"of {MAX_REQUEST_BYTES + 1} bytes is too large" in log.getvalue()
    small = types.SimpleNamespace(payload=b'{"id": 1}')
    inbox.put(small)
    assert inbox.queue.get_nowait() is small
    assert refusals.status()["requests_refused"] == 1
