"""sim_trajectory:=file:PATH -- CSV paths for the simulator and the emulated sensors."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from mm_pc.core.geometry import DEFAULT_MOUNTS
from mm_pc.core.odometry import Odometry
from mm_pc.sim import robot


def _csv(tmp_path, text: str, name: str = "path.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _rows(t, *cols):
    return "".join(",".join(f"{x:.6f}" for x in row) + "\n" for row in zip(t, *cols, strict=True))


def test_a_file_is_interpolated_to_the_1khz_steps(tmp_path):
    t = np.arange(0, 2.0 + 1e-9, 0.01)
    p = _csv(tmp_path, "# a comment\nt,v,w\n" + _rows(t, 0.1 + 0.05 * t, 0.3 * t))
    v, w, vy = robot.load_trajectory_file(p)
    assert vy is None and len(v) == len(w) == 2000
    mid = (np.arange(2000) + 0.5) * robot.DT
    assert np.allclose(v, 0.1 + 0.05 * mid, atol=1e-6) and np.allclose(w, 0.3 * mid, atol=1e-6)
    v2, w2, vy2 = robot.resolve_trajectory(f"file:{p}")
    assert np.array_equal(v, v2) and np.array_equal(w, w2) and vy2 is None


def test_lateral_slip_reaches_the_sensors_and_two_sensor_recovers_it(tmp_path):
    t = np.arange(0, 3.0 + 1e-9, 0.005)  # 200 Hz
    p = _csv(tmp_path, "t,vx,vy,w\n" + _rows(t, 0.2 + 0 * t, 0.05 * np.sin(t), 0.5 + 0 * t))
    v, w, vy = robot.load_trajectory_file(p)
    assert vy is not None and np.allclose(vy, 0.05 * np.sin((np.arange(3000) + 0.5) * 1e-3),
                                          atol=1e-6)
    d = np.stack([np.stack(robot.sensor_displacements(v, w, robot.DT, m, vy), -1)
                  for m in DEFAULT_MOUNTS], axis=1)
    truth = robot.integrate_pose(v, w, robot.DT, vy)[-1]
    slip_free = robot.integrate_pose(v, w, robot.DT)[-1]
    assert np.hypot(*(truth[:2] - slip_free[:2])) > 0.05  # the slip moved the robot
    odo = Odometry(DEFAULT_MOUNTS, "two-sensor")
    odo.integrate(robot.DT, d)
    assert np.allclose(odo.pose.as_array(), truth, atol=1e-9)
    # without vy the sensor model is the old one, bit for bit
    for m in DEFAULT_MOUNTS:
        a = robot.sensor_displacements(v, w, robot.DT, m)
        b = robot.sensor_displacements(v, w, robot.DT, m, np.zeros_like(v))
        assert np.allclose(a, b, atol=0)


BAD = [
    ("missing", None, "cannot read it"),
    ("empty", "", "empty"),
    ("no header", "0,0.1,0\n0.01,0.1,0\n", "line 1: header"),
    ("wrong columns", "t,speed,w\n0,0.1,0\n", "line 1: header 't,speed,w'"),
    ("short row", "t,v,w\n0,0.1,0\n0.01,0.1\n", "line 3: 2 values"),
    ("non-numeric", "t,v,w\n0,0.1,0\n0.01,fast,0\n", "line 3: not a number"),
    ("NaN", "t,v,w\n0,0.1,0\n0.01,nan,0\n", "line 3: '0.01,nan,0' is not finite"),
    ("non-monotone", "t,v,w\n0,0.1,0\n0.01,0.1,0\n0.01,0.1,0\n", "line 4: t = 0.01 s does not"),
    ("rate", "t,v,w\n0,0.1,0\n0.02,0.1,0\n", "line 3: 20 ms after the row before"),
    ("one row", "t,v,w\n0,0.1,0\n", "at least two rows"),
]


@pytest.mark.parametrize(("case", "text", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_files_are_refused_naming_the_file_and_line(tmp_path, case, text, message):
    p = tmp_path / "bad.csv" if text is None else _csv(tmp_path, text, "bad.csv")
    with pytest.raises(ValueError, match="trajectory file") as e:
        robot.load_trajectory_file(p)
    assert str(p) in str(e.value) and message in str(e.value)


def test_unknown_names_list_the_choices():
    with pytest.raises(ValueError, match="file:PATH"):
        robot.resolve_trajectory("spiral")


@pytest.mark.parametrize(
    "command",
    [
        lambda p: __import__("mm_beagle.tools.harness", fromlist=["x"]).node_command(
            {"backend": "sim", "sim_trajectory": f"file:{p}"}, "/bad_file"),
        lambda p: [sys.executable, "-m", "mm_beagle.link.agent_cli", "--backend", "sim",
                   "--sim-trajectory", f"file:{p}"],
        lambda p: [sys.executable, "-m", "mm_pc.monitor.app", "--headless", "--sim", f"file:{p}"],
    ],
    ids=["mm-beagle", "mm-beagle-agent", "mm-monitor"],
)
def test_a_bad_file_exits_2_with_the_line_for_every_program(tmp_path, command):
    pytest.importorskip("rclpy")
    p = _csv(tmp_path, "t,v,w\n0,0.1,0\n0.01,x,0\n")
    out = subprocess.run(command(p), capture_output=True, text=True, timeout=90,
                         env=dict(os.environ))
    text = out.stdout + out.stderr
    assert out.returncode == 2, text
    assert f"trajectory file {p}, line 3: not a number" in text
    assert "Traceback" not in text
