"""mm-beagle alone: ``ros2 launch mm_beagle beagle.launch.py [backend:=sim] [params_file:=F]``.

The parameters come from ``params_file`` (default: the installed config/mm_beagle.yaml, every
parameter with its default); ``backend`` overrides the file's, since it is the one a user
switches most (spidev on the board, sim on a PC without sensors, remote for an agent).
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
                    [FindPackageShare("mm_beagle"), "config", "mm_beagle.yaml"]
                ),
                description="YAML parameters of mm_beagle",
            ),
            DeclareLaunchArgument(
                "backend", default_value="spidev", description="spidev | sim | remote"
            ),
            DeclareLaunchArgument("namespace", default_value="", description="node namespace"),
            Node(
                package="mm_beagle",
                executable="mm-beagle",
                name="mm_beagle",
                namespace=LaunchConfiguration("namespace"),
                parameters=[
                    LaunchConfiguration("params_file"),
                    {"backend": LaunchConfiguration("backend")},
                ],
                output="screen",
            ),
        ]
    )
