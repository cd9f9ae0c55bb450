"""The usual set: ``ros2 launch mm_beagle robot.launch.py [backend:=sim] [monitor:=true]``.

mm-beagle (sensors), mm-odometry (pose from them) and mm-fusion (map pose from it and the
other sensors), each from its own launch file with its installed parameters file;
``chips:=`` / ``sim_chips:=`` go to mm-beagle; ``monitor:=true`` adds the Qt window (on a
machine with a display). The launch files of each node are included, not copied, so each
node is configured in one place.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.substitutions import FindPackageShare


def _include(package: str, launch_file: str, arguments: dict, condition=None):
    """IncludeLaunchDescription of ``package``'s installed launch/``launch_file``."""
    return IncludeLaunchDescription(
        PythonLaunchDescriptionSource(
            PathJoinSubstitution([FindPackageShare(package), "launch", launch_file])
        ),
        launch_arguments=arguments.items(),
        condition=condition,
    )


def generate_launch_description() -> LaunchDescription:
    backend = LaunchConfiguration("backend")
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "backend", default_value="spidev", description="mm-beagle: spidev | sim | remote"
            ),
            DeclareLaunchArgument(
                "monitor", default_value="false", description="also open mm-monitor"
            ),
            DeclareLaunchArgument(
                "chips", default_value="", description="mm-beagle: chip per device ('' = file's)"
            ),
            DeclareLaunchArgument(
                "sim_chips", default_value="", description="mm-beagle: emulated chip per device"
            ),
            _include(
                "mm_beagle",
                "beagle.launch.py",
                {
                    "backend": backend,
                    "chips": LaunchConfiguration("chips"),
                    "sim_chips": LaunchConfiguration("sim_chips"),
                },
            ),
            _include("mm_pc", "odometry.launch.py", {"beagle": "mm_beagle"}),
            _include("mm_pc", "fusion.launch.py", {}),
            _include(
                "mm_pc",
                "monitor.launch.py",
                {"beagle": "/mm_beagle"},
                condition=IfCondition(LaunchConfiguration("monitor")),
            ),
        ]
    )
