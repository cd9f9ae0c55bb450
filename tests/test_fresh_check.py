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
