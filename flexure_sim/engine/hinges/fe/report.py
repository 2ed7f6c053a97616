"""
A hinge's finite-element stiffness next to every closed form that applies (``flexure-sim hinge``).

``compare`` solves the hinge in the plane the rule of model.py picks and in the other one,
evaluates the formulas of closed_forms.py and gives each formula's relative difference from
the finite-element stiffness, K_formula / K_fe - 1, per diagonal entry (rotation, the hinge
frame's x, its y). ``text`` lays that out as a table.
"""
from __future__ import annotations

from typing import Any, Mapping, Optional

import numpy as np

from flexure_sim.engine.hinges.fe import closed_forms, convergence, fe_model as model
from flexure_sim.engine.hinges.fe.shapes import ratios_of, shape
from flexure_sim.engine.hinges.fe.solves import DEFAULT_RESOLUTION, Case, solve

_OTHER = {"stress": "strain", "strain": "stress"}


def compare(name: str, values: Mapping[str, float], E: float, nu: float, plane: str = "auto",
            n: int = DEFAULT_RESOLUTION, study: bool = False) -> dict[str, Any]:
    """
    Return the comparison as plain data (JSON-ready).

    {"shape", "geometry", "E", "nu", "plane", "fe": {"K", "diag", "stress_coefficients",
    "peak_at", "seconds"}, "fe_other_plane": {"plane", "diag"}, "formulas": {formula:
    {"diag", "difference", "source"}}, "convergence": (with ``study``) the Richardson study}.
    """
    chosen = model.plane_of(name, values, plane)
    s = shape(name)
    ell = float(values[s.lengths[0]])
    res = solve(Case(name, ratios_of(name, values), nu, chosen, n))
    K = model.stiffness(name, values, E, nu, chosen, n)
    other = model.stiffness(name, values, E, nu, _OTHER[chosen], n)
    coeff = model.stress_coefficients(name, values, nu, chosen, n)
    fe_diag = np.diag(K)
    out: dict[str, Any] = {
        "shape": name, "geometry": {k: float(v) for k, v in values.items()},
        "E": float(E), "nu": float(nu), "plane": chosen, "resolution": n,
        "fe": {"K": K.tolist(), "diag": fe_diag.tolist(),
               "stress_coefficients": [float(c) for c in coeff],
               "peak_at": (res.peak_at * ell).tolist(), "seconds": res.seconds},
        "fe_other_plane": {"plane": _OTHER[chosen], "diag": np.diag(other).tolist(),
                           "difference": (np.diag(other) / fe_diag - 1.0).tolist()},
        "formulas": {},
    }
    for formula, Kf in closed_forms.evaluate(name, values, E, nu).items():
        diag = np.diag(Kf)
        out["formulas"][formula] = {
            "diag": [None if np.isnan(d) else float(d) for d in diag],
            "difference": [None if np.isnan(d) else float(d / f - 1.0)
                           for d, f in zip(diag, fe_diag)],
            "source": closed_forms.FORMULAS[formula][2],
        }
    if study:
        st = convergence.study(Case(name, ratios_of(name, values), nu, chosen, n))
        out["convergence"] = {
            "levels": st["levels"],
            "order": st["stiffness_order"].tolist(),
            "error": st["stiffness_error"].tolist(),
            "peak_error": st["peak_error"].tolist(),
        }
    return out


def _cell(value: Optional[float], diff: Optional[float]) -> str:
    if value is None:
        return f"{'-':>22}"
    text = f"{value:11.5g}"
    return f" {text} ({diff:+7.2%})" if diff is not None else f" {text}{'':10}"


def text(report: dict[str, Any]) -> str:
    """Return the comparison as a table (differences from the finite-element stiffness)."""
    axial = "y" if report["shape"] == "leaf" else "x"
    geo = ", ".join(f"{k} {v:g} m" for k, v in report["geometry"].items())
    lines = [
        f"{report['shape']} hinge: {geo}; E {report['E']:g} Pa, nu {report['nu']:g}",
        f"finite elements: plane {report['plane']} (model: fe's rule), "
        f"{report['resolution']} elements across a section",
        "",
        f"{'':30}{'Ko (N m/rad)':>22}{'Kx (N/m)':>22}{'Ky (N/m)':>22}   "
        f"(axial along {axial})",
        f"{'FE, plane ' + report['plane']:30}"
        + "".join(_cell(v, None) for v in report["fe"]["diag"]),
    ]
    o = report["fe_other_plane"]
    lines.append(f"{'FE, plane ' + o['plane']:30}"
                 + "".join(_cell(v, d) for v, d in zip(o["diag"], o["difference"])))
    for name, f in report["formulas"].items():
        cells = "".join(_cell(v, d) for v, d in zip(f["diag"], f["difference"]))
        lines.append(f"{name:30}{cells}")
    lines.append("")
    lines += [f"  {name}: {f['source']}" for name, f in report["formulas"].items()]
    c = report["fe"]["stress_coefficients"]
    lines.append("")
    lines.append(f"peak von Mises stress per unit load: {c[0]:.4g} Pa/(N m), "
                 f"{c[1]:.4g} Pa/N (x), {c[2]:.4g} Pa/N (y)")
    if "convergence" in report:
        cv = report["convergence"]
        lines.append(f"mesh convergence (n = {cv['levels']}): Richardson error of the "
                     f"reported stiffness {max(cv['error']):.2e}, observed orders "
                     + ", ".join(f"{p:.2f}" for p in cv["order"]))
    return "\n".join(lines)


#: The notch proportions of docs/hinges.md's table (h / R).
TABLE_H_OVER_R = (0.02, 0.05, 0.1, 1 / 6, 0.25, 0.5, 1.0)


def error_table(plane: str = "stress", nu: float = 0.33,
                h_over_r=TABLE_H_OVER_R) -> list[dict[str, Any]]:
    """
    Return, per h/R of a circular notch, each formula's differences from the FE stiffness.

    Rows {"h_over_r", "fe": diag (E = 1, h = 1, t = 1), formula: [dKo, dKx, dKy] or None}.
    """
    rows = []
    for q in h_over_r:
        geo = {"D": 2.0 / q, "h": 1.0, "t": 1.0}
        K = np.diag(model.stiffness("circular", geo, 1.0, nu, plane))
        row: dict[str, Any] = {"h_over_r": q, "fe": K.tolist()}
        for formula, Kf in closed_forms.evaluate("circular", geo, 1.0, nu).items():
            row[formula] = [None if np.isnan(d) else float(d / k - 1)
                            for d, k in zip(np.diag(Kf), K)]
        rows.append(row)
    return rows


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """Return error_table rows as the Markdown table of docs/hinges.md (percent)."""
    formulas = [f for f in closed_forms.FORMULAS if f in rows[0]]
    head = "| h/R | " + " | ".join(f"{f} Ko, Kx, Ky" for f in formulas) + " |"
    lines = [head, "|" + "---|" * (len(formulas) + 1)]
    for r in rows:
        cells = [", ".join("-" if d is None else f"{100 * d:+.1f}" for d in r[f])
                 for f in formulas]
        lines.append(f"| {r['h_over_r']:.3g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":  # python -m flexure_sim.engine.hinges.fe.report: the doc's tables
    for p in ("stress", "strain"):
        print(f"\nplane {p}: formula / FE - 1, percent\n")
        print(markdown_table(error_table(p)))
