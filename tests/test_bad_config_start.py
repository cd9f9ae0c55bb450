"""Every bad value refused at start: one line, exit 2, no traceback, nothing started or
written (issue 27 item 6, the inputs of its finding 9).

The agent's command line and config file, the node's link and sim-chip parameters,
mm-odometry's calibration file and mm-monitor's --duration, each started as a user
starts it (``python -m``), with a deadline: a FIFO that blocked the start fails the test
instead of hanging it.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from fakes import scaled

from mm_beagle.link import link_checks
from mm_beagle.tools.harness import free_port, isolated_ros_env
from mm_pc.core import user_file

LONG_NAME = "a" * 100_000  # under Linux's 128 KiB limit for one argument


@pytest.fixture
def files(tmp_path):
    """name -> path of the odd files the cases name (a FIFO, a 2 MiB file, bad YAML)."""
    d = tmp_path / "files"
    d.mkdir()
    os.mkfifo(d / "fifo")
    (d / "big.yaml").write_bytes(b"# " + b"x" * (2 << 20) + b"\n")
    (d / "bad.yaml").write_text("cpi: [1, 2\nbackend: {\n")
    return {p.stem: str(p) for p in d.iterdir()} | {"zero": "/dev/zero", "dir": str(d)}


def _run(cmd: list[str], cwd, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        cmd, capture_output=True, text=True, timeout=scaled(60), cwd=cwd,
        env={**isolated_ros_env(), **(env or {})},
    )  # fmt: skip


def _refused(out: subprocess.CompletedProcess, prefix: str, says: str) -> None:
    """Exit 2 and exactly one line: ``prefix`` ... ``says``; no traceback."""
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2, out.stderr[-2000:]
    assert len(lines) == 1, out.stderr[-2000:]
    assert lines[0].startswith(prefix) and says in lines[0], lines[0][:500]
    assert "Traceback" not in out.stderr


# --- mm-beagle-agent ------------------------------------------------------------------------

AGENT_CASES = {
    "ring 20000 s": (["--ring-seconds", "20000"], "'ring_seconds' must be 60..600 s"),
    "ring by memory": (
        ["--ring-seconds", "600", "--poll-rate", "2000"],
        "'ring_seconds' 600 s at 2000 Hz for 2 sensors needs 44 MiB of poll ring; at most 32",
    ),
    "spi -1": (["--spi-speed-hz", "-1"], "'spi_speed_hz' must be 100000..8000000 Hz, got -1"),
    "spi 9 MHz": (["--spi-speed-hz", "9000000"], "must be 100000..8000000 Hz, got 9000000"),
    "poll rate nan": (["--poll-rate", "nan"], "'poll_rate' must be a finite number, got nan"),
    "sim speed -1": (["--sim-speed", "-1"], "'sim_speed' must be 0.001..5 m/s, got -1"),
    "sim speed nan": (["--sim-speed", "nan"], "'sim_speed' must be a finite number, got nan"),
    "lift rate nan": (["--sim-lift-rate", "nan"], "'sim_lift_rate' must be a finite number"),
    "noise inf": (["--sim-noise-counts", "inf"], "'sim_noise_counts' must be a finite number"),
    "retry nan": (["--retry-interval", "nan"], "'retry_interval' must be a finite number"),
    "name 100 kB": (["--name", LONG_NAME], "(100000 characters) must be 1..64 letters"),
    "name space": (["--name", "a b"], "agent name 'a b' must be 1..64 letters, digits"),
    "name slash": (["--name", "a/b"], "one key chunk: no / * $ ? #"),
    "self-test -1": (["--self-test", "-1"], "--self-test must be more than 0 and at most 3600"),
    "self-test nan": (["--self-test", "nan"], "--self-test must be more than 0"),
    "self-test 0": (["--self-test", "0"], "--self-test must be more than 0"),
    "self-test inf": (["--self-test", "inf"], "--self-test must be more than 0"),
    "config fifo": (["--config", "{fifo}"], "config file {fifo}: not a regular file (a FIFO)"),
    "config zero": (["--config", "{zero}"], "/dev/zero: not a regular file (a character device)"),
    "config dir": (["--config", "{dir}"], "not a regular file (a directory)"),
    "config 2 MiB": (["--config", "{big}"], "too large (2097155 bytes; at most 1048576)"),
    "config yaml": (
        ["--config", "{bad}"],
        "config file {bad}: not valid YAML: expected ',' or ']', but got ':' (line 2,",
    ),
    "credentials fifo": (["--credentials", "{fifo}"], "credentials file {fifo}: not a regular"),
    "credentials zero": (["--credentials", "{zero}"], "(a character device)"),
    "listen tls": (["--listen", "tls/127.0.0.1:{port}"], "tls/ needs its certificate to listen"),
    "listen quic": (["--listen", "quic/127.0.0.1:{port}"], "quic/ needs its certificate"),
    "listen tls key": (
        ["--listen", "tls/127.0.0.1:{port}#listen_certificate_file={bad}"],
        "tls/ needs its private key to listen",
    ),
    "listen cert fifo": (
        ["--listen", "tls/127.0.0.1:{port}#listen_certificate_file={fifo}"],
        "listen_certificate_file {fifo}: not a regular file (a FIFO)",
    ),
    "listen iface": (
        ["--listen", "tcp/127.0.0.1:{port}#iface=nope0"],
        "this machine has no network interface 'nope0'",
    ),
    "trajectory fifo": (
        ["--sim-trajectory", "file:{fifo}"],
        "trajectory file {fifo}: cannot read it (not a regular file (a FIFO))",
    ),
    "trajectory zero": (["--sim-trajectory", "file:{zero}"], "(a character device)"),
    "register map fifo": (["--register-map", "{fifo}"], "cannot read register map {fifo}: not a"),
    "register map zero": (["--register-map", "{zero}"], "register map /dev/zero: not a regular"),
    "sim chips": (
        ["--sim-chips", "pmw3360,otos"],
        "'sim_chips' pmw3360,otos differ from 'chips' pln2033,pln2033",
    ),
}  # fmt: skip


def _fill(text: str, files: dict, port: int) -> str:
    return text.format(port=port, **files) if "{" in text and text != LONG_NAME else text


@pytest.mark.parametrize("case", sorted(AGENT_CASES))
def test_the_agent_refuses_a_bad_value_at_start(case, files, tmp_path):
    args, says = AGENT_CASES[case]
    port = free_port()
    (cwd := tmp_path / "cwd").mkdir()
    cmd = [sys.executable, "-m", "mm_beagle.link.agent_cli", "--backend", "sim",
           "--realtime-priority", "0", "--listen", f"tcp/127.0.0.1:{port}"]  # fmt: skip
    out = _run([*cmd, *(_fill(a, files, port) for a in args)], cwd)
    _refused(out, "mm-beagle-agent: error: ", _fill(says, files, port))
    assert "polling" not in out.stderr and list(cwd.iterdir()) == []


# --- mm-beagle (the node) -------------------------------------------------------------------

NODE_CASES = {
    "agent tls": (
        ["backend:=remote", "agent:=tls/127.0.0.1:{port}"],
        "tls/ needs its root CA certificate to connect: add #root_ca_certificate_file=PATH",
    ),
    "agent quic": (["backend:=remote", "agent:=quic/127.0.0.1:{port}"], "quic/ needs its root CA"),
    "agent iface": (
        ["backend:=remote", "agent:=tcp/127.0.0.1:{port}#iface=nope0"],
        "no network interface 'nope0'",
    ),
    "credentials zero": (
        ["backend:=remote", "agent_credentials:={zero}"],
        "cannot read credentials file /dev/zero: not a regular file (a character device)",
    ),
    "credentials fifo": (
        ["backend:=remote", "agent_credentials:={fifo}"],
        "credentials file {fifo}: not a regular file (a FIFO)",
    ),
    "agent name 300": (["backend:=remote", "agent_name:=" + "a" * 300], "(300 characters)"),
    "register map fifo": (["register_map:={fifo}"], "cannot read register map {fifo}: not a"),
    "trajectory fifo": (
        ["backend:=sim", "sim_trajectory:=file:{fifo}"],
        "trajectory file {fifo}: cannot read it (not a regular file (a FIFO))",
    ),
    "sim chips": (
        ["backend:=sim", "sim_chips:=[pmw3360,otos]"],
        "'sim_chips' pmw3360,otos differ from 'chips' pln2033,pln2033: each device's driver",
    ),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(NODE_CASES))
def test_the_node_refuses_a_bad_value_at_start(case, files, tmp_path):
    pytest.importorskip("rclpy")
    params, says = NODE_CASES[case]
    port = free_port()
    (cwd := tmp_path / "cwd").mkdir()
    cmd = [sys.executable, "-m", "mm_beagle.node.node", "--ros-args"]
    for p in params:
        cmd += ["-p", p.format(port=port, **files)]
    out = _run(cmd, cwd)
    _refused(out, "mm-beagle: ", says.format(port=port, **files))
    assert "services under" not in out.stderr and list(cwd.iterdir()) == []


# --- mm-odometry's calibration file, mm-monitor's --duration -------------------------------


@pytest.mark.parametrize(("kind", "says"), [("fifo", "(a FIFO)"), ("zero", "(a character device)")])
def test_mm_odometry_refuses_a_calibration_that_is_no_regular_file(kind, says, files, tmp_path):
    pytest.importorskip("rclpy")
    path = files[kind]
    cmd = [sys.executable, "-m", "mm_pc.ros.odometry_node", "--ros-args", "-p",
           f"calibration_file:={path}"]  # fmt: skip
    out = _run(cmd, tmp_path)
    _refused(out, "mm-odometry: ", f"calibration file {path}: not a regular file {says}")


@pytest.mark.parametrize("kind", ["fifo", "zero"])
def test_a_params_file_that_is_no_regular_file_is_refused(kind, files, tmp_path):
    pytest.importorskip("rclpy")
    path = files[kind]
    cmd = [sys.executable, "-m", "mm_pc.ros.odometry_node", "--ros-args", "--params-file", path]
    _refused(_run(cmd, tmp_path), "mm-odometry: ", f"--params-file {path}: cannot read it (not a")


@pytest.mark.parametrize(
    ("value", "shown"), [("nan", "nan"), ("inf", "inf"), ("-1", "-1"), ("1e9", "1e+09")]
)
def test_mm_monitor_refuses_a_duration_out_of_range(value, shown, tmp_path):
    pytest.importorskip("PySide6")
    env = {"HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path / "config")}
    out = _run([sys.executable, "-m", "mm_pc.monitor.app", "--headless", "--duration", value],
               tmp_path, env)  # fmt: skip
    _refused(out, "mm-monitor: ", f"--duration must be 0..2000000 s (0 = never), got {shown}")


# --- the checks themselves ------------------------------------------------------------------


def test_user_files_are_read_only_when_regular_and_small(files, tmp_path):
    good = tmp_path / "good.yaml"
    good.write_text("a: 1\n")
    assert user_file.read_user_text(good) == "a: 1\n"
    for name, says in (("fifo", "(a FIFO)"), ("zero", "(a character device)"),
                       ("dir", "(a directory)"), ("big", "too large")):  # fmt: skip
        with pytest.raises(OSError) as err:
            user_file.read_user_bytes(files[name])
        assert says in err.value.strerror, name
    with pytest.raises(OSError, match="No such file"):
        user_file.read_user_bytes(tmp_path / "nope")
    assert user_file.read_user_bytes(good, limit=5) == b"a: 1\n"
    with pytest.raises(OSError, match=r"too large \(5 bytes; at most 4\)"):
        user_file.read_user_bytes(good, limit=4)


def test_link_checks_accept_what_zenoh_can_use(files):
    cert = files["bad"]  # any small regular file: only its kind is checked here
    assert link_checks.name_problem("mm_beagle") == ""
    assert link_checks.name_problem("robot-1.left_side") == ""
    assert "1..64" in link_checks.name_problem("x" * 65)
    assert "1..64" in link_checks.name_problem("")
    assert link_checks.endpoint_problem("tcp/127.0.0.1:7447", "listen") == ""
    assert link_checks.endpoint_problem("tcp/127.0.0.1:7447#iface=lo", "connect") == ""
    tls = f"tls/127.0.0.1:7447#listen_certificate_file={cert};listen_private_key_file={cert}"
    assert link_checks.endpoint_problem(tls, "listen") == ""
    assert "root CA" in link_checks.endpoint_problem(tls, "connect")
    ca = "quic/127.0.0.1:7447#root_ca_certificate_base64=QUJD"
    assert link_checks.endpoint_problem(ca, "connect") == ""
    assert "not key=value" in link_checks.endpoint_problem("tcp/1.2.3.4:1#iface", "connect")
    assert "not PROTO/HOST:PORT" in link_checks.endpoint_problem("nope", "listen")
