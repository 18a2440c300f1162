"""One ament_python package, daddy_ros, installing three Python packages: daddy_core (the
solver, no ROS), daddy_ros (the rclpy guidance node) and daddy_sim (its simulator, closed loop,
campaigns, demo and recorder)."""
from glob import glob

from setuptools import find_packages, setup

package_name = "daddy_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["daddy_core", "daddy_core.*", "daddy_ros", "daddy_ros.*",
                                    "daddy_sim", "daddy_sim.*"]),
    package_data={"daddy_core.catalogue": ["cases/*.json", "run_times.json"],
                  "daddy_ros": ["plans/*.json"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools", "numpy", "scipy"],
    extras_require={"plots": ["matplotlib"], "record": ["mcap", "mcap-ros2-support"],
                    "campaigns": ["dask", "distributed", "tqdm"],
                    "analysis": ["pyarrow", "pandas", "oem"],
                    "docs": ["mkdocs", "mkdocs-material", "mkdocstrings[python]"]},
    zip_safe=True,
    maintainer="daddy team",
    maintainer_email="daddy@example.invalid",
    description="DADDy low-thrust trajectory optimizer (daddy_core) and its ROS 2 guidance node.",
    license="MIT",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            "daddy = daddy_core.cli:main",
            "guidance_node = daddy_ros.guidance_node:main",
            "gnc_demo = daddy_sim.demo:main",
            "daddy_campaign = daddy_sim.campaign_cli:main",
        ],
    },
)
