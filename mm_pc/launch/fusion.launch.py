"""mm-fusion: ``ros2 launch mm_pc fusion.launch.py [field_sim:=true]``.

The filter's inputs, beacons, plot and noise come from ``params_file`` (default: the
installed config/mm_fusion.yaml, which also holds mm-field-sim's section);
``field_sim:=true`` starts the simulated mowing run as well, a complete demo without
a robot.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    params = LaunchConfiguration("params_file")
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "params_file",
                default_value=PathJoinSubstitution(
                    [FindPackageShare("mm_pc"), "config", "mm_fusion.yaml"]
                ),
                description="YAML parameters of mm_fusion (and field_sim)",
            ),
            DeclareLaunchArgument(
                "field_sim", default_value="false", description="also run mm-field-sim"
            ),
            DeclareLaunchArgument("namespace", default_value="", description="node namespace"),
            Node(
                package="mm_pc",
                executable="mm-fusion",
                name="mm_fusion",
                namespace=LaunchConfiguration("namespace"),
                parameters=[params],
                output="screen",
            ),
            Node(
                package="mm_pc",
                executable="mm-field-sim",
                name="field_sim",
                namespace=LaunchConfiguration("namespace"),
                parameters=[params],
                output="screen",
                condition=IfCondition(LaunchConfiguration("field_sim")),
            ),
        ]
    )
