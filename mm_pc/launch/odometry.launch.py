"""mm-odometry alone: ``ros2 launch mm_pc odometry.launch.py [beagle:=mm_beagle]``.

It asks the mm_beagle node named by ``beagle`` for the sensor data and publishes
~/odom and ~/path; the rest comes from ``odometry_params`` (default: the installed
config/mm_odometry.yaml, every parameter with its default), named for this node so that
another include of robot.launch.py never sets it. ``frame_prefix:=r1/`` (many robots on
one /tf) overrides the file's only when given.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def _node(context):
    """The node, with frame_prefix from the command line only when it was given."""
    overrides = {"beagle": LaunchConfiguration("beagle")}
    if prefix := LaunchConfiguration("frame_prefix").perform(context):
        overrides["frame_prefix"] = prefix
    return [
        Node(
            package="mm_pc",
            executable="mm-odometry",
            name="mm_odometry",
            namespace=LaunchConfiguration("namespace"),
            parameters=[LaunchConfiguration("odometry_params"), overrides],
            output="screen",
        )
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "odometry_params",
                default_value=PathJoinSubstitution(
                    [FindPackageShare("mm_pc"), "config", "mm_odometry.yaml"]
                ),
                description="YAML parameters of mm_odometry",
            ),
            DeclareLaunchArgument(
                "beagle",
                default_value="mm_beagle",
                description="the mm_beagle node to ask (relative: in the node's namespace)",
            ),
            DeclareLaunchArgument(
                "frame_prefix",
                default_value="",
                description="put before every frame id, e.g. r1/ ('' = the file's)",
            ),
            DeclareLaunchArgument("namespace", default_value="", description="node namespace"),
            OpaqueFunction(function=_node),
        ]
    )
