"""
Numba's disk cache of the stepping loop follows changes to every source compiled into it.

Numba keys a cached function on its own file only (numba issue #1833); ``engine.jit``
adds a digest of the sources a kernel module imports. The test edits a copy of the package
the way an upgrade or a developer does (one module changed, the loop's own file not) and runs
it in fresh processes, as a user's next run would.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from conftest import ROOT

RUN = (
    "from flexure_sim.engine.mechanism.loader import load_mechanism\n"
    "from flexure_sim.engine.solver.simulation import Simulation\n"
    f"sim = Simulation(load_mechanism({str(ROOT / 'config' / 'microstage.yaml')!r}))\n"
    "sim.set_command(1e-6)\n"
    "sim.step(5)\n"
    "print(repr(sim.snapshot().dissipated))\n"
)


def _dissipated(package_root) -> float:
    env = {**os.environ, "PYTHONPATH": str(package_root)}
    env.pop("NUMBA_DISABLE_JIT", None)
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", RUN], cwd=package_root, env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    return float(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_a_change_to_a_module_compiled_into_the_loop_reaches_the_cached_loop(tmp_path):
    package = tmp_path / "flexure_sim"
    # The source tree's Numba caches come along (copytree keeps the times Numba checks them
    # by), as in an installed package that has run before: only what the change below touches
    # is compiled, not every kernel twice (the test took ~30 s on a slow machine). A cache file
    # another process is writing right now (Numba's "<name>.tmp.<uid>", renamed into place when
    # complete: another pytest-xdist worker) stays behind: it can vanish while copytree runs.
    shutil.copytree(ROOT / "flexure_sim", package,
                    ignore=shutil.ignore_patterns("*.pyc", "*.nb[ic].tmp.*"))
    first = _dissipated(tmp_path)
    assert 0.0 < first < 1e-3
    caches = list((package / "engine" / "solver" / "__pycache__").glob("step_loop._advance-*.nbi"))
    assert caches, "the first run did not cache the compiled loop: the test would prove nothing"
    # Change only step_energy.py, which Numba inlines into step_loop.advance: each step's
    # dissipated energy becomes 1 J, so five steps give 5 J if the change is compiled in.
    energy = package / "engine" / "solver" / "step_energy.py"
    text = energy.read_text()
    line = "    return dissipated + 0.5 * h * rho, work, form1\n"
    assert text.count(line) == 1
    energy.write_text(text.replace(line, "    return 1.0, work, form1\n"))
    assert _dissipated(tmp_path) == 5.0
