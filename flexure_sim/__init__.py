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


def _x86_64_with_avx2() -> bool:
    """Tell whether every CPU of this (Linux) machine has AVX2 and FMA (``/proc/cpuinfo``)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as cpuinfo:
            flags = [line.split(":", 1)[1].split() for line in cpuinfo
                     if line.startswith("flags")]
    except OSError:
        return False
    return bool(flags) and all("avx2" in f and "fma" in f for f in flags)


# OpenBLAS picks its kernels by the CPU it finds (DYNAMIC_ARCH): on a CPU with AVX-512 it takes
# its SkylakeX kernels, elsewhere on x86-64 its Haswell ones, and the two round differently in
# the last bits. The stage's linearization then differed in its last bits between two 2-core
# VMs (AMD Zen 4 with AVX-512 against one without), and with it the golden figures and the
# recorded bytes of a lockstep run (test_golden_engine.py, test_golden_recording.py). On every
# x86-64 CPU with AVX2 and FMA the Haswell kernels are taken unless the user chose otherwise,
# so that a run gives the same bits on any such machine; for the engine's small matrices the
# two were as fast (interleaved runs of the stage's step response, 4.0-6.2 ms either way on the
# AVX-512 VM, whose run-to-run noise is larger than any difference). Like the thread count, it
# takes effect when flexure_sim is imported before NumPy.
if _os.uname().machine == "x86_64" and _x86_64_with_avx2():
    _os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")

__version__ = "0.1.0"
