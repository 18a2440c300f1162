"""Launch the guidance node.

    ros2 launch daddy_ros guidance.launch.py [namespace:=/sc1] [params_file:=my.yaml]
        [log_level:=debug] [autostart:=false]

``namespace``: the node's namespace (its topics, services and action move with it; the
bundled parameters file applies in any namespace). ``params_file``: default the installed
``config/guidance.yaml``. ``log_level``: the node's logger level. ``autostart``: false leaves
the lifecycle transitions to a lifecycle manager (msg_docs/README.md, Lifecycle).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

ARGUMENTS = {
    "namespace": ("", "namespace of the guidance node"),
    "params_file": (PathJoinSubstitution([FindPackageShare("daddy_ros"), "config",
                                          "guidance.yaml"]),
                    "parameters file (default: the installed config/guidance.yaml)"),
    "log_level": ("info", "logger level of the node (debug, info, warn, error)"),
    "autostart": ("true", "configure and activate at start (false: a lifecycle manager does)"),
}


def generate_launch_description():
    args = [DeclareLaunchArgument(name, default_value=default, description=text)
            for name, (default, text) in ARGUMENTS.items()]
    node = Node(package="daddy_ros", executable="guidance_node", name="daddy_guidance",
                namespace=LaunchConfiguration("namespace"),
                parameters=[LaunchConfiguration("params_file"),
                            {"autostart": ParameterValue(LaunchConfiguration("autostart"),
                                                         value_type=bool)}],
                arguments=["--ros-args", "--log-level", LaunchConfiguration("log_level")],
                output="screen")
    return LaunchDescription(args + [node])
