"""daddy_core: DADDy low-thrust trajectory optimisation (no ROS)."""
__version__ = "0.1.0"
