"""mm-fusion: ``ros2 launch mm_pc fusion.launch.py [field_sim:=true]``.

The filter's inputs, beacons, plot and noise come from ``fusion_params`` (default: the
installed config/mm_fusion.yaml, which also holds mm-field-sim's section), named for
this node so that another include of robot.launch.py never sets it;
``field_sim:=true`` starts the simulated mowing run as well, a complete demo without
a robot. ``frame_prefix:=r1/`` (many robots on one /tf) overrides the file's, for both
nodes, only when given.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def _nodes(context):
    """mm-fusion (and mm-field-sim), with frame_prefix only when it was given."""
    params = [LaunchConfiguration("fusion_params")]
    if prefix := LaunchConfiguration("frame_prefix").perform(context):
        params.append({"frame_prefix": prefix})
    return [
        Node(
            package="mm_pc",
            executable="mm-fusion",
            name="mm_fusion",
            namespace=LaunchConfiguration("namespace"),
            parameters=params,
            output="screen",
        ),
        Node(
            package="mm_pc",
            executable="mm-field-sim",
            name="field_sim",
            namespace=LaunchConfiguration("namespace"),
            parameters=params,
            output="screen",
            condition=IfCondition(LaunchConfiguration("field_sim")),
        ),
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "fusion_params",
                default_value=PathJoinSubstitution(
                    [FindPackageShare("mm_pc"), "config", "mm_fusion.yaml"]
                ),
                description="YAML parameters of mm_fusion (and field_sim)",
            ),
            DeclareLaunchArgument(
                "field_sim", default_value="false", description="also run mm-field-sim"
            ),
            DeclareLaunchArgument(
                "frame_prefix",
                default_value="",
                description="put before every frame id, e.g. r1/ ('' = the file's)",
            ),
            DeclareLaunchArgument("namespace", default_value="", description="node namespace"),
            OpaqueFunction(function=_nodes),
        ]
    )
