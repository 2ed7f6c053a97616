"""
Fatigue of notch and leaf hinges under a cyclic drive: Goodman and Soderberg safety factors.

Stress-life approach for fluctuating stress (R. G. Budynas and J. K. Nisbett, "Shigley's
Mechanical Engineering Design", 10th ed., McGraw-Hill 2015, Sec. 6-12). A point of the section
whose stress cycles between sigma_1 and sigma_2 carries the amplitude and mean

    sigma_a = |sigma_2 - sigma_1| / 2,     sigma_m = (sigma_1 + sigma_2) / 2,

and with the fully reversed fatigue strength S_e (at the material's cycle count), the ultimate
strength S_u and the yield strength S_y its safety factors n are, for a tensile mean,

    modified Goodman:   1/n = sigma_a / S_e + sigma_m / S_u,
    Soderberg:          1/n = sigma_a / S_e + sigma_m / S_y      (the more conservative line),

and for a compressive mean (sigma_m < 0) the amplitude alone, 1/n = sigma_a / S_e (Shigley
Sec. 6-12: a compressive midrange stress does not shorten the life), so in both cases

    u = 1/n = sigma_a / S_e + max(sigma_m, 0) / S,     S = S_u (Goodman) or S_y (Soderberg).

The points are the section's critical fibres, with their signed stresses
(``StressGeometry.fibres``): the two notch roots (K_t (+-6 m / (t h^2) + f_x / (t h))), the
two faces of both clamped ends of a leaf, and for a finite-element hinge the surface points
where its unit wrenches' stresses peak and their mirror images, each with its von Mises stress
signed as its tangential stress (engine/hinges/stress.py; in plane strain von Mises includes
sigma_zz = nu sigma_t, which cycles in proportion). A hinge's factor is that of its worst
point; the mechanism's, that of its worst hinge (the *critical hinge*).

S_e is the table's fatigue strength of polished specimens at its stated cycle count
(engine/hinges/materials.yaml): "infinite life" below means u <= 1 at that count (aluminium
alloys have no endurance limit; their figure is for 5e8 cycles). No Marin factor is applied;
a hinge's own ``sigma_e`` overrides the material's.

Every formula takes floats or HyperDual values (kinematics/hyperdual.py), so the sensitivities
and the optimiser differentiate the safety factors exactly; recordings (``envelope``) use the
largest cycle of the record, each point's extreme stresses (the first cycle rainflow counting
would extract).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Iterable, Optional

import numpy as np

from flexure_sim.engine.hinges.materials import missing_strength
from flexure_sim.engine.hinges.stress import StressGeometry
from flexure_sim.engine.kinematics import hyperdual as hd

if TYPE_CHECKING:
    from flexure_sim.engine.mechanism.parts import Mechanism

CRITERIA = ("goodman", "soderberg")


def positive_part(x):
    """Return max(x, 0) for floats or HyperDual values: (|x| + x) / 2."""
    return (np.abs(x) + x) * 0.5


def utilisation(amplitude, mean, sigma_e, sigma_mean):
    """
    Return 1/n = sigma_a / S_e + max(sigma_m, 0) / S (module docstring).

    ``sigma_mean``: S_u for the modified Goodman line, S_y for Soderberg's.
    """
    return amplitude / sigma_e + positive_part(mean) / sigma_mean


def cycle(geometry: StressGeometry, w1, w2) -> tuple[Any, Any]:
    """
    Return (sigma_a, sigma_m) per point, (..., k), of a cycle between wrenches w1 and w2.

    From the signed fibres (module docstring).
    """
    f1, f2 = geometry.fibres(w1), geometry.fibres(w2)
    return np.abs(f2 - f1) * 0.5, (f1 + f2) * 0.5


def envelope(geometry: StressGeometry, wrenches: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return (sigma_a, sigma_m) per point of the largest cycle of a record of wrenches (T, 3).

    Each point cycles between its smallest and largest stress of the record.
    """
    f = geometry.fibres(np.asarray(wrenches, dtype=float))
    lo, hi = f.min(axis=0), f.max(axis=0)
    return (hi - lo) * 0.5, (hi + lo) * 0.5


def utilisations(geometry: StressGeometry, amplitude, mean) -> dict:
    """Return {criterion: u per point} of a hinge with its strengths (``has_fatigue``)."""
    return {"goodman": utilisation(amplitude, mean, geometry.sigma_e, geometry.sigma_u),
            "soderberg": utilisation(amplitude, mean, geometry.sigma_e, geometry.sigma_y)}


def worst(values) -> tuple[Any, int]:
    """Return (the largest entry by real part, its index) of a 1-D float or HyperDual array."""
    k = int(np.argmax(hd.real(values)))
    return values[k], k


def _factor(u: float) -> Optional[float]:
    """Return n = 1/u; None for an unloaded hinge (u = 0: no finite factor)."""
    return 1.0 / u if u > 0.0 else None


def with_strengths(mechanism: "Mechanism") -> list[tuple[int, Any]]:
    """Return (index, hinge) of every hinge with a geometry and its fatigue strengths."""
    return [(i, h) for i, h in enumerate(mechanism.hinges)
            if h.stress is not None and h.stress.has_fatigue]


def table(entries: Iterable[tuple[str, StressGeometry, tuple]]) -> dict:
    """
    Return the fatigue of hinges by name.

    ``entries``: (hinge name, its StressGeometry with strengths, its (sigma_a, sigma_m) per point
    from ``cycle`` or ``envelope``). Each result: the Goodman-critical point's ``amplitude`` and
    ``mean`` (Pa), the safety factors ``goodman`` and ``soderberg`` (each its own worst point;
    None when unloaded), ``sigma_e`` with its ``cycles``, ``material``.
    """
    out = {}
    for name, g, (amplitude, mean) in entries:
        amplitude, mean = (np.atleast_1d(np.asarray(x, dtype=float)) for x in (amplitude, mean))
        u = utilisations(g, amplitude, mean)
        ug, k = worst(u["goodman"])
        us, _ = worst(u["soderberg"])
        if g.sigma_e is None or g.cycles is None:
            raise ValueError(f"hinge {name}: no fatigue strength sigma_e at a number of cycles")
        out[name] = {"amplitude": float(amplitude[k]), "mean": float(mean[k]),
                     "goodman": _factor(float(ug)), "soderberg": _factor(float(us)),
                     "sigma_e": float(g.sigma_e), "cycles": float(g.cycles),
                     "material": g.material}
    return out


def between(mechanism: "Mechanism", wrenches_1, wrenches_2) -> dict:
    """Return ``table`` of a cycle between two static states' wrenches (n, 3) each."""
    w1, w2 = np.asarray(wrenches_1, dtype=float), np.asarray(wrenches_2, dtype=float)
    return table((h.name, h.stress, cycle(h.stress, w1[i], w2[i]))
                 for i, h in with_strengths(mechanism))


def critical(fatigue: dict, criterion: str = "goodman") -> Optional[tuple[str, float]]:
    """Return (hinge, its safety factor) of the lowest factor; None if no hinge is loaded."""
    loaded = [(name, v[criterion]) for name, v in fatigue.items() if v[criterion] is not None]
    return min(loaded, key=lambda x: x[1]) if loaded else None


def no_fatigue_advice(mechanism: "Mechanism") -> Optional[str]:
    """
    Return what to add for the notch/leaf hinges without fatigue strengths, or None.

    One line naming the stiffness specifications (materials.missing_strength).
    """
    lacking = [h for h in mechanism.hinges if h.stress is not None and not h.stress.has_fatigue]
    if not lacking:
        return None
    keys = [k for k in dict.fromkeys(h.stress.key for h in lacking if h.stress is not None) if k]
    names = ", ".join(h.name for h in lacking)
    return (f"hinge{'s' if len(lacking) > 1 else ''} {names}: "
            + missing_strength("fatigue strength", " and ".join(keys)))


def infinite_life_input(sim, lower, upper, criterion: str = "goodman", tol: float = 1e-9,
                        max_iter: int = 40) -> tuple[Any, str]:
    """
    Return the drive input up to which cycling from ``lower`` has infinite life, and its hinge.

    Along the ray lower + s (upper - lower) (one number per drive, or a number for one drive),
    the s at which the critical hinge's safety factor is 1, by the secant method on
    max_h u_h(s) - 1 with static solves from the linear estimate at s = 1. Returns (the input at
    that s, in the form of ``upper``; the hinge). ValueError without fatigue strengths or load.
    """
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    w_lo = sim.static(lower).snapshot.wrenches

    def excess(s):
        found = critical(between(sim.mechanism, w_lo, sim.static(lo + s * (hi - lo)).snapshot
                                 .wrenches), criterion)
        if found is None:
            raise ValueError(no_fatigue_advice(sim.mechanism)
                             or "no hinge is loaded by this cycle (lower and upper inputs "
                             "give the same stresses)")
        return 1.0 / found[1] - 1.0, found[0]

    s0, (r0, _) = 1.0, excess(1.0)
    s1 = s0 / (r0 + 1.0)
    r1, hinge = excess(s1)
    for _ in range(max_iter):
        if abs(r1) < tol:
            point = lo + s1 * (hi - lo)
            return (float(point) if point.ndim == 0 else point), hinge
        s0, s1, r0 = s1, s1 - r1 * (s1 - s0) / (r1 - r0), r1
        r1, hinge = excess(s1)
    raise ValueError(f"the infinite-life input did not converge (1/n - 1 = {r1:.3g})")


def static_report(sim, lower, upper) -> dict:
    """
    Return the fatigue of cycling the drives between two static inputs, as JSON-ready data.

    {"cycle": [lower, upper], "hinges": ``between``'s table, "critical": {criterion: {"hinge",
    "safety"}} and "infinite_life": {criterion: {"input", "hinge"}} (None where not defined),
    "note": what to add for hinges without fatigue strengths, or None}.
    """
    mech = sim.mechanism
    hinges = between(mech, sim.static(lower).snapshot.wrenches,
                     sim.static(upper).snapshot.wrenches)
    out: dict[str, Any] = {"cycle": [_jsonable(lower), _jsonable(upper)], "hinges": hinges,
                           "critical": {}, "infinite_life": {},
                           "note": no_fatigue_advice(mech)}
    for criterion in CRITERIA:
        found = critical(hinges, criterion)
        out["critical"][criterion] = (None if found is None
                                      else {"hinge": found[0], "safety": found[1]})
        life = None
        if found is not None:
            point, hinge = infinite_life_input(sim, lower, upper, criterion)
            life = {"input": _jsonable(point), "hinge": hinge}
        out["infinite_life"][criterion] = life
    return out


def _jsonable(u):
    """Return a drive input as JSON: a number, or a list per drive."""
    arr = np.asarray(u, dtype=float)
    return float(arr) if arr.ndim == 0 else arr.tolist()
