"""Parameters as launch_ros hands them to a node: the file its Node writes for a dict.

launch_ros writes a Node's ``parameters=[{...}]`` to a temporary file with ``yaml.dump``,
so a list value (``chips: [pmw3389]``, evaluated to a tuple) becomes ``!!python/tuple``.
rcl's parser reads that tag as a plain list; our nodes' own ``--params-file`` check must
too (``ros2 launch mm_beagle beagle.launch.py chips:=pmw3389`` ended with exit 2, "not
valid YAML", found with the real launch, issue 25), and still refuse other Python tags.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time

import pytest
import yaml
from fakes import scaled

pytest.importorskip("rclpy")

from mm_beagle.tools.harness import isolated_ros_env
from mm_pc.ros.spin import params_file_problems


def _launch_ros_file(tmp_path, params: dict, node: str = "/r2/mm_beagle"):
    """The file launch_ros's Node._create_params_file_from_dict writes (lists as tuples)."""
    evaluated = {k: tuple(v) if isinstance(v, list) else v for k, v in params.items()}
    path = tmp_path / "launch_params_x"
    with open(path, "w") as h:
        yaml.dump({node: {"ros__parameters": evaluated}}, h, default_flow_style=False)
    return path


def test_a_launch_ros_file_with_a_list_passes_the_check(tmp_path):
    path = _launch_ros_file(tmp_path, {"backend": "sim", "chips": ["pmw3389"]})
    assert "!!python/tuple" in path.read_text()
    assert params_file_problems(["p", "--ros-args", "--params-file", str(path)]) == []


def test_other_python_tags_are_still_refused(tmp_path):
    path = tmp_path / "evil.yaml"
    path.write_text('/**:\n  ros__parameters:\n    x: !!python/object/apply:os.system ["true"]\n')
    (problem,) = params_file_problems(["p", "--ros-args", "--params-file", str(path)])
    assert str(path) in problem and "not valid YAML" in problem, problem


@pytest.mark.ros
def test_rcl_reads_the_tuple_tag_as_a_list(tmp_path):
    """What the check is aligned with: rcl's own parser takes the tagged list."""
    import rclpy
    from rclpy.context import Context

    path = _launch_ros_file(tmp_path, {"chips": ["pmw3389", "pln2033"], "frame_prefix": "r2/"},
                            node="/**")  # fmt: skip
    ctx = Context()
    rclpy.init(context=ctx, args=["--ros-args", "--params-file", str(path)])
    try:
        node = rclpy.create_node(
            "mm_launch_params", context=ctx, automatically_declare_parameters_from_overrides=True
        )
        assert node.get_parameter("chips").value == ["pmw3389", "pln2033"]
        assert node.get_parameter("frame_prefix").value == "r2/"
        node.destroy_node()
    finally:
        ctx.try_shutdown()


@pytest.mark.ros
def test_mm_beagle_starts_from_a_launch_ros_file_with_a_list(tmp_path):
    """The real node with that file (as ``beagle.launch.py chips:=pmw3389`` starts it):
    it brings its sensors up as the chip the list names, then stops on SIGINT with 0."""
    path = _launch_ros_file(tmp_path, {"backend": "sim", "chips": ["pmw3389"]}, "/**/mm_beagle")
    cmd = [sys.executable, "-m", "mm_beagle.node", "--ros-args", "--params-file", str(path)]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=isolated_ros_env()
    )
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + scaled(60)
        while not any("polled at" in ln for ln in lines) and proc.poll() is None:
            assert time.monotonic() < deadline, "no 'polled at' within 60 s:\n" + "".join(lines)
            time.sleep(0.1)
        assert proc.poll() is None, "".join(lines)
        up = [ln for ln in lines if " up: " in ln]
        assert len(up) == 2 and all("PMW3389" in ln for ln in up), "".join(lines)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        rc = proc.wait(scaled(30))
    assert rc == 0, "".join(lines)


@pytest.mark.ros
def test_mm_field_sim_answers_its_parameter_services_while_it_replays(tmp_path):
    """``ros2 param get /field_sim ...`` during fusion.launch.py field_sim:=true waited for
    ever (found with the real ros2cli): the replay ran on the only thread and nothing served
    the node's services. Now list/get answer, and a read-only parameter is refused."""
    import rclpy
    from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from mm_pc.ros.field_sim_node import PARAMETERS

    cmd = [sys.executable, "-m", "mm_pc.ros.field_sim_node", "--ros-args",
           "-r", "__ns:=/mm_params_fs", "-p", "seed:=7", "-p", "speed:=1.0"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=isolated_ros_env())  # fmt: skip
    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("mm_params_fs_client", context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)

    def ask(srv_type, service: str, request):
        client = node.create_client(srv_type, f"/mm_params_fs/field_sim/{service}")
        assert client.wait_for_service(timeout_sec=scaled(30)), f"{service} not offered"
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=scaled(10))
        assert future.done(), f"{service} not answered within 10 s (the replay is running)"
        return future.result()

    try:
        listed = ask(ListParameters, "list_parameters", ListParameters.Request()).result.names
        assert set(PARAMETERS) <= set(listed)
        got = ask(GetParameters, "get_parameters", GetParameters.Request(names=["seed"]))
        assert [v.integer_value for v in got.values] == [7]
        refused = ask(SetParameters, "set_parameters", SetParameters.Request(
            parameters=[Parameter("seed", value=8).to_parameter_msg()])).results  # fmt: skip
        assert not refused[0].successful and "read-only" in refused[0].reason
        assert proc.poll() is None  # still replaying
    finally:
        executor.shutdown()
        node.destroy_node()
        ctx.try_shutdown()
        proc.send_signal(signal.SIGINT)
        rc = proc.wait(scaled(30))
    assert rc == 0
