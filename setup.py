"""Install script: ament_python for colcon, plain setuptools for pip."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "clusterfilter_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml")),
    ],
    python_requires=">=3.10",
    install_requires=[
        "setuptools",
        "numpy>=1.24",
        "scipy>=1.10",
        "scikit-learn>=1.3",
        "pyyaml>=6",
        "matplotlib>=3.6",
        "tqdm>=4.60",
        "rosbags>=0.10",
    ],
    zip_safe=True,
    maintainer="clusterfilter_ros maintainers",
    maintainer_email="maintainers@clusterfilter.invalid",
    description="Training-free drone detection in Livox lidar point clouds (ROS 2 Jazzy).",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "detector = clusterfilter_ros.ros.node:main",
            "clusterfilter = clusterfilter_ros.cli:main",
        ],
    },
)
