"""Bad configuration files and an early Ctrl-C: one line, exit 2 (0 for Ctrl-C), nothing written.

Real node processes (python -m ...), as a user would start them.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest
from fakes import console_script, scaled

pytest.importorskip("rclpy")

from mm_beagle.tools.harness import isolated_ros_env
from mm_pc.core.calibration import Calibration
from mm_pc.ros.spin import params_file_problems
from pln2033 import RegisterMapError
from pln2033.pln2033 import RegisterMap

NODES = {
    "mm-beagle": "mm_beagle.node.node",
    "mm-odometry": "mm_pc.ros.odometry_node",
    "mm-fusion": "mm_pc.ros.fusion_node",
}
DEEP = "[" * 5000 + "]" * 5000 + "\n"  # RecursionError in PyYAML's composer


def _bad_files(tmp_path) -> dict[str, tuple[str, str]]:
    """kind -> (path, what the message must say)."""
    files = {"missing": (str(tmp_path / "nope.yaml"), "cannot read it (No such file")}
    for kind, text, says in (
        ("malformed", "a: [1, 2\nb: {\n", "not valid YAML"),
        ("deep", DEEP, "nested too deeply"),
        ("not_a_mapping", "- 1\n- 2\n", "expected a mapping"),
    ):
        p = tmp_path / f"{kind}.yaml"
        p.write_text(text)
        files[kind] = (str(p), says)
    p = tmp_path / "binary.yaml"
    p.write_bytes(b"\xff\xfe\x00garbage")
    files["binary"] = (str(p), "not a text file")
    return files


def _run(module: str, ros_args: list[str], cwd) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", module, "--ros-args", *ros_args],
        capture_output=True, text=True, timeout=scaled(120), cwd=cwd, env=isolated_ros_env(),
    )  # fmt: skip


def test_params_file_problems_name_the_file(tmp_path):
    for kind, (path, says) in _bad_files(tmp_path).items():
        (problem,) = params_file_problems(["prog", "--ros-args", "--params-file", path])
        assert path in problem and says in problem, kind
    good = tmp_path / "good.yaml"
    good.write_text("mm_beagle:\n  ros__parameters:\n    cpi: 1600\n")
    assert params_file_problems(["p", "--ros-args", "--params-file", str(good)]) == []
    assert params_file_problems(["p", "--params-file", "/nope"]) == []  # not a ROS argument
    assert "needs a YAML file" in params_file_problems(["p", "--ros-args", "--params-file"])[0]


@pytest.mark.parametrize("prog", sorted(NODES))
@pytest.mark.parametrize("kind", ["missing", "malformed", "deep", "not_a_mapping", "binary"])
def test_a_bad_params_file_is_one_line_and_exit_2(prog, kind, tmp_path):
    path, says = _bad_files(tmp_path)[kind]
    work = tmp_path / "cwd"
    work.mkdir()
    before = sorted(p.name for p in tmp_path.iterdir())
    out = _run(NODES[prog], ["--params-file", path], work)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith(f"{prog}: --params-file {path}: ") and says in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert list(work.iterdir()) == []


def test_deeply_nested_calibration_file_is_one_line_and_exit_2(tmp_path):
    deep = tmp_path / "deep.yaml"
    deep.write_text(DEEP)
    with pytest.raises(ValueError, match=f"calibration file {deep}: .*nested too deeply"):
        Calibration.load(deep)
    out = _run("mm_pc.ros.odometry_node", ["-p", f"calibration_file:={deep}"], tmp_path)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "nested too deeply" in lines[0] and str(deep) in lines[0], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deep.yaml"]


def test_register_map_errors_name_the_file(tmp_path):
    for name, text, says in (
        ("deep.yaml", DEEP, "nested too deeply"),
        ("typo.yaml", "registerz: {}\n", "unknown key 'registerz'"),
        ("value.yaml", "cpi: {min: -1}\n", "'cpi.min' must be an integer"),
        ("broken.yaml", "cpi: [1,\n", "not valid YAML"),
    ):
        p = tmp_path / name
        p.write_text(text)
        with pytest.raises(RegisterMapError) as err:
            RegisterMap.load(p)
        assert str(p) in str(err.value) and says in str(err.value)
        assert "\n" not in str(err.value)


@pytest.mark.parametrize("prog", ["mm-beagle", "mm-odometry"])
def test_ctrl_c_during_start_up_is_a_clean_stop(prog, tmp_path):
    """SIGINT 0.3 s after start lands while rclpy is being imported: no traceback, exit 0."""
    (bin_dir := tmp_path / "bin").mkdir()
    (cwd := tmp_path / "cwd").mkdir()
    script = console_script(prog, bin_dir)  # as a user's shell starts it
    proc = subprocess.Popen(
        [sys.executable, script, "--ros-args", "-p", "backend:=sim"]
        if prog == "mm-beagle" else [sys.executable, script],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=cwd,
        env=isolated_ros_env(),
    )  # fmt: skip
    try:
        time.sleep(0.3)  # on purpose: the SIGINT lands during the start-up
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=scaled(60))
        assert proc.returncode == 0, out
        assert "Traceback" not in out and "KeyboardInterrupt" not in out, out
        assert list(cwd.iterdir()) == []
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(scaled(30))
