"""mm-beagle alone: ``ros2 launch mm_beagle beagle.launch.py [backend:=sim] [beagle_params:=F]``.

The parameters come from ``beagle_params`` (default: the installed config/mm_beagle.yaml,
every parameter with its default); the argument is named for this node, not
``params_file``, so that robot.launch.py's other includes never see it. ``backend``
overrides the file's, since it is the one a user switches most (spidev on the board, sim
on a PC without sensors, remote for an agent). ``chips:=pmw3360,pln2033``,
``sim_chips:=...`` (one chip per device, comma-separated, or one for all) and
``frame_prefix:=r1/`` (many robots on one /tf) override the file's only when given.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def _node(context):
    """The node, with chips/sim_chips from the command line only when they were given."""
    overrides = {"backend": LaunchConfiguration("backend")}
    given = {
        "chips": LaunchConfiguration("chips").perform(context),
        "sim_chips": LaunchConfiguration("sim_chips").perform(context),
        "frame_prefix": LaunchConfiguration("frame_prefix").perform(context),
    }
    # the node splits "a,b"; frame_prefix is one string
    overrides.update({k: v if k == "frame_prefix" else [v] for k, v in given.items() if v})
    return [
        Node(
            package="mm_beagle",
            executable="mm-beagle",
            name="mm_beagle",
            namespace=LaunchConfiguration("namespace"),
            parameters=[LaunchConfiguration("beagle_params"), overrides],
            output="screen",
        )
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "beagle_params",
                default_value=PathJoinSubstitution(
                    [FindPackageShare("mm_beagle"), "config", "mm_beagle.yaml"]
                ),
                description="YAML parameters of mm_beagle",
            ),
            DeclareLaunchArgument(
                "backend", default_value="spidev", description="spidev | sim | remote"
            ),
            DeclareLaunchArgument(
                "chips",
                default_value="",
                description="chip per device, comma-separated, or one for all ('' = the file's)",
            ),
            DeclareLaunchArgument(
                "sim_chips",
                default_value="",
                description="sim backend: emulated chip per device ('' = the file's / chips)",
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
