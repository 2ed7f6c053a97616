"""
``flexure-sim linearize -o FILE``: a linear model written for other tools (.npz, .mat, .json).

The exact linear model of engine/analysis/linear.py as state-space matrices with their names,
units and equilibrium, so that python-control, MATLAB or a controller's own code loads it.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from flexure_sim.engine.analysis import linear


def export_model(model: linear.LinearModel, path: Path, mechanism: str) -> Path:
    """
    Write A, B, C, D with names: .npz (numpy), .mat (MATLAB, scipy.io.savemat), .json.

    One input per drive (``input_names``; ``input_u0``: the drive inputs of the equilibrium, a
    number for one drive, else one per drive in that order).
    """
    u0 = model.u0 if np.ndim(model.u0) == 0 else np.asarray(model.u0, dtype=float)
    meta = {
        "mechanism": mechanism,
        "input_u0": u0,
        "state_names": model.state_names,
        "input_names": model.input_names,
        "output_names": model.output_names,
        "y0": model.y0.tolist(),
        "units": "SI; states are deviations of (z_F, v_F, u) from the equilibrium, outputs "
        "deviations from y0; the inputs are the drive commands (m, rad on theta; a force "
        "drive's N, N m)",
    }
    arrays = {"A": model.A, "B": model.B, "C": model.C, "D": model.D}
    if "displacement" in model.input_kinds:
        # x' = A x + B u + B1 u': in xi = x - B1 u the model is proper, xi' = A xi + (B + A B1) u,
        # y = C xi + (D + C B1) u + D1 u' + D2 u'' (D1, D2: the outputs that see the input's
        # rate and acceleration: damping forces, the driven body's inertia).
        arrays = {"A": model.A, "B": model.B + model.A @ model.B1, "C": model.C,
                  "D": model.D + model.C @ model.B1, "D1": model.D1, "D2": model.D2}
        meta["input_kinds"] = list(model.input_kinds)
        meta["units"] += (
            "; a displacement input (input_kinds) is the drive's displacement itself: the "
            "states are x - B1 u, x the deviations above, and y = C xi + D u + D1 u' + D2 u''")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        np.savez(path, **arrays, **{k: np.array(v) for k, v in meta.items()})
    elif suffix == ".mat":
        import scipy.io

        scipy.io.savemat(
            path,
            {
                **arrays,
                **{
                    k: (np.array(v, dtype=object) if isinstance(v, list) else v)
                    for k, v in meta.items()
                },
            },
        )
    elif suffix == ".json":
        meta["input_u0"] = np.asarray(u0).tolist()
        path.write_text(json.dumps({**{k: v.tolist() for k, v in arrays.items()}, **meta}))
    else:
        raise ValueError(f"-o {path}: the file name must end in .npz, .mat or .json")
    return path
