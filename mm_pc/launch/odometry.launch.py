"""mm-odometry alone: ``ros2 launch mm_pc odometry.launch.py [beagle:=mm_beagle]``.

It asks the mm_beagle node named by ``beagle`` for the sensor data and publishes
~/odom and ~/path; the rest comes from ``params_file`` (default: the installed
config/mm_odometry.yaml, every parameter with its default).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "params_file",
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
            DeclareLaunchArgument("namespace", default_value="", description="node namespace"),
            Node(
                package="mm_pc",
                executable="mm-odometry",
                name="mm_odometry",
                namespace=LaunchConfiguration("namespace"),
                parameters=[
                    LaunchConfiguration("params_file"),
                    {"beagle": LaunchConfiguration("beagle")},
                ],
                output="screen",
            ),
        ]
    )
