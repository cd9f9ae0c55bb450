"""colcon builds the ROS packages mm_beagle and mm_pc, and what it installs runs.

What a system-ROS user does (`colcon build` over the repository, with and without
`--symlink-install`), here against the venv's ament index: colcon-core/colcon-ros come
from PyPI (the `test` extra), mm_interfaces is ./compile's CMake build on
AMENT_PREFIX_PATH (hence --packages-ignore). Everything goes to tmp_path (build, install
and log bases): the work tree is left as it was. `colcon test` runs a package's tests.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("colcon_core")
pytest.importorskip("colcon_ros")
pytest.importorskip("rclpy")

ROOT = Path(__file__).resolve().parents[1]
PY = "python3.11"  # the venv's; only the site-packages folder name depends on it


def _git_status() -> str:
    return subprocess.run(
        ["git", "status", "--porcelain", "--ignored"], cwd=ROOT, capture_output=True,
        text=True, timeout=30, check=True,
    ).stdout  # fmt: skip


def _scripts() -> dict[str, str]:
    text = (ROOT / "pyproject.toml").read_text()
    body = re.search(r"^\[project\.scripts\]\n(.*?)(?=^\[)", text, re.M | re.S).group(1)
    return {n: t.partition(".")[0] for n, t in re.findall(r'^([\w-]+) = "([\w.:]+)"', body, re.M)}


def compile_colcon_args(tmp: Path) -> list[str]:
    """The colcon arguments `./compile mm_b` uses on a system ROS (its MM_COMPILE_PLAN
    output, with a fake MM_SYSTEM_ROS), with its build, install and log bases moved to tmp."""
    (tmp / "ros").mkdir()
    (tmp / "ros" / "setup.bash").write_text("")
    env = {**os.environ, "MM_SYSTEM_ROS": str(tmp / "ros"), "MM_COMPILE_PLAN": "1"}
    out = subprocess.run(
        ["bash", str(ROOT / "compile"), "mm_b"], capture_output=True, text=True, timeout=60,
        env=env,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    (line,) = [x for x in out.stdout.splitlines() if x.startswith("ros packages: colcon ")]
    args = line.removeprefix("ros packages: colcon ").split()
    moved = {"--log-base": "log", "--build-base": "build", "--install-base": "install"}
    for i, arg in enumerate(args[:-1]):
        if arg in moved:
            assert args[i + 1].startswith((f"{ROOT}/build/", f"{ROOT}/install/")), args[i + 1]
            args[i + 1] = str(tmp / moved[arg])
    return args


@pytest.fixture(scope="module", params=["copy", "symlink"])
def colcon_install(request, tmp_path_factory):
    """One colcon build of the repository into a temporary folder, with the arguments
    ./compile uses, plain ("copy") and with --symlink-install ("symlink"): (install base,
    log text). The mode is ``request.param``; the tmp folder holds build/ beside install/."""
    assert (ROOT / "install" / "COLCON_IGNORE").is_file(), (
        "./compile marks install/ COLCON_IGNORE (else colcon crawls the venv): run ./compile setup"
    )
    assert "mm_interfaces" in os.environ.get("AMENT_PREFIX_PATH", ""), "source install/setup.bash"
    tmp = tmp_path_factory.mktemp("colcon")
    before = _git_status()
    colcon = shutil.which("colcon")
    assert colcon, "colcon is not on PATH (the test extra installs it)"
    cmd = [colcon, *compile_colcon_args(tmp)]
    if request.param == "symlink":
        cmd.append("--symlink-install")
    out = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert _git_status() == before, "colcon build changed the work tree"
    log = (tmp / "log" / "latest_build" / "logger_all.log").read_text()
    return tmp / "install", log


def test_colcon_finds_exactly_the_three_ros_packages(colcon_install):
    _install, log = colcon_install
    found = re.findall(r"Package '[^']+' with type '([\w.]+)' and name '(\w+)'", log)
    assert {name: kind for kind, name in found} == {
        "mm_beagle": "ros.ament_python",
        "mm_pc": "ros.ament_python",
        "mm_interfaces": "ros.ament_cmake",  # vendor/tf2_msgs stays COLCON_IGNOREd
    }


@pytest.mark.parametrize("pkg", ["mm_beagle", "mm_pc"])
def test_installed_tree_has_what_ros2_run_and_launch_look_for(colcon_install, pkg):
    install, _log = colcon_install
    prefix = install / pkg
    share = prefix / "share" / pkg
    assert (prefix / "share/ament_index/resource_index/packages" / pkg).is_file()
    assert (share / "package.xml").read_bytes() == (ROOT / pkg / "package.xml").read_bytes()
    for sub in ("launch", "config"):
        source = sorted(p.name for p in (ROOT / pkg / sub).iterdir() if p.is_file())
        assert source and sorted(p.name for p in (share / sub).iterdir()) == source
    expected = sorted(n for n, top in _scripts().items() if top == pkg)
    assert sorted(p.name for p in (prefix / "lib" / pkg).iterdir()) == expected
    site = prefix / "lib" / PY / "site-packages"
    if _mode(install) == "symlink":
        # the share files link to the work tree; the packages are links in the build folder
        # (on the install's PYTHONPATH), nothing copied into site-packages
        first = sorted(os.listdir(share / "launch"))[0]
        assert (share / "launch" / first).resolve() == ROOT / pkg / "launch" / first
        build = install.parent / "build" / pkg
        tops = {pkg, "pln2033"} if pkg == "mm_pc" else {pkg}
        for top in tops:
            assert (build / top).is_symlink() and (build / top).resolve() == ROOT / top
        assert not (site / pkg).exists()
        return
    assert (site / pkg / "__init__.py").is_file()
    assert not (site / pkg / "setup.py").exists()  # the build file is not a module
    assert (site / pkg / "config").is_dir()
    assert (site / "pln2033" / "pln2033" / "default_regmap.yaml").is_file() == (pkg == "mm_pc")


def _mode(install: Path) -> str:
    """How colcon installed: "symlink" (--symlink-install: develop, an egg-link) or "copy"."""
    site = install / "mm_pc" / "lib" / PY / "site-packages"
    return "symlink" if (site / "mm-pc.egg-link").is_file() else "copy"


def _in_colcon_env(install: Path, script: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", "-c", f'source "{install}/setup.bash" && {script}'], cwd=cwd,
        capture_output=True, text=True, timeout=90,
    )  # fmt: skip


def test_installed_packages_are_found_by_the_ament_index(colcon_install, tmp_path):
    install, _log = colcon_install
    probe = (
        "from ament_index_python.packages import get_package_prefix, get_package_share_directory\n"
        "import mm_beagle, mm_pc, pln2033\n"
        "print(get_package_share_directory('mm_beagle'))\n"
        "print(get_package_prefix('mm_pc'))\n"
        "print(mm_beagle.__file__)\nprint(pln2033.__file__)\n"
    )
    (tmp_path / "probe.py").write_text(probe)
    out = _in_colcon_env(install, "python probe.py", tmp_path)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.split()
    assert lines[0] == str(install / "mm_beagle/share/mm_beagle")
    assert lines[1] == str(install / "mm_pc")
    if _mode(install) == "copy":  # the copy, not the work tree (nor the venv's pip install)
        assert lines[2].startswith(str(install / "mm_beagle/lib"))
        assert lines[3].startswith(str(install / "mm_pc/lib"))
    else:  # the build folder's links to the work tree
        assert lines[2] == str(install.parent / "build/mm_beagle/mm_beagle/__init__.py")
        assert lines[3] == str(install.parent / "build/mm_pc/pln2033/__init__.py")
        assert Path(lines[2]).resolve() == ROOT / "mm_beagle" / "__init__.py"


@pytest.mark.parametrize(
    ("pkg", "exe", "bad", "word"),
    [
        ("mm_beagle", "mm-beagle", "cpi:=7", "cpi"),
        ("mm_pc", "mm-odometry", "rate:=0.0", "rate"),
    ],
)
def test_installed_executable_refuses_a_bad_parameter(
    colcon_install, tmp_path, pkg, exe, bad, word
):
    install, _log = colcon_install
    from mm_beagle.tools.harness import isolated_ros_env

    env_prefix = " ".join(
        f"{k}={v}" for k, v in isolated_ros_env().items() if k.startswith(("ROS_", "MM_"))
    )
    out = _in_colcon_env(
        install, f'env {env_prefix} "{install}/{pkg}/lib/{pkg}/{exe}" --ros-args -p {bad}', tmp_path
    )
    assert out.returncode == 2, out.stdout + out.stderr
    assert word in out.stderr and "Traceback" not in out.stderr


def test_installed_monitor_answers_help(colcon_install, tmp_path):
    install, _log = colcon_install
    out = _in_colcon_env(install, f'"{install}/mm_pc/lib/mm_pc/mm-monitor" --help', tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("usage: mm-monitor")


def test_setup_py_is_inert_when_imported_from_the_pip_wheel(tmp_path):
    """pip's wheel carries mm_beagle/setup.py as a module; importing it builds nothing."""
    for module in ("mm_beagle.setup", "mm_pc.setup"):
        out = subprocess.run(
            [sys.executable, "-c", f"import {module}"], cwd=tmp_path, capture_output=True,
            text=True, timeout=60,
        )  # fmt: skip
        assert out.returncode == 0 and out.stdout == "" and out.stderr == "", out


HAVE_LAUNCH = all(importlib.util.find_spec(m) for m in ("launch", "launch_ros"))
RUN_ROBOT = """
import sys
import launch
from ament_index_python.packages import get_package_share_directory
from launch.actions import IncludeLaunchDescription, Shutdown, TimerAction
from launch.launch_description_sources import PythonLaunchDescriptionSource

robot = get_package_share_directory("mm_beagle") + "/launch/robot.launch.py"
service = launch.LaunchService(argv=[])
service.include_launch_description(launch.LaunchDescription([
    IncludeLaunchDescription(PythonLaunchDescriptionSource(robot),
                             launch_arguments={"backend": "sim"}.items()),
    TimerAction(period=10.0, actions=[Shutdown(reason="test over")]),
]))
sys.exit(service.run())
"""


@pytest.mark.skipif(not HAVE_LAUNCH, reason="launch/launch_ros not installed (no PyPI wheel)")
def test_robot_launch_runs_the_chain_from_the_colcon_install(colcon_install, tmp_path):
    """What `ros2 launch mm_beagle robot.launch.py backend:=sim` does, for 10 s."""
    from mm_beagle.tools.harness import isolated_ros_env

    install, _log = colcon_install
    (tmp_path / "run.py").write_text(RUN_ROBOT)
    env = " ".join(f"{k}={v}" for k, v in isolated_ros_env().items() if k.startswith("ROS_"))
    out = _in_colcon_env(install, f"env {env} python run.py", tmp_path)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    text = out.stdout + out.stderr
    for exe in ("mm-beagle", "mm-odometry", "mm-fusion"):
        assert re.search(rf"\[{exe}-\d+\]: process started", text), exe
        assert re.search(rf"\[{exe}-\d+\]: process has finished cleanly", text), exe
    accepted = re.search(r"mouse: accepted (\d+)", text)  # fusion heard odometry from beagle
    assert accepted and int(accepted.group(1)) > 0, text[-2000:]


def test_colcon_test_runs_the_package_tests(colcon_install, tmp_path):
    """`colcon test` on each build: pytest in the package folder against the install, here
    only tests/sim (--pytest-args; by default setup.cfg's testpaths, which
    tests/test_ros_package_xml.py checks)."""
    install, _log = colcon_install
    base = install.parent
    cmd = [
        shutil.which("colcon"), "--log-base", str(tmp_path / "log"), "test",
        "--base-paths", str(ROOT), "--packages-ignore", "mm_interfaces",
        "--packages-select", "mm_pc",
        "--build-base", str(base / "build"), "--install-base", str(install),
        "--pytest-args", "../tests/sim", "-p", "no:cacheprovider",
    ]  # fmt: skip
    out = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    report = (base / "build" / "mm_pc" / "pytest.xml").read_text()
    suite = re.search(r"<testsuite [^>]*>", report).group(0)
    counts = {k: int(v) for k, v in re.findall(r'(tests|failures|errors)="(\d+)"', suite)}
    collected = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
         "tests/sim"], cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    want = int(re.search(r"(\d+) tests? collected", collected.stdout).group(1))
    assert counts == {"tests": want, "failures": 0, "errors": 0}, suite
    assert want > 0 and 'classname="mm_pc.' in report  # colcon's --junit-prefix


@pytest.mark.skipif(not HAVE_LAUNCH, reason="launch/launch_ros not installed (no PyPI wheel)")
def test_robot_launch_runs_from_compiles_own_ament_index(tmp_path):
    """After ./compile alone (no colcon): `ros2 launch mm_beagle robot.launch.py` finds the
    package, its launch files and executables in the venv's ament index."""
    from mm_beagle.tools.harness import isolated_ros_env

    (tmp_path / "run.py").write_text(RUN_ROBOT)
    env = isolated_ros_env()  # this environment, with a private ROS domain
    out = subprocess.run(
        [sys.executable, "run.py"], cwd=tmp_path, env=env, capture_output=True, text=True,
        timeout=90,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    text = out.stdout + out.stderr
    for exe in ("mm-beagle", "mm-odometry", "mm-fusion"):
        assert re.search(rf"\[{exe}-\d+\]: process started", text), exe
        assert re.search(rf"\[{exe}-\d+\]: process has finished cleanly", text), exe
    accepted = re.search(r"mouse: accepted (\d+)", text)
    assert accepted and int(accepted.group(1)) > 0, text[-2000:]
