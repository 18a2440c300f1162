"""Launch the guidance node with the default parameters file."""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch_ros.actions import Node


def generate_launch_description():
    params = os.path.join(get_package_share_directory("daddy_ros"), "config", "guidance.yaml")
    return LaunchDescription([
        Node(package="daddy_ros", executable="guidance_node", name="daddy_guidance",
             parameters=[params], output="screen"),
    ])
