"""mm-monitor, the Qt window: ``ros2 launch mm_pc monitor.launch.py [beagle:=/mm_beagle]``.

mm-monitor takes command-line options, not ROS parameters (it is a window, not a node
others configure), so it is started as a process with those options; launch_ros's Node
would append ``--ros-args``, which its option parser does not know.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.substitutions import LaunchConfiguration
from launch_ros.substitutions import ExecutableInPackage


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "beagle", default_value="/mm_beagle", description="the mm_beagle node to watch"
            ),
            DeclareLaunchArgument("rate", default_value="15.0", description="sample rate (Hz)"),
            DeclareLaunchArgument("method", default_value="exact", description="pose method"),
            ExecuteProcess(
                cmd=[
                    ExecutableInPackage("mm-monitor", "mm_pc"),
                    "--beagle",
                    LaunchConfiguration("beagle"),
                    "--rate",
                    LaunchConfiguration("rate"),
                    "--method",
                    LaunchConfiguration("method"),
                ],
                output="screen",
            ),
        ]
    )
