"""
Packaging for flexure_sim.

One layout serves colcon (ament_python) and plain pip:
- colcon honours setup.cfg's install_scripts, so console scripts land in lib/flexure_sim;
- pip ignores it, so small launchers are also installed as data_files under
  lib/flexure_sim/ (what `ros2 run` looks for), next to the ament index marker.

Dependencies: package.xml names the same ones by their rosdep keys (the optional "sweep" and
"fe" extras are pip-only: a ROS install adds them with pip when it needs them). matplotlib is
only needed by `flexure-sim plot` (extra "plot"); the node and the other tools never import it.
The extra "test" is how colcon (and a Jazzy ament_python package) learns that `colcon test`
runs pytest.
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "flexure_sim"
EXECUTABLES = {
    "stage_node": "flexure_sim.node.stage.stage_node:main",
    "replay": "flexure_sim.node.apps.replay:main",
    "pi_controller": "flexure_sim.node.apps.pi_controller:main",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    # The material table is data of the code that reads it (engine/hinges/materials.py):
    # package data, so every install layout has it next to its module.
    package_data={PACKAGE: ["py.typed", "engine/hinges/materials.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml")) + sorted(glob("config/*.xml"))),
        (f"share/{PACKAGE}/config/examples", sorted(glob("config/examples/*"))),
        (f"share/{PACKAGE}/config/studies", sorted(glob("config/studies/*.yaml"))),
        (f"share/{PACKAGE}/launch", sorted(glob("launch/*.launch.py"))),
        (f"lib/{PACKAGE}", [f"scripts/ros2run/{name}" for name in sorted(EXECUTABLES)]),
    ],
    # The oldest versions the code needs, as requirements.txt states them (test_packaging.py
    # holds the two lists equal): NumPy 1.26 is Jazzy's on Ubuntu 24.04; mcap 1.6's Writer (with
    # flush()) is the reference the recorder's writer is tested against.
    install_requires=["numpy>=1.26", "scipy>=1.11", "numba>=0.59", "PyYAML>=6.0", "mcap>=1.6",
                      "mcap-ros2-support>=0.5"],
    extras_require={
        "plot": ["matplotlib>=3.7"],
        # flexure-sim sweep (Dask, Parquet, progress bar); imported only when a sweep runs.
        "sweep": ["dask>=2024.1", "distributed>=2024.1", "pyarrow>=14", "tqdm>=4.66"],
        # model: fe hinges and flexure-sim hinge; imported only when a hinge is meshed.
        "fe": ["gmsh>=4.11", "scikit-fem>=9.0"],
        "test": ["pytest>=7.4", "rosbags>=0.10"],
    },
    zip_safe=True,
    maintainer="flexure_sim developers",
    maintainer_email="flexure-sim@example.com",
    description="Twistor-based simulation of planar flexure mechanisms, with a ROS 2 stage node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [f"{name}={target}" for name, target in EXECUTABLES.items()]
        + ["flexure-sim=flexure_sim.cli:main"],
    },
)
