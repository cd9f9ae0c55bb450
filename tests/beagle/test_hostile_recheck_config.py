"""Bad values refused at start (issue 27's recheck of "What to build" 6): a patch_dir that
does not exist or is no directory was accepted by mm-beagle-agent (exit 0, serving) and by
mm-beagle on a local backend; a peer's or a user's load_patch was the first to find out.
Now one line and exit 2, before anything opens."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from mm_beagle.link.link_checks import patch_dir_problem


def test_patch_dir_must_be_a_directory(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    assert patch_dir_problem("") == ""  # patch loading off
    assert patch_dir_problem(str(tmp_path)) == ""
    assert patch_dir_problem(str(tmp_path / "none")) == (
        f"'patch_dir' '{tmp_path / 'none'}' does not exist (give the directory of the patch "
        "files, or '')"
    )
    assert "is not a directory" in patch_dir_problem(str(fifo))


@pytest.mark.parametrize("kind", ["missing", "fifo"])
def test_the_agent_refuses_a_patch_dir_that_is_no_directory(tmp_path, kind):
    path = tmp_path / kind
    if kind == "fifo":
        os.mkfifo(path)
    res = subprocess.run(
        [sys.executable, "-m", "mm_beagle.link.agent_cli", "--backend", "sim",
         "--realtime-priority", "0", "--patch-dir", str(path), "--self-test", "1"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert res.stderr.splitlines() == [f"mm-beagle-agent: error: {patch_dir_problem(str(path))}"]
    assert res.stdout == ""  # no self-test ran


def test_the_node_refuses_a_patch_dir_that_is_no_directory_on_a_local_backend(tmp_path):
    pytest.importorskip("rclpy")
    from mm_beagle.tools.harness import isolated_ros_env, node_command

    path = tmp_path / "none"
    res = subprocess.run(
        node_command({"backend": "sim", "patch_dir": str(path)}),
        env=isolated_ros_env(keep_user_domain=False), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    lines = [ln for ln in (res.stderr + res.stdout).splitlines() if ln.strip()]
    assert lines == [f"mm-beagle: {patch_dir_problem(str(path))}"]
