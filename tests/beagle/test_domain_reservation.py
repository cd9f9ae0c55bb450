"""Private ROS domains: two runs at once never share one (a shared domain let one test
run's monitor count another run's /mm_beagle)."""

from __future__ import annotations

import subprocess
import sys

# a child that takes a domain out of two ids the real runs never use, prints it and
# holds it until its stdin closes
PICK = """
import sys
from mm_beagle.tools import harness
harness.ISOLATED_DOMAINS = range(300, 302)
print(harness._reserve_domain(), flush=True)
sys.stdin.read()
"""


def _holder() -> tuple[subprocess.Popen, int]:
    proc = subprocess.Popen([sys.executable, "-c", PICK], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)  # fmt: skip
    return proc, int(proc.stdout.readline())


def _release(proc: subprocess.Popen) -> None:
    proc.stdin.close()
    proc.wait(timeout=30)


def test_a_domain_held_by_one_run_is_never_picked_by_another():
    first, held = _holder()
    try:
        others = []
        for _ in range(8):  # a random pick alone would take the held one half the time
            proc, domain = _holder()
            others.append(domain)
            _release(proc)
        assert held in (300, 301)
        assert others == [601 - held] * 8
    finally:
        _release(first)


def test_a_domain_is_free_again_once_its_run_ended():
    first, held = _holder()
    second, other = _holder()
    _release(first)
    third, again = _holder()  # the only free one is the first run's
    _release(second)
    _release(third)
    assert {held, other} == {300, 301} and again == held
