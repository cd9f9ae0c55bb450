"""The usual set: ``ros2 launch mm_beagle robot.launch.py [backend:=sim] [monitor:=true]``.

mm-beagle (sensors), mm-odometry (pose from them) and mm-fusion (map pose from it and the
other sensors), each from its own launch file with its own parameters file:
``beagle_params:=``, ``odometry_params:=``, ``fusion_params:=`` (default: each package's
installed config); ``chips:=`` / ``sim_chips:=`` go to mm-beagle; ``monitor:=true`` adds
the Qt window (on a machine with a display). The launch files of each node are included,
not copied, so each node is configured in one place.

One robot of many: ``namespace:=r1 frame_prefix:=r1/`` puts the three nodes under /r1 and
their frames under r1/ (docs/system-ros.md, "Many robots").

Launch configurations are not scoped per include (ros2/launch: IncludeLaunchDescription
sets its arguments, and the included file's argument defaults, in the including context,
where the next include sees them). So every include sits in a scoped GroupAction (what it
sets is gone after it), gets every argument it shares with another include explicitly,
and each node's parameters file has its own argument name.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, IncludeLaunchDescription
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.substitutions import FindPackageShare


def _include(package: str, launch_file: str, arguments: dict, condition=None):
    """``package``'s installed launch/``launch_file`` with ``arguments``, in its own scope."""
    return GroupAction(
        [
            IncludeLaunchDescription(
                PythonLaunchDescriptionSource(
                    PathJoinSubstitution([FindPackageShare(package), "launch", launch_file])
                ),
                launch_arguments=arguments.items(),
            )
        ],
        scoped=True,
        condition=condition,
    )


def _beagle_node(namespace):
    """The mm_beagle node's full name for mm-monitor (a process, not a launch_ros Node, so
    neither ``namespace`` nor an outer PushRosNamespace reaches it by itself): the pushed
    namespace (launch_ros's ``ros_namespace``), then ``namespace`` (absolute: it alone, as
    for a Node), then ``mm_beagle``; mm-monitor makes a relative name absolute."""
    pushed = LaunchConfiguration("ros_namespace", default="")
    return PathJoinSubstitution([pushed, namespace, "mm_beagle"])


def _config(package: str, name: str):
    return PathJoinSubstitution([FindPackageShare(package), "config", name])


def generate_launch_description() -> LaunchDescription:
    namespace, prefix = LaunchConfiguration("namespace"), LaunchConfiguration("frame_prefix")
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
            DeclareLaunchArgument(
                "beagle_params",
                default_value=_config("mm_beagle", "mm_beagle.yaml"),
                description="YAML parameters of mm_beagle",
            ),
            DeclareLaunchArgument(
                "odometry_params",
                default_value=_config("mm_pc", "mm_odometry.yaml"),
                description="YAML parameters of mm_odometry",
            ),
            DeclareLaunchArgument(
                "fusion_params",
                default_value=_config("mm_pc", "mm_fusion.yaml"),
                description="YAML parameters of mm_fusion",
            ),
            DeclareLaunchArgument(
                "namespace", default_value="", description="namespace of the three nodes"
            ),
            DeclareLaunchArgument(
                "frame_prefix",
                default_value="",
                description="put before every frame id of the three nodes, e.g. r1/ ('' = files')",
            ),
            _include(
                "mm_beagle",
                "beagle.launch.py",
                {
                    "beagle_params": LaunchConfiguration("beagle_params"),
                    "backend": LaunchConfiguration("backend"),
                    "chips": LaunchConfiguration("chips"),
                    "sim_chips": LaunchConfiguration("sim_chips"),
                    "namespace": namespace,
                    "frame_prefix": prefix,
                },
            ),
            _include(
                "mm_pc",
                "odometry.launch.py",
                {
                    "odometry_params": LaunchConfiguration("odometry_params"),
                    "beagle": "mm_beagle",
                    "namespace": namespace,
                    "frame_prefix": prefix,
                },
            ),
            _include(
                "mm_pc",
                "fusion.launch.py",
                {
                    "fusion_params": LaunchConfiguration("fusion_params"),
                    "field_sim": "false",
                    "namespace": namespace,
                    "frame_prefix": prefix,
                },
            ),
            _include(
                "mm_pc",
                "monitor.launch.py",
                {"beagle": _beagle_node(namespace)},
                condition=IfCondition(LaunchConfiguration("monitor")),
            ),
        ]
    )
