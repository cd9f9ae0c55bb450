"""./compile's choice of set-up path: colcon for mm_b/mm_p only where a system ROS is.

No machine here has /opt/ros/jazzy, so MM_SYSTEM_ROS points at a fake one (a folder with a
setup.bash) and MM_COMPILE_PLAN=1 makes compile say what it would do, without doing it
(a real run would rebuild install/venv for the system ROS).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def plan(verb: str, system_ros: Path, path: str | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, "MM_SYSTEM_ROS": str(system_ros), "MM_COMPILE_PLAN": "1"}
    if path is not None:
        env["PATH"] = path
    return subprocess.run(
        [shutil.which("bash"), str(ROOT / "compile"), verb], capture_output=True, text=True,
        timeout=60, env=env,
    )  # fmt: skip


@pytest.fixture
def fake_ros(tmp_path):
    ros = tmp_path / "jazzy"
    ros.mkdir()
    (ros / "setup.bash").write_text("# fake system ROS\n")
    return ros


@pytest.fixture
def colcon_on_path(tmp_path):
    """A PATH with a (never run) colcon on it, so the plan does not depend on the test extra."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "colcon").write_text("#!/bin/sh\nexit 99\n")
    (bin_dir / "colcon").chmod(0o755)
    return f"{bin_dir}:/usr/bin:/bin"


@pytest.mark.parametrize(("verb", "extras"), [("mm_b", "beagle"), ("mm_p", "monitor")])
def test_with_a_system_ros_mm_b_and_mm_p_build_with_colcon(fake_ros, colcon_on_path, verb, extras):
    out = plan(verb, fake_ros, colcon_on_path)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == f"ros: system ROS at {fake_ros} (venv with --system-site-packages)"
    assert f"python: pip install -e .[{extras}]" in lines
    (colcon,) = [line for line in lines if line.startswith("ros packages: colcon")]
    assert f"--base-paths {ROOT} " in colcon
    assert "--packages-ignore mm_interfaces --packages-select mm_pc mm_beagle " in colcon
    assert f"--install-base {ROOT}/install/ros" in colcon
    assert f"--build-base {ROOT}/build/colcon" in colcon


def test_without_a_system_ros_mm_b_keeps_the_wheel_path(tmp_path, colcon_on_path):
    out = plan("mm_b", tmp_path / "nothing-here", colcon_on_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("ros: no system ROS at")
    assert "colcon" not in out.stdout


def test_full_setup_never_uses_colcon(fake_ros, colcon_on_path):
    out = plan("setup", fake_ros, colcon_on_path)
    assert out.returncode == 0, out.stderr
    assert "python: pip install -e .[beagle,monitor,test]" in out.stdout
    assert "colcon" not in out.stdout


def test_system_ros_without_colcon_names_the_debian_package(fake_ros, tmp_path):
    bin_dir = tmp_path / "no-colcon"
    bin_dir.mkdir()
    for tool in ("dirname", "tr"):  # what the plan needs; a real /usr/bin may have colcon
        (bin_dir / tool).symlink_to(shutil.which(tool))
    out = plan("mm_b", fake_ros, str(bin_dir))
    assert out.returncode == 1
    assert "apt-get install python3-colcon-common-extensions" in out.stderr
    assert "Traceback" not in out.stderr


def test_pyprojects_ros_extra_pins_what_compile_installs():
    """The `ros` extra (for pip users) and compile's ROS_WHEELS cannot drift apart."""
    import re

    text = (ROOT / "pyproject.toml").read_text()
    extra = re.search(r"^ros = \[\n(.*?)^\]", text, re.M | re.S).group(1)
    pins = re.findall(r'"([^"]+)"', extra)
    wheels = re.search(r"^ROS_WHEELS=\(\n(.*?)^\)", (ROOT / "compile").read_text(), re.M | re.S)
    installed = re.findall(r'"([^"]+)"', wheels.group(1))
    assert pins and "ros-jazzy-rclpy[fastrtps]==7.1.*" in pins
    assert set(pins) <= set(installed), set(pins) - set(installed)
