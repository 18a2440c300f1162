"""ROS 2 layer over daddy_core (rclpy guidance node)."""
