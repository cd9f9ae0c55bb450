"""Test-wide set-up: every run talks ROS 2 only to itself.

A random ROS_DOMAIN_ID per pytest session and localhost-only discovery, set
before anything imports rclpy, so parallel runs (or a node left running by
hand) never see each other and nothing leaves this machine.
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

from hypothesis import settings

from mm_beagle.harness import use_isolated_ros_env

# the harness's one definition (domain, localhost, no static peers); a private domain
# even if the shell has a ROS_DOMAIN_ID: tests must not meet the user's live nodes
use_isolated_ros_env(keep_user_domain=False)
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
# the monitor's settings and default calibration live under XDG_CONFIG_HOME: a private
# folder per run, so tests neither read the user's nor leave any behind
_CONFIG_HOME = tempfile.mkdtemp(prefix="mm-test-config-")
os.environ["XDG_CONFIG_HOME"] = _CONFIG_HOME
atexit.register(shutil.rmtree, _CONFIG_HOME, ignore_errors=True)

# Hypothesis: the same examples on every run by default ("repeatable"), so CI on a
# shared, noisy machine is never red by chance and never by a timing deadline;
# HYPOTHESIS_PROFILE=explore searches fresh random examples (run it before a release).
settings.register_profile("repeatable", derandomize=True, deadline=None)
settings.register_profile("explore", deadline=None, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))
