"""Command replies on the remote backend under a responder on the path (issue 27's
recheck, with a real agent, node and a zenoh router between them: 3 of 3 believed).

Without credentials a foreign responder knows the agent's boot id (from its status) and
its seqs, so its reply passed every check and, answering first, was taken: 'set to 1600
CPI' while the agent set 800. With credentials a reply the agent sent earlier, recorded
and answered again first, carried a valid tag and was taken the same way. Now every reply
is waited for, a reply whose seq is behind what the node had applied when it asked is
refused (a replay), and good replies that disagree are none believed."""

from __future__ import annotations

import json
import os

import pytest

from mm_beagle.link import link_auth
from mm_beagle.link.remote import RemoteAgent
from mm_beagle.poller.poller import PollerConfig
from mm_beagle.poller.poller_client import PollerError

S0, S1 = "/dev/spidev1.0", "/dev/spidev1.1"
BOOT = 0x5EED


class Bytes:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class Sample:
    def __init__(self, body: bytes, tag: bytes | None = None) -> None:
        self.payload = body
        self.attachment = Bytes(tag) if tag is not None else None


class Reply:
    def __init__(self, sample: Sample) -> None:
        self.ok, self.err = sample, None


class Session:
    """zenoh's session.get as the node sees it: the replies of every responder, in order."""

    def __init__(self, *samples: Sample) -> None:
        self.samples = samples
        self.asked: list[bytes] = []

    def get(self, key, payload, **_kw):
        self.asked.append(payload)
        return [Reply(s) for s in self.samples]


def body(text: str, seq: list[int], status: str = "ok", boot: int = BOOT) -> bytes:
    return json.dumps({"status": status, "payload": text, "seq": seq, "boot_id": boot}).encode()


def remote_on(session: Session, credentials: str = "") -> RemoteAgent:
    r = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=8192), credentials=credentials)
    r.session = session
    r._block_cc = r._target_all = r._no_consolidation = None
    r.boot = BOOT
    r.next_agent = [5000, 5000]  # the polls the node has applied
    r.link_up = True
    return r


def test_a_foreign_reply_with_the_right_boot_is_not_believed_before_the_agents():
    liar = Sample(body("/dev/spidev1.0 set to 1600 CPI", [5000, 5000]))
    agent = Sample(body("/dev/spidev1.0 set to 800 CPI", [5000, 5000]))
    remote = remote_on(Session(liar, agent))
    with pytest.raises(PollerError, match="conflicting replies: 2 different replies"):
        remote.command("set_cpi", 0, 800)
    assert remote.refused == 2 and remote.drops.counts == {"reply": 1}
    # the agent alone (or twice, as zenoh may deliver it): taken
    remote.session = Session(agent, agent)
    assert remote.command("set_cpi", 0, 800) == ("ok", "/dev/spidev1.0 set to 800 CPI")


def test_a_recorded_reply_answered_again_is_refused_with_credentials(tmp_path):
    path = tmp_path / "agent.credentials"
    path.write_text("mm:correct-horse-battery-staple\n")
    os.chmod(path, 0o600)
    auth = link_auth.FrameAuth.from_credentials(str(path), "mm_beagle")
    old = body("/dev/spidev1.0 set to 1600 CPI", [1200, 1200])  # recorded at seq 1200
    fresh = body("/dev/spidev1.0 set to 800 CPI", [5000, 5000])
    replay = Sample(old, auth.tag("reply", old))
    agent = Sample(fresh, auth.tag("reply", fresh))
    remote = remote_on(Session(replay, agent), credentials=str(path))
    assert remote.command("set_cpi", 0, 800) == ("ok", "/dev/spidev1.0 set to 800 CPI")
    assert remote.refused == 1 and remote.drops.counts == {"reply": 1}
    # the replay alone: refused, the command fails and says why
    remote.session = Session(replay)
    with pytest.raises(PollerError, match=r"behind seq 5000 .*a recorded reply replayed"):
        remote.command("set_cpi", 0, 800)
    assert remote.refused == 2
