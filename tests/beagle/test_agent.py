"""mm-beagle-agent: its configuration, its link requests, who may talk to it, and
the node's remote backend through link drops and agent restarts.

Real processes throughout: the agent on emulated sensors, zenoh sessions on
loopback, and mm-beagle (backend:=remote) answering over real ROS 2 services.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

import pytest
from fakes import scaled, wait_until

zenoh = pytest.importorskip("zenoh")

from mm_beagle.link import link, link_auth, zenoh_config  # noqa: E402
from mm_beagle.tools.harness import (  # noqa: E402
    BeagleClient,
    agent_command,
    agent_process,
    beagle_process,
    free_port,
)
from mm_beagle.tools.link_proxy import ProxyProcess  # noqa: E402

S0, S1 = "/dev/spidev1.0", "/dev/spidev1.1"


def run_agent(*args: str, timeout: float = 30) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "mm_beagle.link.agent_cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


# --- configuration ----------------------------------------------------------------------


@pytest.fixture
def creds(tmp_path):
    path = tmp_path / "agent.credentials"
    assert run_agent("--make-credentials", str(path)).returncode == 0
    return str(path)


def test_make_credentials_writes_a_private_file_and_never_overwrites(creds):
    assert oct(os.stat(creds).st_mode & 0o777) == "0o600"
    user, password = link_auth.load_credentials(creds)
    assert user == "mm" and len(password) >= 24
    again = run_agent("--make-credentials", creds)
    assert again.returncode == 2 and "exists" in again.stderr
    assert link_auth.load_credentials(creds) == (user, password)


@pytest.mark.parametrize(
    ("args", "expect"),
    [
        (["--listen", "tcp/0.0.0.0:7447"], "needs credentials"),
        (["--listen", "tcp/192.168.7.2:7447"], "needs credentials"),
        (["--listen", "garbage"], "not PROTO/HOST:PORT"),
        (["--listen", "tcp/127.0.0.1:99999"], "no valid port"),
        (["--cpi", "801"], "'cpi'"),
        (["--poll-rate", "0"], "poll_rate"),
        (["--ring-seconds", "10"], "ring_seconds"),
        (["--name", "a/b"], "key chunk"),
        (["--devices", "/dev/a", "/dev/a"], "distinct"),
        (["--register-map", "/nonexistent.yaml"], "nonexistent"),
        (["--credentials", "/nonexistent"], "cannot read credentials"),
        (["--sim-fail-windows", "nope"], "DEVICE@START-END"),
        (["--realtime-priority", "100"], "0..99"),
        (["--sim-speed", "9"], "'sim_speed' must be 0.001..5 m/s, got 9"),
        (["--spi-speed-hz", "50"], "'spi_speed_hz' must be 100000..8000000 Hz, got 50"),
        (["--retry-interval", "0"], "'retry_interval' must be 0.1..60 s, got 0"),
        (["--ring-seconds", "10"], "'ring_seconds' must be 60..600 s (at least the link's"),
        (["--patch-file", "/etc/hostname"], "patch loading is off"),
        (["--patch-dir", "/", "--patch-file", "/nonexistent.patch"], "not a file"),
        (["--patch-dir", "/nonexistent", "--patch-file", "x.patch"], "cannot be used"),
    ],
)
def test_bad_configuration_exits_2_with_a_message(args, expect):
    res = run_agent("--backend", "sim", *args)
    assert res.returncode == 2, res.stderr
    assert expect in res.stderr
    assert "Traceback" not in res.stderr


def test_readable_credentials_and_bad_config_files_are_refused(tmp_path, creds):
    os.chmod(creds, 0o644)
    res = run_agent("--credentials", creds)
    assert res.returncode == 2 and "chmod 600" in res.stderr
    for text, expect in (
        ("cpi: [1, 2", "not valid YAML"),
        ("- a\n- b\n", "mapping"),
        ("colour: red\n", "unknown options"),
        ("cpi: fast\n", "'cpi' must be int"),
        ("backend: remote\n", "'backend' is 'remote'; allowed: spidev, sim"),
        ("poll_rate: 5000\n", "'poll_rate' must be 10..2000 Hz, got 5000"),
        ("[" * 5000, "nested too deeply"),  # one line, as for calibration files
    ):
        cfg = tmp_path / "agent.yaml"
        cfg.write_text(text)
        res = run_agent("--config", str(cfg))
        assert res.returncode == 2, (text, res.stderr)
        assert expect in res.stderr and "Traceback" not in res.stderr


def test_self_test_prints_one_json_line_and_loses_nothing():
    res = run_agent(
        "--backend",
        "sim",
        "--realtime-priority",
        "0",
        "--listen",
        f"tcp/127.0.0.1:{free_port()}",
        "--self-test",
        "2",
    )
    assert res.returncode == 0, res.stderr
    report = json.loads(res.stdout.strip().splitlines()[-1])
    for key in ("polls", "rate_hz", "cpu_us_per_poll", "counts_generated", "counts_lost", "rss_mb"):
        assert key in report
    assert report["polls"] > 500 and report["counts_generated"] > 1000
    assert report["counts_lost"] == 0
    # the poll thread's own CPU beside the whole process's (zenoh, sender thread)
    assert 0 < report["cpu_us_per_poll_poll_thread"] <= report["cpu_us_per_poll"]


# --- the link, queried directly -----------------------------------------------------------


def session_to(endpoint: str, credentials: str = ""):
    return zenoh.open(zenoh_config.zenoh_config(connect=[endpoint], credentials=credentials))


def ask(session, key: str, payload: bytes, timeout: float | None = None) -> bytes | None:
    """The first good reply to a get on ``key`` (None after ``timeout`` s, default 10 scaled)."""
    timeout = scaled(10) if timeout is None else timeout
    for reply in session.get(key, payload=payload, timeout=timeout):
        if reply.ok is not None:
            return reply.ok.payload.to_bytes()
    return None


def command(session, **msg) -> dict:
    data = ask(session, link.keys("mm_beagle")["cmd"], json.dumps(msg).encode())
    assert data is not None, "the agent did not answer"
    return json.loads(data)


@pytest.fixture(scope="module")
def agent(tmp_path_factory):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    log = tmp_path_factory.mktemp("agent") / "agent.log"
    patches = tmp_path_factory.mktemp("patches")
    (patches / "ok.patch").write_text("0x12, 0x34, 0xAB, 0xCD  // two 16-bit words\n")
    outside = tmp_path_factory.mktemp("elsewhere") / "evil.patch"
    outside.write_text("0xDE, 0xAD\n")
    (patches / "link.patch").symlink_to(outside)
    opts = {"backend": "sim", "listen": [endpoint], "patch_dir": str(patches)}
    with agent_process(opts, str(log)) as proc:
        s = session_to(endpoint)
        wait_until(lambda: ask(s, link.keys("mm_beagle")["cmd"], b'{"cmd": "info"}', 0.5), 60,
                   "the agent's answer to 'info'", interval=0.1)
        yield proc, s
        s.close()


def cpis(session) -> list[int]:
    return [command(session, cmd="settings", sensor=d)["payload"]["cpi_x"] for d in (S0, S1)]


@pytest.mark.parametrize(
    ("msg", "expect"),
    [
        (b"\xff\xfe", "not JSON"),
        (b"[1, 2]", "JSON object"),
        (b'{"cmd": "format_disk"}', "unknown command"),
        (b'{"cmd": "set_cpi", "sensor": "/dev/spidev9.9", "cpi": 800}', "unknown sensor"),
        (b'{"cmd": "set_cpi", "sensor": "/dev/spidev1.0", "cpi": "800"}', "integer"),
        (b'{"cmd": "set_cpi", "sensor": "/dev/spidev1.0", "cpi": true}', "integer"),
        (b'{"cmd": "set_cpi", "sensor": "/dev/spidev1.0", "cpi": 801}', "100..6400"),
        (b'{"cmd": "set_cpi", "sensor": "/dev/spidev1.0", "cpi": 0}', "100..6400"),
        # patch code: never sent over the network, only named in the agent's patch_dir
        (b'{"cmd": "load_patch", "sensor": "/dev/spidev1.0", "words": [4660]}', "not 'words'"),
        (b'{"cmd": "load_patch", "sensor": "/dev/spidev1.0"}', "needs 'file'"),
        (b'{"cmd": "load_patch", "sensor": "/dev/spidev1.0", "file": 7}', "needs 'file'"),
        (b'{"cmd": "load_patch", "sensor": "/dev/spidev1.0", "file": "../e.patch"}', "outside"),
        (b'{"cmd": "load_patch", "sensor": "/dev/spidev1.0", "file": "/etc/passwd"}', "outside"),
        (b'{"cmd": "load_patch", "sensor": "/dev/spidev1.0", "file": "link.patch"}', "outside"),
        (b'{"cmd": "load_patch", "sensor": "/dev/spidev1.0", "file": "nope.patch"}', "not a file"),
    ],
)
def test_bad_commands_are_refused_with_a_message_and_change_nothing(agent, msg, expect):
    _, s = agent
    before = cpis(s)
    data = ask(s, link.keys("mm_beagle")["cmd"], msg)
    reply = json.loads(data)
    assert reply["status"] == "invalid" and expect in reply["payload"]
    assert cpis(s) == before == [1600, 1600]


def history(session, payload: bytes, timeout: float = 30.0) -> bytes:
    """Put a history request (again every 0.2 s), return the first answer on the history key."""
    got: list[bytes] = []
    keys = link.keys("mm_beagle")
    sub = session.declare_subscriber(keys["history"], lambda s: got.append(s.payload.to_bytes()))

    def answered() -> bool:
        if not got:
            session.put(keys["history_req"], payload)
        return bool(got)

    try:
        wait_until(answered, timeout, "an answer on the history key", interval=0.2)
    finally:
        sub.undeclare()
    return got[0]


@pytest.mark.parametrize(
    ("msg", "expect"),
    [
        (b"nope", "not JSON"),
        (b'{"id": 1, "sensor": -1, "since": 0}', ">= 0"),
        (b'{"id": 1, "sensor": 7, "since": 0}', "not one of"),
        (b'{"id": 1, "sensor": 0, "since": 1e99}', "integer"),
        (b'{"id": -5, "sensor": 0, "since": 0}', "'id'"),
        (b'{"id": 1, "sensor": 0, "since": 9223372036854775807}', "ahead of the newest"),
    ],
)
def test_bad_history_requests_are_refused(agent, msg, expect):
    _, s = agent
    reply = json.loads(history(s, msg))
    assert reply["status"] == "invalid" and expect in reply["payload"]


def test_a_history_request_gets_the_polls_asked_for(agent):
    _, s = agent
    data = history(s, b'{"id": 42, "sensor": 1, "since": 10, "max": 25}')
    batch = link.decode_batch(data, 2)
    assert batch.number == 42
    (block,) = batch.blocks
    assert (block.index, block.first_seq, block.count) == (1, 10, 25)
    assert len(block.arrays[1]) == 2 * 25  # dx, int16


def test_good_commands_answer_and_set_cpi_reads_back(agent):
    _, s = agent
    info = command(s, cmd="info")["payload"]
    assert info["devices"] == [S0, S1] and info["ring_size"] >= 60_000
    reply = command(s, cmd="set_cpi", sensor=S1, cpi=3200)
    assert reply["status"] == "ok" and reply["payload"] == 3200
    assert cpis(s) == [1600, 3200]
    assert command(s, cmd="set_cpi", sensor=S1, cpi=1600)["status"] == "ok"
    patch = command(s, cmd="load_patch", sensor=S0, file="ok.patch")
    assert patch["status"] == "ok" and patch["payload"] == 2  # words of the file in patch_dir


# --- who may talk to the agent ------------------------------------------------------------


def test_a_peer_without_the_credentials_is_refused_and_changes_nothing(tmp_path, creds):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with agent_process({"backend": "sim", "listen": [endpoint], "credentials": creds}):
        good = session_to(endpoint, creds)
        wait_until(lambda: ask(good, link.keys("mm_beagle")["cmd"], b'{"cmd": "info"}', 0.5), 60,
                   "the agent's answer to 'info' with the credentials",
                   interval=0.1)
        wrong = tmp_path / "wrong.credentials"
        wrong.write_text("mm:not-the-password-at-all\n")
        wrong.chmod(0o600)
        for bad in ("", str(wrong)):
            # the agent refuses the session itself: it never opens, so nothing is sent
            opened: list = []
            t = threading.Thread(
                target=lambda b=bad, out=opened: out.append(session_to(endpoint, b)), daemon=True
            )
            t.start()
            t.join(3.0)
            assert not opened, f"a session with credentials {bad!r} was accepted"
        assert cpis(good) == [1600, 1600]
        assert command(good, cmd="set_cpi", sensor=S0, cpi=400)["payload"] == 400
        good.close()


# --- the node's remote backend through drops and restarts ---------------------------------


def node_totals(client) -> dict[str, tuple[int, int, int]]:
    res = client.call("get_sensor_data", id="")
    assert res.success, res.message
    return {d.id: (d.seq, d.x_total_counts, d.y_total_counts) for d in res.data}


def wait_link(client, up: bool, timeout: float = 60) -> str:
    """Wait until get_sensor_data says the link is up (or the agent unreachable): its message."""
    seen = [""]

    def link_is() -> bool:
        res = client.call("get_sensor_data", id="", timeout=scaled(30))
        seen[0] = res.message
        return res.success == up and (up or "unreachable" in res.message)

    try:
        wait_until(link_is, timeout, f"the link {'up' if up else 'down'}", interval=0.1)
    except AssertionError as exc:
        raise AssertionError(f"{exc}; the node's last answer: {seen[0]!r}") from None
    return seen[0]


def sample_sums(client, dev: str, since: int, until: int) -> tuple[int, int, int]:
    """(dx, dy, dropped) of the single polls since..until through get_samples."""
    sx = sy = dropped = 0
    seq = since
    while seq < until:
        res = client.call("get_samples", id=dev, since_seq=seq, max_samples=20000)
        assert res.success, res.message
        dropped += res.dropped
        take = min(len(res.dx), until - res.first_seq)
        sx += sum(res.dx[:take])
        sy += sum(res.dy[:take])
        seq = res.first_seq + take
    return sx, sy, dropped


@pytest.mark.ros
def test_link_drops_lose_no_poll_and_an_agent_restart_keeps_totals_monotone(tmp_path):
    port = free_port()
    proxy = ProxyProcess(port)
    client = BeagleClient("mm_agent_test")
    opts = {"backend": "sim", "listen": [f"tcp/127.0.0.1:{port}"], "sim_trajectory": "meander"}
    node_log = tmp_path / "node.log"
    try:
        with (
            agent_process(opts, str(tmp_path / "agent.log")) as agent,
            beagle_process(
                {"backend": "remote", "agent": proxy.endpoint, "diagnostics_period": 0.5},
                env=dict(os.environ),
                log_path=str(node_log),
            ),
        ):
            assert client.wait(scaled(60)), node_log.read_text()
            wait_link(client, up=True)
            start = node_totals(client)
            lost: dict[str, int] = {}
            for _ in range(2):
                proxy.cut()
                msg = wait_link(client, up=False)
                assert proxy.endpoint in msg
                r = client.call("set_resolution", id=S0, cpi=800)
                assert not r.success and "unreachable" in r.message
                time.sleep(1.5)  # an outage long enough for polls to pile up in the agent's ring
                proxy.restore()
                wait_link(client, up=True)
            end = node_totals(client)
            diag = client.diagnostics(time.monotonic(), timeout=scaled(30))
            for dev in (S0, S1):
                seq0, x0, y0 = start[dev]
                seq1, x1, y1 = end[dev]
                sx, sy, dropped = sample_sums(client, dev, seq0, seq1)
                lost[dev] = int(diag[dev]["link_polls_lost"])
                assert int(diag[dev]["link_drops"]) >= 2
                # the totals are exact whatever happened to single polls
                assert int(diag[dev]["sim_generated_y_counts"]) == int(diag[dev]["y_total_counts"])
                assert int(diag[dev]["sim_generated_x_counts"]) == int(diag[dev]["x_total_counts"])
                # every poll of the outages came from the agent's ring
                assert (sx, sy, dropped) == (x1 - x0, y1 - y0, 0), node_log.read_text()[-3000:]
                assert lost[dev] == 0
            # the agent restarts: the node's totals and seq continue, never go back
            agent.send_signal(2)
            agent.wait(scaled(30))
            wait_link(client, up=False)
            with agent_process(opts, str(tmp_path / "agent2.log")):
                wait_link(client, up=True)

                def past_end():
                    now = node_totals(client)
                    return now if all(now[d][0] > end[d][0] for d in (S0, S1)) else None

                after = wait_until(past_end, 30, "polls from the restarted agent on both sensors")
                for dev in (S0, S1):
                    assert after[dev][0] > end[dev][0]
                    assert after[dev][2] > end[dev][2]  # meander drives forward
                d = client.diagnostics(time.monotonic(), timeout=scaled(30))
                assert d[S0]["agent_restarts"] == "1"
    finally:
        client.close()
        proxy.close()


@pytest.mark.ros
def test_a_link_that_drops_again_while_the_gap_is_fetched_loses_no_poll(tmp_path):
    """A flapping link: back for 50 ms (the node sees a batch and starts asking
    for the gap), then down again for 2 s. The node waits for the link instead of
    counting the gap lost, and says the agent is unreachable meanwhile."""
    port = free_port()
    proxy = ProxyProcess(port)
    client = BeagleClient("mm_agent_flap_test")
    opts = {"backend": "sim", "listen": [f"tcp/127.0.0.1:{port}"], "sim_trajectory": "meander"}
    node_log = tmp_path / "node.log"
    try:
        with (
            agent_process(opts, str(tmp_path / "agent.log")),
            beagle_process(
                {"backend": "remote", "agent": proxy.endpoint, "diagnostics_period": 0.5},
                env=dict(os.environ),
                log_path=str(node_log),
            ),
        ):
            assert client.wait(scaled(60)), node_log.read_text()
            wait_link(client, up=True)
            start = node_totals(client)
            for _ in range(2):
                proxy.cut()
                wait_link(client, up=False)
                time.sleep(1.0)  # down a while before it flaps
                proxy.flap(0.05, 2.0)
                wait_link(client, up=True)
            # the link is up again once a batch arrives, before its gap is fetched: wait for
            # a batch applied after that, so a gap counted lost is on the diagnostics read
            up = node_totals(client)

            def past_up():
                now = node_totals(client)
                return now if all(now[d][0] > up[d][0] for d in (S0, S1)) else None

            end = wait_until(past_up, 30, "polls applied after the link came back")
            diag = client.diagnostics(time.monotonic(), timeout=scaled(30))
            for dev in (S0, S1):
                seq0, x0, y0 = start[dev]
                seq1, x1, y1 = end[dev]
                assert sample_sums(client, dev, seq0, seq1) == (x1 - x0, y1 - y0, 0)
                assert diag[dev]["link_polls_lost"] == "0", node_log.read_text()[-3000:]
                assert int(diag[dev]["sim_generated_y_counts"]) == int(diag[dev]["y_total_counts"])
    finally:
        client.close()
        proxy.close()


@pytest.mark.ros
def test_bad_frames_on_the_polls_key_are_dropped_and_counted(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    client = BeagleClient("mm_agent_frames")
    try:
        with (
            agent_process({"backend": "sim", "listen": [endpoint]}),
            beagle_process(
                {"backend": "remote", "agent": endpoint, "diagnostics_period": 0.5},
                env=dict(os.environ),
            ),
        ):
            assert client.wait(scaled(60))
            wait_link(client, up=True)
            # the agent's access control (zenoh_config.agent_acl) drops a peer's puts on its
            # keys: the node never sees them (tests/beagle/test_hostile_link.py feeds the node
            # bad frames past the agent, through a router of its own, and finds them counted)
            rogue = session_to(endpoint)
            for junk in (b"", b"MMB1", b"\x00" * 200, b"MMB1\x01\x09" + b"\x00" * 100):
                rogue.put(link.keys("mm_beagle")["polls"], junk)
            time.sleep(1.0)
            diag = client.diagnostics(time.monotonic(), timeout=scaled(30))
            assert diag[S0]["link_bad_frames"] == "0", diag[S0]
            rogue.close()
            before = node_totals(client)
            # still fed by the real agent
            wait_until(lambda: node_totals(client)[S0][0] > before[S0][0], 30,
                       "polls from the real agent after the bad frames")
    finally:
        client.close()


def test_agent_command_line_builder_round_trips():
    cmd = agent_command({"backend": "sim", "listen": ["tcp/127.0.0.1:1", "tcp/[::1]:2"]})
    assert cmd[-6:] == [
        "--backend",
        "sim",
        "--listen",
        "tcp/127.0.0.1:1",
        "--listen",
        "tcp/[::1]:2",
    ]


def test_applying_a_block_never_puts_the_agents_lock_word_into_the_node_state():
    """The agent's I_VERSION (odd while it was writing, or just another number) must
    not reach the node's seqlock even for a moment: only the node's own +1/+1."""
    import numpy as np

    from mm_beagle.link import link
    from mm_beagle.link.remote import RemoteAgent
    from mm_beagle.poller import shared_state as ss
    from mm_beagle.poller.poller import PollerConfig

    remote = RemoteAgent(PollerConfig(devices=[S0, S1], ring_size=1024))
    seen: list[int] = []

    class Watched(np.ndarray):
        """The node's int fields of sensor 0, recording every lock word written."""

        def __setitem__(self, key, value):
            super().__setitem__(key, value)
            seen.append(int(np.asarray(self)[ss.I_VERSION]))

    st = remote.state.ints[0].view(Watched)
    remote.state.ints = [st, remote.state.ints[1]]  # what _apply writes through
    ints = np.zeros(ss.N_INT, np.int64)
    ints[ss.I_VERSION] = 12345  # odd: the agent's own lock word mid-write
    ints[ss.I_SEQ], ints[ss.I_Y_TOTAL] = 3, 7
    from mm_beagle.link.remote_feed import RING_DTYPES

    arrays = [np.zeros(3, dt) for dt in RING_DTYPES]
    arrays[2][:] = (2, 2, 3)  # dy: the totals add up to the polls (or the block is refused)
    arrays = tuple(a.tobytes() for a in arrays)
    records = link.records_of(arrays)
    block = link.Block(0, 0, 3, ints.tobytes(), np.zeros(ss.N_FLOAT).tobytes(), records)
    remote.next_agent[0] = 0  # followed from seq 0 (a first contact's counts start after it)
    before = int(st[ss.I_VERSION])
    remote._apply(block, fetch_gaps=False)
    assert int(st[ss.I_VERSION]) == before + 2
    assert 12345 not in seen and all(v in (before, before + 1, before + 2) for v in seen)
    assert int(st[ss.I_Y_TOTAL]) == 7 and int(st[ss.I_SEQ]) == 3


def test_the_agents_config_is_built_as_the_nodes(tmp_path):
    """Defaults <- file <- command line, then mm_beagle.poller.options.poller_config_from."""
    from mm_beagle.link.agent_cli import DEFAULTS, build_parser, config_from_args
    from mm_beagle.poller.options import poller_config_from

    f = tmp_path / "agent.yaml"
    f.write_text("poll_rate: 500\nsim_speed: 0.5\nchips: ['pln2033,pln2033']\n")
    args = ["--config", str(f), "--backend", "sim", "--sim-fail-windows", "/dev/spidev1.1@1-2"]
    cfg = config_from_args(build_parser().parse_args(args))
    p = cfg.poller
    assert (p.backend, p.poll_rate, p.sim.speed) == ("sim", 500.0, 0.5)
    assert p.chips == ["pln2033", "pln2033"]  # "a,b" in one entry too
    assert p.sim.fail_windows == ["/dev/spidev1.1@1-2"] and p.sim.trajectory == "figure_eight"
    assert p.ring_size == round(65.536 * 500)
    direct = poller_config_from({**DEFAULTS, "backend": "sim"}, 1024, [(0.1, 0.0, 0.0)] * 2)
    assert (direct.devices, direct.cpi, direct.ring_size) == (DEFAULTS["devices"], 1600, 1024)
    assert direct.sim.mounts == [(0.1, 0.0, 0.0)] * 2
    with pytest.raises(ValueError, match="distinct"):
        poller_config_from({**DEFAULTS, "devices": ["/dev/a", "/dev/a"]}, 1024)
