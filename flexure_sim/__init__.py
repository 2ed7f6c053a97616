"""
flexure_sim: planar flexure mechanisms with the twistor-based potential energy method.

Layers, visible in the folder listing (each imports only the ones above it):
  engine/     the physics, no ROS (kinematics -> hinge laws -> mechanism -> solver)
  recording/  rosbag2-format MCAP writing and reading
  node/       the ROS 2 nodes: stage_node, replay
  tools/      the flexure-sim command-line tools (analyse, plot, export, fit, bench, measure)
  cli.py      the flexure-sim entry point
"""
import os as _os

# The engine works on small matrices (25x25 for the stage), where a multi-threaded BLAS
# only adds synchronisation: on a loaded 2-core machine it made a linearization 8x slower
# (8 ms instead of 0.9 ms, BENCHMARKS.md). Single-threaded BLAS is the default unless the
# user chose otherwise; it takes effect when flexure_sim is imported before NumPy.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
