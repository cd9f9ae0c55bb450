"""A program started where ROS 2 (or an extra) is missing says how to get it and exits 2,
never a traceback.

A pip install without ROS is emulated by a sitecustomize that blocks the ROS modules
(``sys.modules[name] = None`` makes their import fail as if they were absent), and, for the
real thing, by ``python -S`` (no site-packages at all) with only the work tree on the path.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from fakes import console_script

from mm_pc import prerequisites

ROOT = Path(__file__).resolve().parents[1]
BLOCKED = ["rclpy", "mm_interfaces", "tf2_msgs", "geometry_msgs", "nav_msgs", "sensor_msgs",
           "std_msgs", "diagnostic_msgs", "rcl_interfaces", "builtin_interfaces"]  # fmt: skip


def _run(args: list[str], tmp_path: Path, block: list[str]) -> subprocess.CompletedProcess:
    (tmp_path / "sitecustomize.py").write_text(
        f"import sys\nsys.modules.update(dict.fromkeys({block!r}))\n"
    )
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": f"{tmp_path}:{ROOT}", "HOME": str(tmp_path)}
    return subprocess.run(
        [sys.executable, *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60
    )


@pytest.mark.parametrize("command", ["mm-beagle", "mm-odometry", "mm-fusion", "mm-field-sim"])
def test_node_without_ros_exits_2_with_the_way_to_get_it(tmp_path, command):
    out = _run([console_script(command, tmp_path)], tmp_path, BLOCKED)
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert out.stderr.startswith(f"{command}: needs ROS 2 Jazzy")
    assert "./compile setup" in out.stderr and "/opt/ros/jazzy" in out.stderr


def test_watch_without_ros_fails_the_same_way_from_inside_main(tmp_path):
    out = _run([console_script("mm-watch", tmp_path)], tmp_path, BLOCKED)
    assert out.returncode == 2, out.stderr
    assert "rclpy is missing" in out.stderr and "Traceback" not in out.stderr


def test_missing_message_package_built_here_names_compile(tmp_path):
    out = _run([console_script("mm-odometry", tmp_path)], tmp_path, ["mm_interfaces"])
    assert out.returncode == 2, out.stderr
    assert "the message package mm_interfaces, which ./compile builds" in out.stderr


def test_other_missing_modules_keep_their_traceback(tmp_path):
    out = _run([console_script("mm-fusion", tmp_path)], tmp_path, ["numpy"])
    assert out.returncode == 1
    assert "Traceback" in out.stderr and "numpy" in out.stderr


def test_without_any_site_packages(tmp_path):
    env = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT), "HOME": str(tmp_path)}
    out = subprocess.run(
        [sys.executable, "-S", console_script("mm-beagle", tmp_path)], cwd=tmp_path, env=env,
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 2, out.stderr
    assert "needs ROS 2 Jazzy (rclpy is missing)" in out.stderr


def test_importing_a_package_installs_no_hook(tmp_path):
    """A notebook's ``import mm_pc.core.odometry`` leaves sys.excepthook alone; the console
    scripts' launchers install it."""
    code = (
        "import sys\nbefore = sys.excepthook\nimport mm_pc.core.odometry, mm_beagle, pln2033\n"
        "assert sys.excepthook is before\nfrom mm_pc.commands import mm_odometry\n"
        "print('ok')\n"
    )
    out = _run(["-c", code], tmp_path, [])
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_ros_module_names():
    assert prerequisites.is_ros_module("rclpy.node")
    assert prerequisites.is_ros_module("std_srvs")
    assert prerequisites.is_ros_module("mm_interfaces.msg")
    assert not prerequisites.is_ros_module("numpy")
    assert not prerequisites.is_ros_module(None)


def test_monitor_without_the_monitor_extra_names_it(tmp_path):
    out = _run([console_script("mm-monitor", tmp_path), "--headless", "--duration", "1"], tmp_path,
               ["PySide6", "shiboken6"])  # fmt: skip
    assert out.returncode == 2, out.stderr
    assert out.stderr.startswith("mm-monitor: needs PySide6, from the 'monitor' extra")
    assert "pip install '.[monitor]'" in out.stderr and "Traceback" not in out.stderr


def test_messages_for_what_is_neither_ros_nor_an_extra():
    assert prerequisites.message("x", "numpy") is None
    assert "'beagle' extra" in prerequisites.message("mm-beagle", "spidev")


def test_ctrl_c_wrapped_by_a_class_body_is_still_a_clean_stop(tmp_path):
    """SIGINT while a dataclass is being built (a node still importing) reaches the hook as
    a RuntimeError caused by the KeyboardInterrupt: a stop, exit 0, no traceback."""
    code = (
        "from mm_pc import prerequisites\n"
        "prerequisites.install()\n"
        "try:\n"
        "    raise KeyboardInterrupt\n"
        "except KeyboardInterrupt as e:\n"
        "    raise RuntimeError(\"Error calling __set_name__ on 'Field'\") from e\n"
    )
    out = _run(["-c", code], tmp_path, [])
    assert out.returncode == 0, out.stderr
    assert "stopped by Ctrl-C" in out.stderr and "Traceback" not in out.stderr
    code = "from mm_pc import prerequisites\nprerequisites.install()\nraise RuntimeError('boom')"
    other = _run(["-c", code], tmp_path, [])
    assert other.returncode == 1 and "RuntimeError: boom" in other.stderr  # not a Ctrl-C


# --- a system library missing at import time (tools/system-packages.txt) -------------------


def test_the_package_list_maps_the_qt_libraries_to_their_debian_packages():
    packages = prerequisites.library_packages()
    assert packages["libEGL.so.1"] == "libegl1"
    assert packages["libglib-2.0.so.0"] == "libglib2.0-0"  # not Ubuntu 24.04's ...t64
    assert packages["libxcb-cursor.so.0"] == "libxcb-cursor0"
    needs = {need for _pkg, need, _so in prerequisites.system_packages()}
    assert needs == {"setup", "headless", "window", "test"}


def test_a_malformed_package_list_names_the_line(tmp_path):
    bad = tmp_path / "system-packages.txt"
    bad.write_text("# comment\npython3 setup\nlibegl1 libEGL.so.1\n")
    with pytest.raises(ValueError, match="line 3: expected 'PACKAGE NEED"):
        prerequisites.system_packages(bad)


def test_the_soname_is_read_from_the_loaders_message():
    err = ImportError("libEGL.so.1: cannot open shared object file: No such file or directory")
    assert prerequisites.missing_library(err) == "libEGL.so.1"
    assert prerequisites.missing_library(ImportError("No module named 'x'")) is None
    text = prerequisites.library_message("mm-monitor", "libEGL.so.1", ["libxcb-icccm.so.4"])
    assert "the system library libEGL.so.1 is missing (and 1 more" in text
    assert "sudo apt-get install libegl1 libxcb-icccm4\n" in text
    unknown = prerequisites.library_message("mm-monitor", "libweird.so.3", [])
    assert "apt-file search libweird.so.3" in unknown and "apt-get" not in unknown.split("\n")[1]
    assert "source install/setup.bash" in prerequisites.library_message("mm-beagle", "librcl.so")


def test_ldd_not_found_lines_are_the_missing_libraries():
    ldd = "x.so:\n\tlibEGL.so.1 => not found\n\tlibc.so.6 => /lib/libc.so.6 (0x7f)\n"
    assert prerequisites.unresolved([], ldd) == ["libEGL.so.1"]


@pytest.mark.parametrize("command", ["mm-monitor", "mm-bench"])
def test_monitor_whose_qt_cannot_load_a_library_names_the_package(tmp_path, command):
    """PySide6 importing on a bare Debian: the loader's ImportError becomes the apt-get line."""
    fake = tmp_path / "PySide6"
    fake.mkdir()
    (fake / "__init__.py").write_text(
        "raise ImportError('libEGL.so.1: cannot open shared object file: No such file or "
        "directory')\n"
    )
    args = ["gui", "--frames", "1"] if command == "mm-bench" else ["--headless", "--duration", "1"]
    out = _run([console_script(command, tmp_path), *args], tmp_path, [])
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert "the system library libEGL.so.1 is missing" in out.stderr
    assert "sudo apt-get install libegl1" in out.stderr


def test_qt_platform_report_over_every_qt_file_and_its_usage():
    from mm_pc.monitor import qt_platform

    assert qt_platform.main(["--bogus"]) == 2
    files = prerequisites.qt_files()
    assert any(f.name == "libqxcb.so" for f in files)  # the window's plugin is among them
    assert any(f.name == "libqoffscreen.so" for f in files)
