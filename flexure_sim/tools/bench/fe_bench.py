"""
Benchmark of the finite-element hinge (``model: fe``): one hinge's solve and the cached load.

- solve: the stage's notch hinge (D 3 mm, h 0.25 mm, t 20 mm, plane strain, the default
  resolution) meshed by gmsh and solved by scikit-fem with an empty cache, median of 3
  (gmsh and scikit-fem already imported; goal < 5 s);
- cached: the same hinge's stiffness read from the disk cache (median of 50), and a second
  load of config/examples/microstage_fe.yaml, seven such hinges (median of 10; goal < 10 ms).
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from flexure_sim.engine.hinges.fe import fe_model as model
from flexure_sim.engine.hinges.fe.solves import DEFAULT_RESOLUTION
from flexure_sim.engine.mechanism.builtins import builtin_dir, searched
from flexure_sim.engine.mechanism.loader import ConfigError, mechanism_from_dict
from flexure_sim.engine.mechanism.yaml_files import read_yaml

GEOMETRY = {"D": 3e-3, "h": 0.25e-3, "t": 0.02}
#: The stage with finite-element hinges, among the built-ins' examples.
STAGE = Path("examples") / "microstage_fe.yaml"


def stage_file() -> Path:
    """Return `STAGE` where this install (or checkout) keeps its built-in mechanisms."""
    folder = builtin_dir()
    if folder is None:
        raise ConfigError(f"{STAGE}: no built-in mechanisms found in {searched()}")
    return folder / STAGE


def _median(fn, n: int) -> float:
    times = []
    for _ in range(n):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def bench_fe_hinge() -> dict:
    """Return {"solve_s", "cached_stiffness_s", "cached_stage_load_s", "resolution"}."""
    old = os.environ.get("FLEXURE_SIM_CACHE")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            import gmsh  # noqa: F401  (imports are not the solve's cost)
            import skfem  # noqa: F401

            def cold():
                os.environ["FLEXURE_SIM_CACHE"] = tempfile.mkdtemp(dir=tmp)
                model.stiffness("circular", GEOMETRY, 69e9, 0.33)

            solve_s = _median(cold, 3)
            os.environ["FLEXURE_SIM_CACHE"] = tmp
            model.stiffness("circular", GEOMETRY, 69e9, 0.33)
            cached = _median(lambda: model.stiffness("circular", GEOMETRY, 69e9, 0.33), 50)
            path = stage_file()
            data = read_yaml(path, ConfigError)
            mechanism_from_dict(data, source=str(path))
            stage = _median(lambda: mechanism_from_dict(data, source=str(path)), 10)
    finally:
        if old is None:
            os.environ.pop("FLEXURE_SIM_CACHE", None)
        else:
            os.environ["FLEXURE_SIM_CACHE"] = old
    return {"solve_s": solve_s, "cached_stiffness_s": cached, "cached_stage_load_s": stage,
            "resolution": DEFAULT_RESOLUTION}
