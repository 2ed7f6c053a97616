"""Pictures of a finite-element hinge: its mesh, and the von Mises stress under a unit moment."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from flexure_sim.engine.hinges.fe.elastic import solve
from flexure_sim.engine.hinges.fe.mesh import mesh_profile
from flexure_sim.engine.hinges.fe.shapes import profile, ratios_of, shape


def plot_hinge(name: str, values: Mapping[str, float], nu: float, plane: str, n: int,
               directory: Path) -> list[str]:
    """Write ``<shape>_mesh.png`` and ``<shape>_stress.png`` into ``directory``; their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    s = shape(name)
    ell, t = float(values[s.lengths[0]]), float(values[s.plate])
    prof = profile(name, ratios_of(name, values))
    m = mesh_profile(prof, n)
    sol = solve(m, prof.half, nu, plane)
    mm = 1e3 * ell  # reference lengths -> mm
    xy = m.nodes * mm
    # Each six-node triangle drawn as its four straight sub-triangles (edges through the mid
    # nodes), so the curved outline shows.
    t6 = m.triangles
    sub = np.concatenate([t6[:, [0, 3, 5]], t6[:, [3, 1, 4]], t6[:, [5, 4, 2]],
                          t6[:, [3, 4, 5]]])
    tri = Triangulation(xy[:, 0], xy[:, 1], sub)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []

    fig, ax = plt.subplots(figsize=(7, 5))
    ax.triplot(tri, lw=0.3, color="k")
    ax.set_aspect("equal")
    ax.set_xlabel("x along the hinge [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(f"{name} hinge: {len(t6)} six-node triangles, {n} across a section "
                 f"(clamps at x = +-{prof.half * mm:.3g} mm)")
    path = directory / f"{name}_mesh.png"
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)
    paths.append(str(path))

    # Von Mises under a unit moment, Pa per N m: element-vertex values averaged at the nodes.
    vm = sol.von_mises[0] / (t * ell * ell)
    nodal = np.zeros(len(xy))
    count = np.zeros(len(xy))
    np.add.at(nodal, t6[:, :3], vm)
    np.add.at(count, t6[:, :3], 1.0)
    corner = count > 0
    nodal[corner] /= count[corner]
    for k, (a, b) in enumerate(((0, 1), (1, 2), (2, 0))):  # mid nodes: mean of their ends
        nodal[t6[:, 3 + k]] = 0.5 * (nodal[t6[:, a]] + nodal[t6[:, b]])
    fig, ax = plt.subplots(figsize=(7, 5))
    shade = ax.tripcolor(tri, nodal / 1e6, shading="gouraud", cmap="viridis")
    fig.colorbar(shade, ax=ax, label="von Mises stress per unit moment [MPa/(N m)]")
    peak = sol.peak_at[0] * mm
    ax.plot(peak[0], peak[1], "r+", ms=12, label=f"peak {sol.peak[0] / (t * ell * ell) / 1e6:.4g}"
            " MPa/(N m)")
    ax.legend(loc="upper right")
    ax.set_aspect("equal")
    ax.set_xlabel("x along the hinge [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(f"{name} hinge, plane {plane}, plate {t * 1e3:g} mm: unit moment on body B")
    path = directory / f"{name}_stress.png"
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)
    paths.append(str(path))
    return paths
