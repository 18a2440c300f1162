import os
import random

import pytest

# Every rclpy process started by the tests stays on loopback, in its own domain.
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# (1-101: the safe range on Linux, as the Makefile draws it)
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 101)))
os.environ.setdefault("ROS_PYTHON_CHECK_FIELDS", "1")


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", default=False,
                     help="run the slow acceptance solves (halo, DRO)")


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: long acceptance solve; run with --run-slow")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--run-slow"):
        return
    skip = pytest.mark.skip(reason="slow acceptance solve: make test-slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
