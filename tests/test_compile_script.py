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
