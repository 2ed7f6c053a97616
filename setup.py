"""
Packaging for flexure_sim.

One layout serves colcon (ament_python) and plain pip:
- colcon honours setup.cfg's install_scripts, so console scripts land in lib/flexure_sim;
- pip ignores it, so small launchers are also installed as data_files under
  lib/flexure_sim/ (what `ros2 run` looks for), next to the ament index marker.

Dependencies: package.xml names the same ones by their rosdep keys. matplotlib is only needed
by `flexure-sim plot` (extra "plot"); the node and the other tools never import it. The extra
"test" is how colcon (and a Jazzy ament_python package) learns that `colcon test` runs pytest.
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
    install_requires=["numpy", "scipy", "numba", "PyYAML", "mcap", "mcap-ros2-support"],
    extras_require={
        "plot": ["matplotlib"],
        # flexure-sim sweep (Dask, Parquet, progress bar); imported only when a sweep runs.
        "sweep": ["dask", "distributed", "pyarrow", "tqdm"],
        "test": ["pytest", "rosbags"],
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
