"""tools/fresh-check (the README's set-up on a fresh Debian root) and the README agree on
what a new user installs first; its arguments are checked before anything is built. The
check itself needs root and ~7 minutes: CI runs it (.ci/run), not this suite."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FRESH = ROOT / "tools" / "fresh-check"


def test_the_readme_names_exactly_what_the_fresh_check_installs_first():
    prereqs = re.search(r"^README_PREREQS=\((.*)\)$", FRESH.read_text(), re.M)
    assert prereqs is not None
    line = f"sudo apt-get install {prereqs.group(1)}\n"
    assert line in (ROOT / "README.md").read_text()


def test_help_and_a_bad_option():
    out = subprocess.run([str(FRESH), "--help"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0 and "usage: tools/fresh-check [--test" in out.stdout
    assert "set -euo" not in out.stdout  # the comment block only
    out = subprocess.run([str(FRESH), "--tset"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 2
    assert out.stderr == "fresh-check: unknown option '--tset' (see tools/fresh-check --help)\n"


def test_ci_runs_the_fresh_check_before_the_suite_and_fails_with_it():
    ci = (ROOT / ".ci" / "run").read_text()
    assert ci.index("tools/fresh-check") < ci.index("exec ./compile test")
    assert ci.rstrip().endswith("exec ./compile test")


def _ci(tmp_path: Path, fresh_exit: int, **env: str) -> subprocess.CompletedProcess:
    """.ci/run in a copy whose tools/fresh-check and compile are stand-ins that say so."""
    (tmp_path / ".ci").mkdir(parents=True)
    (tmp_path / "tools").mkdir()
    (tmp_path / ".ci" / "run").write_text((ROOT / ".ci" / "run").read_text())
    for path, text in ((tmp_path / "tools" / "fresh-check", f"echo fresh; exit {fresh_exit}"),
                       (tmp_path / "compile", 'echo "compile $*"')):  # fmt: skip
        path.write_text(f"#!/bin/bash\n{text}\n")
        path.chmod(0o755)
    return subprocess.run(["bash", str(tmp_path / ".ci" / "run")], capture_output=True,
                          text=True, timeout=30, env={"PATH": "/usr/bin:/bin", **env})  # fmt: skip


def test_ci_fails_when_the_fresh_check_fails_and_runs_the_suite_when_it_passes(tmp_path):
    failed = _ci(tmp_path / "a", 1)
    assert failed.returncode == 1 and failed.stdout == "fresh\n"
    assert "the fresh-machine check (tools/fresh-check) exited 1" in failed.stderr
    passed = _ci(tmp_path / "b", 0)
    assert passed.returncode == 0 and passed.stdout == "fresh\ncompile test\n"
    skipped = _ci(tmp_path / "c", 1, MM_SKIP_FRESH_CHECK="1")
    assert skipped.stdout == "compile test\n" and "NOT run" in skipped.stderr
