"""Our ROS processes stay on this machine without Fast DDS shared memory (issue 29 item 13:
a red ``[RTPS_TRANSPORT_SHM Error]`` line at the first start): the environment the harness
gives them, and the demo's two processes started for real."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from fakes import scaled

from mm_beagle.tools import harness
from mm_beagle.tools.harness import LOCALHOST_UDP_PROFILE, isolated_ros_env


@pytest.fixture
def clean_env(monkeypatch):
    for key in ("RMW_IMPLEMENTATION", "FASTRTPS_DEFAULT_PROFILES_FILE",
                "FASTDDS_DEFAULT_PROFILES_FILE", "ROS_LOCALHOST_ONLY",
                "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.delenv(key, raising=False)
    return monkeypatch


def test_fast_dds_gets_a_udp_localhost_profile_and_no_localhost_range(clean_env):
    clean_env.setenv("ROS_LOCALHOST_ONLY", "1")  # Jazzy maps it to LOCALHOST, with SHM
    env = isolated_ros_env()
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert "ROS_LOCALHOST_ONLY" not in env
    profile = Path(env["FASTRTPS_DEFAULT_PROFILES_FILE"])
    text = profile.read_text()
    assert text == LOCALHOST_UDP_PROFILE
    assert "<useBuiltinTransports>false</useBuiltinTransports>" in text  # no SHM
    assert "<type>UDPv4</type>" in text and "SHM" not in text
    assert "<interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>" in text
    clean_env.setenv("FASTRTPS_DEFAULT_PROFILES_FILE", str(profile))  # a child: kept
    assert isolated_ros_env()["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"


def test_a_stale_or_foreign_profile_text_is_rewritten(clean_env):
    path = Path(harness.localhost_profile_file())
    path.write_text("<profiles/>")
    assert harness.localhost_profile_file() == str(path)
    assert path.read_text() == LOCALHOST_UDP_PROFILE


@pytest.mark.parametrize("key,value", [
    ("RMW_IMPLEMENTATION", "rmw_cyclonedds_cpp"),
    ("FASTRTPS_DEFAULT_PROFILES_FILE", "/etc/my-fastdds.xml"),
    ("FASTDDS_DEFAULT_PROFILES_FILE", "/etc/my-fastdds.xml"),
])
def test_another_rmw_or_the_users_own_profile_keeps_the_localhost_range(clean_env, key, value):
    clean_env.setenv(key, value)
    env = isolated_ros_env()
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert env.get("FASTRTPS_DEFAULT_PROFILES_FILE", "") in ("", value)


def _shm_mappings(pid: int) -> list[str]:
    """The Fast DDS shared-memory files process ``pid`` has mapped."""
    try:
        maps = Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return []
    return sorted({ln.split()[-1] for ln in maps.splitlines() if "/dev/shm/fastrtps" in ln})


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(p) for p in text.split()]


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc maps")
def test_the_demos_processes_print_no_error_and_map_no_shared_memory(tmp_path, clean_env):
    pytest.importorskip("rclpy")
    pytest.importorskip("mm_interfaces")
    env = {**os.environ, "HOME": str(tmp_path)}  # a first start: no settings, no cache
    cmd = [sys.executable, "-m", "mm_pc.monitor.app", "--sim", "--headless",
           "--duration", "6", "--screenshot", str(tmp_path / "s.png")]
    proc = subprocess.Popen(cmd, env=env, cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    seen: dict[int, list[str]] = {}
    deadline = time.monotonic() + scaled(60)
    while proc.poll() is None and time.monotonic() < deadline:
        for pid in (proc.pid, *_children(proc.pid)):
            seen.setdefault(pid, []).extend(_shm_mappings(pid))
        time.sleep(0.2)
    out, err = proc.communicate(timeout=scaled(60))
    assert proc.returncode == 0, err
    assert "replies to" in out and "node log:" in out  # it started the node and talked to it
    assert len(seen) >= 2  # the monitor and its mm-beagle were both looked at
    assert not any(seen.values()), seen
    # what both processes printed (the node's log folder is removed after a good run)
    assert not [ln for ln in err.splitlines() if "Error" in ln or "RTPS_" in ln], err


def test_the_profile_lives_in_the_users_cache_not_in_the_temporary_folder(clean_env, tmp_path):
    """A run leaves nothing in /tmp (the fresh-machine check looks): the file is reused
    from ``$XDG_CACHE_HOME/mouse-monitor``; an unwritable cache falls back to /tmp."""
    import tempfile

    clean_env.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    path = Path(harness.localhost_profile_file())
    assert path.parent == tmp_path / "cache" / "mouse-monitor"
    assert path.read_text() == LOCALHOST_UDP_PROFILE
    assert not list(path.parent.glob("*.tmp"))
    (tmp_path / "blocked").write_text("a file where the folder would be")
    clean_env.setenv("XDG_CACHE_HOME", str(tmp_path / "blocked"))
    assert Path(harness.localhost_profile_file()).parent == Path(tempfile.gettempdir())
