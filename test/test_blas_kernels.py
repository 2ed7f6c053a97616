"""
flexure_sim's choice of OpenBLAS kernels (``flexure_sim/__init__.py``).

The same bits on every x86-64 machine with AVX2 and FMA, whichever of OpenBLAS's kernels the
CPU would get.
"""
import ctypes
import glob
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

import flexure_sim

ROOT = Path(__file__).resolve().parent.parent


def _corename() -> str:
    """Return the kernel set the OpenBLAS bundled with NumPy runs (its own report)."""
    libs = Path(np.__file__).resolve().parent.parent / "numpy.libs"
    for path in glob.glob(str(libs / "*openblas*")):
        lib = ctypes.CDLL(path)
        for name in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename",
                     "openblas_get_corename64_", "openblas_get_corename"):
            function = getattr(lib, name, None)
            if function is not None:
                function.restype = ctypes.c_char_p
                return function().decode()
    raise AssertionError(f"no OpenBLAS with a corename function in {libs}")


def test_an_avx2_machine_runs_the_haswell_kernels_unless_the_user_chose():
    avx2 = os.uname().machine == "x86_64" and flexure_sim._x86_64_with_avx2()
    flags = Path("/proc/cpuinfo").read_text().split()
    assert avx2 == (os.uname().machine == "x86_64" and "avx2" in flags and "fma" in flags)
    if avx2:
        # This process imported flexure_sim before NumPy (conftest.py).
        assert _corename() == "Haswell"
    # A user's own choice stands (a fresh process that sets it before the import).
    code = ("import os; os.environ['OPENBLAS_CORETYPE'] = 'Prescott'; import flexure_sim; "
            "print(os.environ['OPENBLAS_CORETYPE'])")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout.split()
    assert out == ["Prescott"]
