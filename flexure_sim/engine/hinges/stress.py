"""
Peak stress in notch and leaf hinges from their wrench, and the stress ratio sigma / sigma_y.

The wrench (m, f_x, f_y) is the one a hinge exerts on its body B, in frame b at the hinge's
centre (solver.Snapshot.wrenches); its magnitude is the section load. Works on floats and
on HyperDual values (kinematics/hyperdual.py), so sensitivities of the peak stress are exact.

Circular notch hinge (stiffness.notch_stiffness: hole diameter D, neck thickness h, plate
thickness t; axial direction x of the hinge frame, as in microstage.sci). The thinnest
section is at the centre, where the moment is given, so the shear force has no lever arm
there. Nominal stresses: bending 6 |m| / (t h^2), axial |f_x| / (t h). The peak is

    sigma = K_t (6 |m| / (t h^2) + |f_x| / (t h)),

with K_t the elastic stress-concentration factor of two opposite U-notches in a member of
rectangular section under in-plane bending, W. C. Young and R. G. Budynas, "Roark's
Formulas for Stress and Strain", 7th ed. (McGraw-Hill, 2002), Table 17.1:

    K_t = C1 + C2 (2a/W) + C3 (2a/W)^2 + C4 (2a/W)^3,   Ci = ci1 + ci2 sqrt(a/r) + ci3 a/r,

for notch depth a, notch radius r and gross width W. A circular notch hinge is the case of
semicircular notches, a = r = D/2, W = h + D (a/r = 1, 2a/W = D/(h + D)); the factor tends to
1 for a thin neck between large holes (2a/W -> 1), as flexure hinges are designed. Checked
against Peterson's Chart 2.24 (opposite semicircular notches in bending; W. D. and D. F.
Pilkey, "Peterson's Stress Concentration Factors", 3rd ed., 2008) within 2 % for 2a/W <= 0.5,
and for thin necks against a plane-stress finite-element model: at the stage's h/D = 1/12
it is 1.2 % above (conservative), where Peterson's polynomial is 5.7 % high. Applying
the bending factor to the axial part too is conservative (the tension factor of the same
notch is smaller).

Leaf (cantilever) hinge (stiffness.cantilever_stiffness: length L along the hinge frame's y
axis, thickness T along x, width w; frame at the centroid). The shear force f_x adds a
moment f_x L / 2 at either end, so the largest end moment is |m| + |f_x| L / 2:

    sigma = 6 (|m| + |f_x| L / 2) / (w T^2) + |f_y| / (w T)

(straight beam, no concentration: the fillets at the clamps are not modelled).
Finite-element hinge (``model: fe``, engine/hinges/fe): the peak von Mises stress per unit
moment and force, c = (c_m, c_x, c_y), from the same solve as the stiffness
(fe.model.stress_coefficients); the stress of a wrench is bounded by

    sigma = c_m |m| + c_x |f_x| + c_y |f_y|

(von Mises is a norm of the stress tensor: exact for one component, conservative for
combinations, like the formulas above). The handbook K_t is for the closed forms only. Its
fibres are the surface points where the unit wrenches' stresses peak and their mirror images
(both notch roots, the four fillet roots of a leaf; fe/elastic.py): at a traction-free
surface the stress is uniaxial along it and linear in the wrench, so point p's von Mises
stress signed as its tangential stress is a_p . (m, f_x, f_y) with the rows a_p of
fe.model.fibre_coefficients. Their largest magnitude is at most the bound above.

Hinges with a ``matrix`` stiffness or a fitted polynomial law have no geometry: no stress.

Each hinge's ``StressGeometry`` (model, dimensions, and the strengths of its material:
sigma_y, and sigma_u, sigma_e for fatigue, engine/hinges/materials.py) is part of the loaded
mechanism (``Hinge.stress``, set by mechanism/loader.py from the very numbers the stiffness
formula used), so any Mechanism -- loaded, swept or recorded -- has its stresses without its
YAML file. ``fibres`` gives the signed stress at the section's critical points from the same
section terms as the peak stress (the fatigue criteria, engine/hinges/fatigue.py, cycle them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping, Optional

import numpy as np

from flexure_sim.engine.kinematics import hyperdual as hd

if TYPE_CHECKING:
    from flexure_sim.engine.mechanism.parts import Mechanism

#: Roark's Table 17.1, two U-notches in a rectangular member, in-plane bending: rows C1..C4,
#: columns (constant, sqrt(a/r), a/r), for 0.25 <= a/r <= 2 and 2 < a/r <= 50.
_ROARK_U_NOTCH_BENDING = (
    (
        (0.723, 2.845, -0.504),
        (-1.836, -5.746, 1.314),
        (7.254, -1.885, 1.646),
        (-5.140, 4.785, -2.456),
    ),
    (
        (0.833, 2.069, -0.009),
        (0.024, -5.383, 0.126),
        (-0.856, 6.460, -0.199),
        (0.999, -3.146, 0.082),
    ),
)


def u_notch_bending_factor(depth, radius, width):
    """
    Return K_t of two opposite U-notches (depth a, radius r) in a member of gross width W.

    The member is under in-plane bending (Roark, Table 17.1; module docstring); 0.25 <= a/r <= 50.
    """
    ar = depth / radius
    ar_real = float(hd.real(ar))
    if not 0.25 <= ar_real <= 50.0:
        raise ValueError(f"notch depth / radius {ar_real:.3g} outside Roark's range [0.25, 50]")
    rows = _ROARK_U_NOTCH_BENDING[0 if ar_real <= 2.0 else 1]
    x = 2.0 * depth / width
    root = np.sqrt(ar)
    c = [k0 + k1 * root + k2 * ar for k0, k1, k2 in rows]
    return c[0] + x * (c[1] + x * (c[2] + x * c[3]))


def notch_concentration(h, D):
    """
    K_t of a circular notch hinge (neck h, holes D) in bending.

    Semicircular U-notches, a = r = D/2 in a member of width h + D (module docstring).
    """
    return u_notch_bending_factor(0.5 * D, 0.5 * D, h + D)


def _notch_terms(wrench, D, h, t):
    """(K_t, signed bending stress 6 m / (t h^2), signed axial stress f_x / (t h)) at the neck."""
    m, fx = wrench[..., 0], wrench[..., 1]
    return notch_concentration(h, D), 6.0 * m / (t * h * h), fx / (t * h)


def notch_stress(wrench, D, h, t):
    """Peak stress (Pa) of a circular notch hinge under wrench (m, f_x, f_y)."""
    kt, bending, axial = _notch_terms(wrench, D, h, t)
    return kt * (np.abs(bending) + np.abs(axial))


def notch_fibres(wrench, D, h, t):
    """
    Signed stress (Pa) at the two notch roots, (..., 2): K_t (+-6 m / (t h^2) + f_x / (t h)).

    The peak stress is the larger magnitude of the two (|a + b| or |a - b| is |a| + |b|).
    """
    kt, bending, axial = _notch_terms(wrench, D, h, t)
    return _stack_last([kt * (bending + axial), kt * (axial - bending)])


def _leaf_terms(wrench, length, thickness, width):
    """Return (m, the shear force's moment f_x L / 2 at either end, f_y)."""
    m, fx, fy = wrench[..., 0], wrench[..., 1], wrench[..., 2]
    return m, 0.5 * length * fx, fy


def leaf_stress(wrench, length, thickness, width):
    """Peak stress (Pa) of a leaf hinge under wrench (m, f_x, f_y) at its centroid."""
    m, arm, fy = _leaf_terms(wrench, length, thickness, width)
    return 6.0 * (np.abs(m) + np.abs(arm)) / (
        width * thickness * thickness
    ) + np.abs(fy) / (width * thickness)


def fe_stress(wrench, c_m, c_x, c_y, rows=()):
    """Peak stress (Pa) of a finite-element hinge under wrench (m, f_x, f_y) (module docstring)."""
    return (c_m * np.abs(wrench[..., 0]) + c_x * np.abs(wrench[..., 1])
            + c_y * np.abs(wrench[..., 2]))


def fe_fibres(wrench, c_m, c_x, c_y, rows):
    """
    Signed stress (Pa) at a finite-element hinge's fibres, (..., k): a_p . (m, f_x, f_y).

    ``rows``: the fibres' coefficients a_p (module docstring), floats or HyperDual scalars.
    """
    plain = not any(isinstance(x, hd.HyperDual) for row in rows for x in row)
    if plain and not isinstance(wrench, hd.HyperDual):
        return np.asarray(wrench, dtype=float) @ np.array(rows, dtype=float).reshape(-1, 3).T
    return _stack_last([a * wrench[..., 0] + b * wrench[..., 1] + c * wrench[..., 2]
                        for a, b, c in rows])


def leaf_fibres(wrench, length, thickness, width):
    """
    Signed stress (Pa) at the two faces of both clamped ends, (..., 4).

    End moments m +- f_x L / 2, faces +-: +-6 (m +- f_x L / 2) / (w T^2) + f_y / (w T); the peak
    stress is the largest magnitude.
    """
    m, arm, fy = _leaf_terms(wrench, length, thickness, width)
    axial = fy / (width * thickness)
    ends = [6.0 * (m + arm) / (width * thickness * thickness),
            6.0 * (m - arm) / (width * thickness * thickness)]
    return _stack_last([axial + ends[0], axial - ends[0], axial + ends[1], axial - ends[1]])


def _stack_last(items):
    """Stack floats or HyperDual values along a new last axis."""
    if any(isinstance(x, hd.HyperDual) for x in items):
        return hd.stack(items, axis=-1)
    return np.stack(np.broadcast_arrays(*items), axis=-1)


#: Per stiffness model with a geometry: the keys of its stiffness formula the stress uses, in
#: the order of the stress function's arguments.
STRESS_KEYS = {"notch": ("D", "h", "t"), "cantilever": ("length", "thickness", "width")}
_STRESS_FUNCTIONS = {"notch": notch_stress, "cantilever": leaf_stress, "fe": fe_stress}
#: Signed stress at the critical points of the section (fatigue: engine/hinges/fatigue.py).
_FIBRE_FUNCTIONS = {"notch": notch_fibres, "cantilever": leaf_fibres, "fe": fe_fibres}


@dataclass(frozen=True)
class StressGeometry:
    """
    What one hinge's stress needs, and the strengths its stress is compared with.

    Its stiffness ``model`` (notch, cantilever or fe), the ``dimensions`` (m) of that model in
    the order of STRESS_KEYS[model] -- for ``fe`` the three peak-stress coefficients
    (Pa/(N m), Pa/N, Pa/N) and the fibres' coefficient rows, a tuple of 3-tuples --, the yield
    strength ``sigma_y`` (Pa) or None, and for fatigue
    (engine/hinges/fatigue.py) the ultimate strength ``sigma_u`` and the fully reversed fatigue
    strength ``sigma_e`` (Pa) at ``cycles`` cycles, or None; the ``material`` they come from
    (engine/hinges/materials.py) or None for numbers given in the file; ``key``: the stiffness
    specification's key in the mechanism file, for messages. Floats in a loaded mechanism;
    HyperDual values where mechanism/parameters.py varies them.
    """

    model: str
    dimensions: tuple
    sigma_y: Optional[Any] = None
    sigma_u: Optional[Any] = None
    sigma_e: Optional[Any] = None
    cycles: Optional[float] = None
    material: Optional[str] = None
    key: str = field(default="", compare=False)

    @classmethod
    def of(cls, model: str, values: Mapping[str, Any], sigma_y: Optional[Any] = None,
           **strengths: Any) -> Optional["StressGeometry"]:
        """
        From a stiffness model's numbers by key; None for a model without a geometry.

        ``strengths``: the other fields (materials.strengths gives them with sigma_y).
        """
        keys = STRESS_KEYS.get(model)
        if keys is None:
            return None
        return cls(model, tuple(values[k] for k in keys), sigma_y, **strengths)

    def stress(self, wrench):
        """Return the peak stress, Pa, under one wrench or an array (..., 3) (module docstring)."""
        return _STRESS_FUNCTIONS[self.model](wrench, *self.dimensions)

    def fibres(self, wrench):
        """
        Return the signed stress (Pa) at the section's critical points, (..., k).

        The fatigue criteria cycle it (engine/hinges/fatigue.py).
        """
        return _FIBRE_FUNCTIONS[self.model](wrench, *self.dimensions)

    @property
    def has_fatigue(self) -> bool:
        """Tell whether the fatigue criteria have their strengths (sigma_e, sigma_u, sigma_y)."""
        return None not in (self.sigma_e, self.sigma_u, self.sigma_y)

    def ratio_coefficients(self) -> np.ndarray:
        """
        Return the coefficients c (3,) with sigma / sigma_y = c .

        |wrench|: both formulas are sums of positive factors times |m|, |f_x|, |f_y|, so c is the
        stress of unit wrenches over sigma_y.
        """
        if self.sigma_y is None:
            raise ValueError(f"a {self.model} hinge without sigma_y has no stress ratio")
        return np.asarray(self.stress(np.eye(3)), dtype=float) / float(self.sigma_y)


def hinge_stress(wrench, geometry: Optional[StressGeometry]) -> Optional[Any]:
    """Peak stress of one hinge (floats or HyperDual), or None for a hinge without geometry."""
    return None if geometry is None else geometry.stress(wrench)


def stress_table(wrenches, mechanism: "Mechanism") -> dict:
    """
    Per notch/leaf hinge of the mechanism.

    Stress (Pa), yield strength (Pa or None) and their ratio (None without a yield strength);
    wrenches (n, 3) floats (Snapshot.wrenches).
    """
    out = {}
    for hinge, w in zip(mechanism.hinges, np.asarray(wrenches, dtype=float)):
        g = hinge.stress
        if g is None:
            continue
        s = float(g.stress(w))
        sy = None if g.sigma_y is None else float(g.sigma_y)
        out[hinge.name] = {"stress": s, "sigma_y": sy, "ratio": s / sy if sy else None,
                           "material": g.material}
    return out


def no_yield_advice(mechanism: "Mechanism") -> Optional[str]:
    """
    Return what to add for the notch/leaf hinges without a yield strength, or None if none lacks.

    One line naming the stiffness specifications (materials.missing_strength).
    """
    from flexure_sim.engine.hinges.materials import missing_strength

    lacking = [h for h in mechanism.hinges if h.stress is not None and h.stress.sigma_y is None]
    if not lacking:
        return None
    keys = list(dict.fromkeys(h.stress.key for h in lacking if h.stress is not None))
    names = ", ".join(h.name for h in lacking)
    return f"hinge{'s' if len(lacking) > 1 else ''} {names}: " + missing_strength(
        "yield strength", " and ".join(k for k in keys if k))


def ratio_map(mechanism: "Mechanism") -> tuple[list[str], np.ndarray, np.ndarray]:
    """
    Return the hinges with a yield strength.

    Returns (names, their indices, C (k, 3)) such that (C * |wrenches[indices]|).sum(1) are
    their stress ratios -- a few microseconds per call, for the node's per-tick diagnostics.
    """
    rows = [(h.name, i, h.stress.ratio_coefficients()) for i, h in enumerate(mechanism.hinges)
            if h.stress is not None and h.stress.sigma_y is not None]
    return ([r[0] for r in rows], np.array([r[1] for r in rows], dtype=int),
            np.array([r[2] for r in rows], dtype=float).reshape(-1, 3))


def peak_ratio(table: dict) -> Optional[tuple[str, float]]:
    """(hinge, largest stress ratio) of a stress table; None if no hinge has a yield strength."""
    ratios = [(name, v["ratio"]) for name, v in table.items() if v["ratio"] is not None]
    return max(ratios, key=lambda x: x[1]) if ratios else None


def stroke_limit(sim, tol: float = 1e-9, max_iter: int = 30) -> tuple[float, str]:
    """
    Drive input (m) at which the first hinge reaches yield.

    The secant method on max_h sigma_h / sigma_y,h (u) = 1 with static solves
    (``Simulation.static``), from the linear estimate u / ratio(u) at the drive's stroke. Returns
    (input, hinge).
    """
    def ratio(u):
        snap = sim.static(u).snapshot
        found = peak_ratio(stress_table(snap.wrenches, sim.mechanism))
        if found is None:
            raise ValueError(no_yield_advice(sim.mechanism) or "no hinge has a notch or leaf "
                             "geometry to compute stress from")
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
