"""mm-monitor's command line refuses bad inputs with one line and exit 2, writing nothing;
a headless replay ends with the replay; a screenshot never overwrites an input."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

pytest.importorskip("rclpy")
pytest.importorskip("PySide6")

from mm_beagle.tools.harness import isolated_ros_env
from mm_pc.monitor.io.mcap_writer import McapRecorder
from mm_pc.monitor.model.sim_feed import sim_replies

REPLAY_S = 2.0
DEEP = "[" * 5000 + "]" * 5000 + "\n"


def monitor(*args, cwd, timeout=90) -> subprocess.CompletedProcess:
    env = dict(isolated_ros_env(), QT_QPA_PLATFORM="offscreen")
    return subprocess.run(
        [sys.executable, "-m", "mm_pc.monitor.app", "--headless", *map(str, args)],
        capture_output=True, text=True, timeout=timeout, env=env, cwd=cwd,
    )  # fmt: skip


def one_line(out: subprocess.CompletedProcess) -> str:
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    return lines[0]


def snapshot(folder) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    rec = McapRecorder(path)
    replies = list(sim_replies("straight", 20, seconds=REPLAY_S))
    for r in replies:
        rec.write_reply(r)
    rec.close()
    return path


def test_a_bad_beagle_name_is_refused(tmp_path):
    out = monitor("--beagle", "/9bad name!", "--duration", "1", cwd=tmp_path)
    assert out.returncode == 2
    line = one_line(out)
    assert line.startswith("mm-monitor: --beagle '/9bad name!' is not a ROS node name")
    assert "allowed:" in line
    assert snapshot(tmp_path) == {}


@pytest.mark.parametrize("kind", ["missing", "deep", "garbage"])
def test_a_bad_calibration_file_is_refused(kind, tmp_path):
    cal = tmp_path / f"{kind}.yaml"
    if kind == "deep":
        cal.write_text(DEEP)
    elif kind == "garbage":
        cal.write_text("sensors: [1, 2\n")
    before = snapshot(tmp_path)
    out = monitor("--calibration", cal, "--duration", "1", cwd=tmp_path)
    assert out.returncode == 2
    line = one_line(out)
    assert line.startswith(f"mm-monitor: --calibration: calibration file {cal}: ")
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("kind", ["empty", "random"])
def test_a_headless_replay_of_a_bad_file_exits_2_with_the_reason(kind, recording, tmp_path):
    bad = tmp_path / f"{kind}.mcap"
    bad.write_bytes({"empty": b"", "random": os.urandom(5000)}[kind])
    shot = tmp_path / "shot.png"
    before = snapshot(tmp_path)
    out = monitor("--replay", bad, "--screenshot", shot, cwd=tmp_path)
    assert out.returncode == 2, out.stdout + out.stderr
    line = one_line(out)
    assert line.startswith(f"mm-monitor: --replay {bad}: "), line
    assert snapshot(tmp_path) == before  # no screenshot either


def test_a_headless_replay_without_duration_ends_with_the_replay(recording, tmp_path):
    out = monitor("--replay", recording, cwd=tmp_path, timeout=60)
    assert out.returncode == 0, out.stderr
    n = len(list(sim_replies("straight", 20, seconds=REPLAY_S)))
    assert f"processed {n} replies" in out.stdout, out.stdout
    assert snapshot(tmp_path) == {}


@pytest.mark.parametrize("onto", ["replay", "calibration"])
def test_a_screenshot_onto_an_input_is_refused(onto, recording, tmp_path):
    from mm_pc.core.calibration import Calibration

    cal = tmp_path / "cal.yaml"
    Calibration().save(cal)
    before, rec_before = snapshot(tmp_path), recording.read_bytes()
    target = recording if onto == "replay" else cal
    out = monitor("--replay", recording, "--calibration", cal, "--screenshot", target,
                  cwd=tmp_path)  # fmt: skip
    assert out.returncode == 2
    line = one_line(out)
    assert line == (f"mm-monitor: --screenshot {target}: that is the --{onto} input; "
                    "write the screenshot to another path")  # fmt: skip
    assert snapshot(tmp_path) == before and recording.read_bytes() == rec_before


def test_a_sim_node_that_exits_ends_the_run_with_its_reason(tmp_path):
    """What the monitor does each tick with --sim: a real process that exited with a
    reason in its log ends the run; the reason is kept, and a running one is left alone."""
    from mm_pc.monitor.app import _check_node

    log = tmp_path / "sim_beagle.log"
    quits = []

    class App:
        def quit(self):
            quits.append(1)

    with open(log, "w") as out:
        node = subprocess.Popen(
            [sys.executable, "-c", "import sys; print('mm-beagle: patch_file is bad'); "
             "print('mm-beagle: shutting down, stopping the poller'); sys.exit(2)"],
            stdout=out, stderr=subprocess.STDOUT,
        )  # fmt: skip
        node.wait(30)
    running = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        reasons: list[str] = []
        _check_node(running, log, reasons, App())
        assert reasons == [] and quits == []
    finally:
        running.kill()
        running.wait(5)
    _check_node(node, log, reasons, App())
    assert reasons == [
        f"the emulated mm-beagle exited (code 2): mm-beagle: patch_file is bad (log {log})"
    ]
    assert quits == [1]


def test_a_headless_replay_of_a_cut_file_replays_what_is_whole_and_says_so(recording, tmp_path):
    """A recording cut by a crash or a full disk (issue 29): the whole messages before the
    cut are replayed, with a warning that says where the file ends; exit 0."""
    cut = tmp_path / "cut.mcap"
    data = recording.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    shot = tmp_path / "shot.png"
    out = monitor("--replay", cut, "--screenshot", shot, cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    text = out.stdout + out.stderr
    assert f"cut.mcap is cut short (a crash or a full disk?) at byte {len(data) // 2}" in text
    replies = int(re.search(r"(\d+) replies to replay", text).group(1))
    assert replies > 0 and f"processed {replies} replies" in text, text
    assert shot.exists()
