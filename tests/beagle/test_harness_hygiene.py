"""Children of the harness stop with their parent whatever dispositions they inherit;
a user's ROS_DOMAIN_ID is respected; the private domain range is the safe one."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import psutil
import pytest
from fakes import scaled, wait_until

from mm_beagle.tools import harness
from mm_beagle.tools.harness import ISOLATED_DOMAINS, ISOLATED_MARK, isolated_ros_env


def test_a_users_domain_id_is_kept(monkeypatch):
    monkeypatch.delenv(ISOLATED_MARK, raising=False)
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    env = isolated_ros_env()
    assert env["ROS_DOMAIN_ID"] == "42" and env[ISOLATED_MARK] == "42"
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"  # limited to 127.0.0.1 by:
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == harness.localhost_profile_file()


def test_without_one_the_private_domain_is_in_1_to_101(monkeypatch):
    monkeypatch.delenv(ISOLATED_MARK, raising=False)
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    assert range(1, 102) == ISOLATED_DOMAINS
    ids = {int(isolated_ros_env()["ROS_DOMAIN_ID"]) for _ in range(300)}
    assert min(ids) >= 1 and max(ids) <= 101 and len(ids) > 50
    monkeypatch.setenv("ROS_DOMAIN_ID", "")  # set but empty: none
    assert 1 <= int(isolated_ros_env()["ROS_DOMAIN_ID"]) <= 101
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")  # the test suite's choice: never the user's
    picked = {isolated_ros_env(keep_user_domain=False)["ROS_DOMAIN_ID"] for _ in range(20)}
    assert picked != {"42"}


PARENT = textwrap.dedent(
    """
    import signal, sys, time
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # what `nohup ... &` hands down
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sys.path.insert(0, {root!r})
    from mm_beagle.tools.harness import _child
    cmd = [sys.executable, "-c", "import time; print('child up', flush=True); time.sleep(120)"]
    with _child(cmd, {{}}, {log!r}) as proc:
        print(proc.pid, flush=True)
        time.sleep(120)
    """
)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux")
def test_a_child_stops_when_its_parent_with_sigint_ignored_is_killed(tmp_path):
    root = os.path.dirname(os.path.dirname(harness.__file__))
    log = str(tmp_path / "child.log")
    parent = subprocess.Popen(
        [sys.executable, "-c", PARENT.format(root=root, log=log)],
        stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    child = None
    try:
        child = psutil.Process(int(parent.stdout.readline()))
        wait_until(lambda: "child up" in Path(log).read_text(), 60, "the child's 'child up' line")
        assert child.is_running()
        parent.send_signal(signal.SIGKILL)
        parent.wait(scaled(30))
        _, alive = psutil.wait_procs([child], timeout=scaled(30))
        assert not alive, "the child outlived its SIGKILLed parent"
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait(scaled(30))
        if child is not None and child.is_running():
            child.kill()


NODE_PARENT = textwrap.dedent(
    """
    import signal, sys, time
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # what `nohup ... &` hands down
    sys.path.insert(0, {root!r})
    from mm_beagle.tools.harness import beagle_process, isolated_ros_env
    params = {{"backend": "sim", "devices": ["/dev/spidev1.0"]}}
    with beagle_process(params, isolated_ros_env(), {log!r}, namespace="/orphan") as proc:
        print(proc.pid, flush=True)
        time.sleep(120)
    """
)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux")
@pytest.mark.parametrize("when", ["starting", "polling"])
def test_a_real_node_and_its_poller_stop_when_a_nohup_parent_is_killed(when, tmp_path):
    """The issue's case: a monitor in the background dies; its mm-beagle must not stay.
    ``starting``: the parent dies while the node still imports rclpy (before the node's
    own SIGINT handler: an inherited SIG_IGN would swallow the parent-death signal)."""
    root = os.path.dirname(os.path.dirname(harness.__file__))
    log = tmp_path / "node.log"
    parent = subprocess.Popen(
        [sys.executable, "-c", NODE_PARENT.format(root=root, log=str(log))],
        stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    procs: list[psutil.Process] = []
    try:
        node = psutil.Process(int(parent.stdout.readline()))
        procs = [node]
        if when == "polling":
            wait_until(node.children, 60, "the node's poller process", interval=0.1)
            procs += node.children(recursive=True)
            assert len(procs) >= 2, log.read_text()
        else:
            time.sleep(0.3)  # on purpose: the parent dies while the node still starts
        parent.send_signal(signal.SIGKILL)
        parent.wait(scaled(30))
        time.sleep(1.0)  # anything the node starts meanwhile is found and watched too
        with contextlib.suppress(psutil.Error):
            procs += node.children(recursive=True)
        _, alive = psutil.wait_procs(procs, timeout=scaled(30))
        assert not alive, f"still running after the parent's SIGKILL: {alive}"
        assert "Traceback" not in log.read_text()
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait(scaled(30))
        for p in procs:
            with contextlib.suppress(psutil.Error):
                p.kill()
