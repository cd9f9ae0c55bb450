"""Test-wide set-up: every run talks ROS 2 only to itself.

A random ROS_DOMAIN_ID per pytest session and localhost-only discovery, set
before anything imports rclpy, so parallel runs (or a node left running by
hand) never see each other and nothing leaves this machine.
"""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import tempfile

from hypothesis import settings

from mm_beagle.tools.harness import use_isolated_ros_env

# The suite tests the commands as a user's terminal starts them: a suite started in the
# background (`nohup ... &`, a CI runner) inherits SIGINT/SIGTERM ignored, which every
# child would keep (by design: mm_pc.stop_signals leaves an ignored signal ignored) and
# each Ctrl-C test would fail. Put back the defaults the children then inherit.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
if signal.getsignal(signal.SIGTERM) is signal.SIG_IGN:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)

# the harness's one definition (domain, localhost, no static peers); a private domain
# even if the shell has a ROS_DOMAIN_ID: tests must not meet the user's live nodes
use_isolated_ros_env(keep_user_domain=False)
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
# Every temporary file of the run (pytest's tmp_path, the nodes' logs; the processes the
# tests start inherit TMPDIR) goes into one private folder, removed at the end: a test
# run leaves /tmp as it found it.
_RUN_TMP = tempfile.mkdtemp(prefix="mm-test-run-")
os.environ["TMPDIR"] = _RUN_TMP
tempfile.tempdir = None  # gettempdir() reads TMPDIR again
atexit.register(shutil.rmtree, _RUN_TMP, ignore_errors=True)
# the monitor's settings and default calibration live under XDG_CONFIG_HOME: a private
# folder per run, so tests neither read the user's nor leave any behind
os.environ["XDG_CONFIG_HOME"] = tempfile.mkdtemp(prefix="mm-test-config-")

# Hypothesis: the same examples on every run by default ("repeatable"), so CI on a
# shared, noisy machine is never red by chance and never by a timing deadline;
# HYPOTHESIS_PROFILE=explore searches fresh random examples (run it before a release).
settings.register_profile("repeatable", derandomize=True, deadline=None)
settings.register_profile("explore", deadline=None, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


#: ``--quick``: the folders and files whose tests start no ROS process and open no Qt
#: window (the inner loop: under two minutes on 2 cores; docs/testing.md)
QUICK = ("core/", "pln2033/", "sim/", "test_layers.py", "test_ros_package_xml.py",
         "test_prerequisites.py")


def pytest_addoption(parser):
    parser.addoption("--quick", action="store_true",
                     help="only the tests that start no ROS process and no Qt window")


def pytest_collection_modifyitems(config, items):
    """``--quick`` keeps the tests of :data:`QUICK`; every test's pytest-timeout limit is
    scaled by MM_TEST_TIMEOUT_FACTOR like the waits (fakes.scaled)."""
    import pytest
    from fakes import TIMEOUT_FACTOR

    if config.getoption("--quick"):
        root = os.path.dirname(__file__) + os.sep
        keep = [i for i in items if str(i.path).removeprefix(root).startswith(QUICK)]
        config.hook.pytest_deselected(items=[i for i in items if i not in keep])
        items[:] = keep
    if TIMEOUT_FACTOR > 1:
        default = float(config.getini("timeout") or 0)
        for item in items:
            marker = item.get_closest_marker("timeout")
            limit = marker.args[0] if marker and marker.args else default
            if limit:
                item.add_marker(pytest.mark.timeout(limit * TIMEOUT_FACTOR))
