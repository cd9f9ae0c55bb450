"""``frame_prefix`` (issue 25): every node that names frames puts it before every frame id
it publishes, as robot_state_publisher does; '' by default, checked like the frame ids."""

from __future__ import annotations

import os
import subprocess

import pytest

pytest.importorskip("rclpy")
import rclpy
from rclpy.parameter import Parameter

from mm_pc.ros.tf import frame_prefix_problem, prefixed, sensor_frame_names


def test_a_prefix_is_empty_or_the_start_of_a_frame_id():
    assert frame_prefix_problem("") == ""
    assert frame_prefix_problem("r1/") == ""
    assert frame_prefix_problem("robot_2.") == ""
    assert "no leading '/'" in frame_prefix_problem("/r1/")
    assert "'frame_prefix' is 'r 1/'" in frame_prefix_problem("r 1/")
    assert prefixed("r1/", "odom") == "r1/odom"
    assert prefixed("", "odom") == "odom"


def test_sensor_frames_are_named_then_prefixed():
    devices = ["/dev/spidev1.0", "/dev/spidev1.1"]
    assert sensor_frame_names(devices, (), "r1/") == ["r1/mouse_spidev1_0", "r1/mouse_spidev1_1"]
    assert sensor_frame_names(devices, ("left", "right"), "r2/") == ["r2/left", "r2/right"]
    assert sensor_frame_names(devices) == ["mouse_spidev1_0", "mouse_spidev1_1"]
    with pytest.raises(ValueError, match="no leading '/'"):
        sensor_frame_names(devices, (), "/r1/")


def _tables() -> dict:
    import importlib

    modules = {
        "mm-beagle": "mm_beagle.node.params",
        "mm-odometry": "mm_pc.ros.odometry_node",
        "mm-fusion": "mm_pc.ros.fusion_node",
        "mm-field-sim": "mm_pc.ros.field_sim_node",
    }
    return {p: importlib.import_module(m).PARAMETERS for p, m in modules.items()}


def test_every_node_that_names_frames_takes_a_read_only_frame_prefix():
    for program, table in _tables().items():
        assert any(name.endswith("_frame") for name in table), program
        default, desc = table["frame_prefix"]
        assert default == "" and desc.read_only, program
        assert "robot_state_publisher" in desc.description


@pytest.mark.ros
@pytest.mark.parametrize(
    "module", ["mm_pc.ros.odometry_node", "mm_pc.ros.fusion_node", "mm_pc.ros.field_sim_node"]
)
def test_a_bad_prefix_exits_2_with_a_message(module, ros_command):
    out = subprocess.run(
        ros_command(module, {"frame_prefix": "/r1/"}, "/prefix_bad"),
        capture_output=True, text=True, timeout=60, env=dict(os.environ),
    )  # fmt: skip
    assert out.returncode == 2, out.stdout + out.stderr
    assert "'frame_prefix' is '/r1/': TF frame ids have no leading '/'" in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.ros
def test_beagle_refuses_a_bad_prefix_even_without_its_odometry():
    from mm_beagle.tools.harness import node_command

    out = subprocess.run(
        node_command({"backend": "sim", "frame_prefix": "r 1/"}, "/prefix_bad"),
        capture_output=True, text=True, timeout=60, env=dict(os.environ),
    )  # fmt: skip
    assert out.returncode == 2, out.stdout + out.stderr
    assert "'frame_prefix' is 'r 1/'" in out.stdout + out.stderr


@pytest.fixture
def context():
    ctx = rclpy.Context()  # its own: other tests may hold the default context
    rclpy.init(context=ctx)
    yield ctx
    rclpy.shutdown(context=ctx)


@pytest.mark.ros
def test_odometry_publishes_every_frame_after_the_prefix_also_after_a_live_change(context):
    from mm_pc.ros.odometry_node import OdometryNode

    node = OdometryNode(
        context=context, parameter_overrides=[Parameter("frame_prefix", value="r1/")]
    )
    try:
        assert node.frame("odom_frame") == "r1/odom"
        assert node.frame("base_frame") == "r1/base_link"
        assert node.sensor_frames == ["r1/mouse_spidev1_0", "r1/mouse_spidev1_1"]
        assert node.path.header.frame_id == "r1/odom"
        (result,) = node.set_parameters([Parameter("odom_frame", value="odom_mouse")])
        assert result.successful
        assert node.path.header.frame_id == "r1/odom_mouse"
        assert node.get_parameter("odom_frame").value == "odom_mouse"  # the parameter as set
    finally:
        node.destroy_node()


@pytest.mark.ros
def test_fusion_and_field_sim_publish_their_frames_after_the_prefix(context):
    from mm_pc.ros.field_sim_node import FRAMES, FieldSimNode
    from mm_pc.ros.fusion_node import FusionNode

    prefix = [Parameter("frame_prefix", value="r2/")]
    fusion = FusionNode(context=context, parameter_overrides=prefix)
    try:
        msg = fusion.odometry_message()
        assert (msg.header.frame_id, msg.child_frame_id) == ("r2/map", "r2/base_link")
        assert fusion.path.header.frame_id == "r2/map"
    finally:
        fusion.destroy_node()
    sim = FieldSimNode(context=context, parameter_overrides=prefix)
    try:
        assert set(FRAMES) == {
            "map_frame", "odom_frame", "wheel_odom_frame", "base_frame", "gps_frame",
            "imu_frame", "range_frame",
        }  # fmt: skip
        assert sim.p["odom_frame"] == "r2/odom" and sim.p["range_frame"] == "r2/range_antenna"
        assert all(sim.p[name].startswith("r2/") for name in FRAMES)
    finally:
        sim.destroy_node()
