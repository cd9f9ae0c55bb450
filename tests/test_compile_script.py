"""The compile script: its verbs, and clear errors for missing prerequisites."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COMPILE = ROOT / "compile"


def run(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(COMPILE), *args], capture_output=True, text=True, timeout=60, env=env
    )


def test_help_lists_every_verb():
    out = run("help")
    assert out.returncode == 0
    for verb in ("demo", "test", "bench", "setup", "mm_b", "mm_p", "clean", "help"):
        assert f"\n  {verb}" in out.stdout


def test_unknown_verb_fails_with_usage():
    out = run("frobnicate")
    assert out.returncode != 0
    assert "unknown verb 'frobnicate'" in out.stderr
    assert "usage: ./compile" in out.stderr


def _path_without(tmp_path: Path, missing: set[str]) -> dict[str, str]:
    """A PATH holding only the tools the script needs, minus ``missing``."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    tools = [
        "python3",
        "cmake",
        "cc",
        "c++",
        "make",
        "sha256sum",
        "cut",
        "cat",
        "dirname",
        "uname",
        "grep",
        "sed",
        "xargs",
        "nproc",
        "rm",
        "mkdir",
    ]
    for tool in tools:
        found = shutil.which(tool)
        if tool not in missing and found:
            (bin_dir / tool).symlink_to(found)
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "MM_PYTHON")}
    env["PATH"] = str(bin_dir)
    return env


@pytest.mark.parametrize(
    ("missing", "message"),
    [
        ({"cmake"}, "apt-get install cmake"),
        ({"cc"}, "apt-get install build-essential"),
        ({"c++"}, "apt-get install build-essential"),
        ({"python3"}, "no supported python3 (3.10-3.13)"),
    ],
)
def test_missing_prerequisite_is_named(tmp_path, missing, message):
    env = _path_without(tmp_path, missing)
    out = subprocess.run(
        [shutil.which("bash"), str(COMPILE), "setup"],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert out.returncode != 0
    assert message in out.stderr
    # nothing was built or changed
    assert "creating the virtual environment" not in out.stderr


# --- the system package check (tools/system-packages.txt) ---------------------------------
# compile and the package list are copied to tmp_path (build/ lands there); fake dpkg-query,
# apt-cache, apt-get, sudo and id on PATH record what would run. No python3 is on that PATH,
# so a set-up that gets past the check stops right after it ("no supported python3", exit 1).

PACKAGES = """\
# test list
python3        setup
cmake          setup     # a comment
libglib2.0-0|libglib2.0-0t64  headless  libglib-2.0.so.0
libegl1        headless  libEGL.so.1
libxcb-icccm4  window    libxcb-icccm.so.4
"""

FAKES = {
    # installed: every name not in $FAKE_MISSING (spaces around each name)
    "dpkg-query": """for p in "$@"; do case "$p" in -*) ;; *)
        case " $FAKE_MISSING " in *" $p "*) ;; *) printf '%s:ii  ' "$p" ;; esac ;; esac; done""",
    "apt-cache": 'case " $FAKE_APT_KNOWS " in *" $2 "*) exit 0 ;; *) exit 100 ;; esac',
    "apt-get": 'echo "apt-get $*" >> "$FAKE_LOG"; exit "${FAKE_APT_EXIT:-0}"',
    "sudo": """if [ "$1" = -n ]; then exit "${FAKE_SUDO_N:-0}"; fi
        echo "sudo $1 $2" >> "$FAKE_LOG"; exec "$@\"""",
    "id": 'echo "${FAKE_UID:-0}"',
}


def _package_check(tmp_path: Path, verb: str = "setup", packages: str = PACKAGES,
                   fakes: tuple[str, ...] = tuple(FAKES), **env: str):  # fmt: skip
    """Run ``compile VERB`` with the fakes; (completed process, the fakes' log lines)."""
    root = tmp_path / "repo"
    (root / "tools").mkdir(parents=True)
    shutil.copy(COMPILE, root / "compile")
    (root / "tools" / "system-packages.txt").write_text(packages)
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("dirname", "env", "mkdir", "tail", "cat"):
        (bin_dir / tool).symlink_to(shutil.which(tool))
    for name in fakes:
        (bin_dir / name).write_text("#!/bin/bash\n" + FAKES[name] + "\n")
        (bin_dir / name).chmod(0o755)
    log = tmp_path / "fakes.log"
    log.touch()
    full_env = {"PATH": str(bin_dir), "HOME": str(tmp_path), "FAKE_LOG": str(log), **env}
    out = subprocess.run(
        [shutil.which("bash"), str(root / "compile"), verb], capture_output=True, text=True,
        timeout=60, env=full_env, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    return out, log.read_text().splitlines()


def test_root_installs_every_missing_package_at_once(tmp_path):
    out, calls = _package_check(
        tmp_path, FAKE_MISSING="libegl1 libglib2.0-0 libglib2.0-0t64 libxcb-icccm4",
        FAKE_APT_KNOWS="libglib2.0-0t64",  # Ubuntu 24.04: the old name is only virtual
    )
    assert calls == [
        "apt-get -q -o DPkg::Lock::Timeout=300 update",
        "apt-get -q -o DPkg::Lock::Timeout=300 install -y libglib2.0-0t64 libegl1 libxcb-icccm4",
    ]
    assert "installed: libglib2.0-0t64 libegl1 libxcb-icccm4" in out.stderr
    assert out.returncode == 1 and "no supported python3" in out.stderr  # went on


def test_only_the_test_verb_installs_the_test_packages(tmp_path):
    packages = PACKAGES + "xvfb  test\n"
    _out, calls = _package_check(tmp_path / "s", "setup", packages, FAKE_MISSING="cmake xvfb")
    assert calls[-1].endswith("install -y cmake")
    _out, calls = _package_check(tmp_path / "t", "test", packages, FAKE_MISSING="cmake xvfb")
    assert calls[-1].endswith("install -y cmake xvfb")


def test_a_user_with_sudo_gets_the_one_line_and_sudo_runs_it(tmp_path):
    out, calls = _package_check(tmp_path, FAKE_UID="1000", FAKE_MISSING="cmake libegl1")
    assert "running:  sudo apt-get install cmake libegl1" in out.stderr
    assert calls == [
        "sudo env DEBIAN_FRONTEND=noninteractive",
        "apt-get -q -o DPkg::Lock::Timeout=300 update",
        "sudo env DEBIAN_FRONTEND=noninteractive",
        "apt-get -q -o DPkg::Lock::Timeout=300 install -y cmake libegl1",
    ]
    assert out.returncode == 1 and "no supported python3" in out.stderr


def test_sudo_that_needs_a_password_without_a_terminal_stops_with_the_line(tmp_path):
    out, calls = _package_check(tmp_path, FAKE_UID="1000", FAKE_SUDO_N="1",
                                FAKE_MISSING="libxcb-icccm4")  # fmt: skip
    assert out.returncode == 2 and calls == []
    assert "run:  sudo apt-get install libxcb-icccm4" in out.stderr
    assert "MM_SKIP_SYSTEM_PACKAGES=1" in out.stderr


def test_no_sudo_stops_with_the_root_command(tmp_path):
    fakes = ("dpkg-query", "apt-cache", "apt-get", "id")
    out, calls = _package_check(tmp_path, fakes=fakes, FAKE_UID="1000", FAKE_MISSING="cmake")
    assert out.returncode == 2 and calls == []
    assert "there is no sudo" in out.stderr and "apt-get install cmake" in out.stderr


def test_apt_failing_stops_with_exit_2(tmp_path):
    out, calls = _package_check(tmp_path, FAKE_MISSING="cmake", FAKE_APT_EXIT="100")
    assert out.returncode == 2 and calls == ["apt-get -q -o DPkg::Lock::Timeout=300 update"]
    assert "apt-get could not install them" in out.stderr and "install cmake" in out.stderr


def test_nothing_missing_installs_nothing(tmp_path):
    out, calls = _package_check(tmp_path)
    assert calls == [] and "system packages" not in out.stderr
    assert out.returncode == 1 and "no supported python3" in out.stderr


def test_the_sensor_node_verb_checks_only_the_set_up_packages(tmp_path):
    out, calls = _package_check(tmp_path, verb="mm_b", FAKE_MISSING="libegl1 libxcb-icccm4")
    assert calls == [] and out.returncode == 1
    _out, calls = _package_check(tmp_path / "2", verb="mm_b", FAKE_MISSING="cmake libegl1")
    assert calls[-1].endswith("install -y cmake")


def test_the_escape_hatch_and_a_system_without_dpkg(tmp_path):
    out, calls = _package_check(tmp_path, FAKE_MISSING="cmake", MM_SKIP_SYSTEM_PACKAGES="1")
    assert calls == [] and "system packages" not in out.stderr
    out, calls = _package_check(tmp_path / "2", fakes=("apt-get", "id"), FAKE_MISSING="cmake")
    assert calls == []
    assert out.stderr.count("not a Debian/Ubuntu system") == 1


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("cmake  build", "line 2: need 'build' of cmake is not one of setup, headless, window, test"),  # noqa: E501
        ("cmake", "line 2: need '' of cmake"),
        ("Bad_Name setup", "line 2: 'Bad_Name' is not a Debian package name"),
    ],
)
def test_a_malformed_package_list_is_named_with_exit_2(tmp_path, line, message):
    out, calls = _package_check(tmp_path, packages=f"python3 setup\n{line}\n")
    assert out.returncode == 2 and calls == []
    assert message in out.stderr


def _function(name: str, call: str) -> subprocess.CompletedProcess:
    """Run one function of compile (its text cut out of the script) in bash."""
    text = COMPILE.read_text()
    body = text[text.index(f"{name}() {{") :]
    body = body[: body.index("\n}\n") + 3]
    return subprocess.run(["bash", "-c", body + call], capture_output=True, text=True,
                          timeout=30)  # fmt: skip


def test_demo_headless_is_the_20_s_run_with_a_screenshot():
    out = _function("demo_args", 'demo_args --headless sim_chips:=pmw3360; echo "${DEMO_ARGS[*]}"')
    assert out.stdout.split() == [
        "--headless", "--sim-chips", "pmw3360",
        "--duration", "20", "--screenshot", "demo-output/mm-monitor.png",
    ]  # fmt: skip
    out = _function("demo_args", 'demo_args --headless --duration 5; echo "${DEMO_ARGS[*]}"')
    assert out.stdout.split() == [
        "--headless", "--duration", "5", "--screenshot", "demo-output/mm-monitor.png"
    ]
    out = _function("demo_args", 'demo_args --rate 100; echo "${DEMO_ARGS[*]}"')
    assert out.stdout.split() == ["--rate", "100"]


EDITABLE_NOISE = """\
WARNING: Location 'file:///opt/pypi-more/simple/pip/' is ignored: it is neither a file nor a directory.
  /tmp/pip-build-env-x/overlay/lib/python3.11/site-packages/setuptools/command/editable_wheel.py:354: BuildBackendWarning: Editable installation.
  !!

          ********************************************************************************
          Please be careful with folders in your working directory with the same
          name as your package as they may take precedence during imports.
          ********************************************************************************

  !!
    with strategy, WheelFile(wheel_path, "w") as wheel_obj:
ERROR: a real error stays
"""  # noqa: E501


def test_setuptools_editable_notice_is_filtered_and_errors_are_not():
    out = _function("pip_noise_filter", f"pip_noise_filter <<'X'\n{EDITABLE_NOISE}X\n")
    assert out.stdout == "ERROR: a real error stays\n"
