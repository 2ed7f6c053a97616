"""Peak stress in notch and leaf hinges from their wrench, and the stress ratio sigma / sigma_y.

The wrench (m, f_x, f_y) is the one a hinge exerts on its body B, in frame b at the hinge's
centre (solver.Snapshot.wrenches); its magnitude is the section load. Works on floats and
on HyperDual values (hyperdual.py), so sensitivities of the peak stress are exact.

Circular notch hinge (stiffness.notch_stiffness: hole diameter D, neck thickness h, plate
thickness t; axial direction x of the hinge frame, as in microstage.sci). The thinnest
section is at the centre, where the moment is given, so the shear force has no lever arm
there. Nominal stresses: bending 6 |m| / (t h^2), axial |f_x| / (t h). The peak is

    sigma = K_t (6 |m| / (t h^2) + |f_x| / (t h)),  K_t = (1 + h / D)^(9/20),

with K_t the stress-concentration factor of a circular notch hinge in bending,
K_t = (1 + t_min / (2 R))^(9/20) with R = D / 2 the notch radius, the fit to Peterson's
charts given by S. T. Smith, "Flexures: Elements of Elastic Mechanisms" (Gordon and Breach,
2000) and used by N. Lobontiu, "Compliant Mechanisms: Design of Flexure Hinges" (CRC, 2003),
after W. D. Pilkey, "Peterson's Stress Concentration Factors" (Wiley, 1997). Applying the
bending factor to the axial part too is conservative (the tension factor of a shallow notch
is smaller).

Leaf (cantilever) hinge (stiffness.cantilever_stiffness: length L along the hinge frame's y
axis, thickness T along x, width w; frame at the centroid). The shear force f_x adds a
moment f_x L / 2 at either end, so the largest end moment is |m| + |f_x| L / 2:

    sigma = 6 (|m| + |f_x| L / 2) / (w T^2) + |f_y| / (w T)

(straight beam, no concentration: the fillets at the clamps are not modelled).
Hinges with a ``matrix`` stiffness have no geometry: no stress.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from . import hyperdual as hd


def notch_concentration(h, D):
    """K_t = (1 + h/D)^(9/20) of a circular notch hinge in bending (module docstring)."""
    return (1.0 + h / D) ** 0.45


def notch_stress(wrench, D, h, t):
    """Peak stress (Pa) of a circular notch hinge under wrench (m, f_x, f_y)."""
    m, fx = wrench[..., 0], wrench[..., 1]
    return notch_concentration(h, D) * (6.0 * np.abs(m) / (t * h * h) + np.abs(fx) / (t * h))


def leaf_stress(wrench, length, thickness, width):
    """Peak stress (Pa) of a leaf hinge under wrench (m, f_x, f_y) at its centroid."""
    m, fx, fy = wrench[..., 0], wrench[..., 1], wrench[..., 2]
    return 6.0 * (np.abs(m) + 0.5 * length * np.abs(fx)) / (
        width * thickness * thickness
    ) + np.abs(fy) / (width * thickness)


def _num(x):
    return x if isinstance(x, hd.HyperDual) else float(x)


def hinge_stress(wrench, geometry: dict) -> Optional[Any]:
    """Peak stress of one hinge from its stiffness model's numbers (``model`` and the keys of
    the mechanism file), or None for a hinge without geometry."""
    model = geometry.get("model")
    if model == "notch":
        return notch_stress(wrench, *(_num(geometry[k]) for k in ("D", "h", "t")))
    if model == "cantilever":
        return leaf_stress(wrench, *(_num(geometry[k]) for k in ("length", "thickness", "width")))
    return None


def stress_table(wrenches, geometry: list, names: list) -> dict:
    """Per hinge: stress (Pa), yield strength (Pa or None) and their ratio (None without a
    yield strength); wrenches (n, 3) floats."""
    out = {}
    for name, w, g in zip(names, np.asarray(wrenches, dtype=float), geometry):
        s = hinge_stress(w, g)
        if s is None:
            continue
        sy = float(g["sigma_y"]) if g.get("sigma_y") is not None else None
        out[name] = {"stress": float(s), "sigma_y": sy, "ratio": float(s) / sy if sy else None}
    return out


def peak_ratio(table: dict) -> Optional[tuple[str, float]]:
    """(hinge, largest stress ratio) of a stress table; None if no hinge has a yield strength."""
    ratios = [(name, v["ratio"]) for name, v in table.items() if v["ratio"] is not None]
    return max(ratios, key=lambda x: x[1]) if ratios else None


def stroke_limit(sim, geometry: list, tol: float = 1e-9, max_iter: int = 30) -> tuple[float, str]:
    """Drive input (m) at which the first hinge reaches yield: the secant method on
    max_h sigma_h / sigma_y,h (u) = 1 with static solves (``Simulation.static``), from the
    linear estimate u / ratio(u) at the drive's stroke. Returns (input, hinge)."""
    names = [h.name for h in sim.mechanism.hinges]

    def ratio(u):
        snap = sim.static(u).snapshot
        found = peak_ratio(stress_table(snap.wrenches, geometry, names))
        if found is None:
            raise ValueError("no hinge has a yield strength (sigma_y in its stiffness model)")
        return found[1] - 1.0, found[0]

    u0 = sim.drive.stroke[1] if sim.drive.stroke[1] > 0 else -sim.drive.stroke[0]
    r0, _ = ratio(u0)
    u1 = u0 / (r0 + 1.0)
    r1, hinge = ratio(u1)
    for _ in range(max_iter):
        if abs(r1) < tol:
            return u1, hinge
        u0, u1, r0 = u1, u1 - r1 * (u1 - u0) / (r1 - r0), r1
        r1, hinge = ratio(u1)
    raise ValueError(f"stroke limit did not converge (ratio - 1 = {r1:.3g} at {u1:.6g} m)")
