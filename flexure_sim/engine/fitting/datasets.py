"""
Synthetic (displacement, wrench) data for fitting polynomial hinges.

Also the studies of docs/polynomial_hinges.md.

- ``law_data``: exact wrenches of any hinge law (e.g. the twistor quadratic law, 4.7) at
  given displacements.
- ``cantilever_data``: a large-deflection leaf hinge (a planar Reissner beam: bending,
  shear and stretch, exact geometry), loaded by body B at its tip -- a hinge with no
  closed-form potential in twist(or) coordinates.
- ``error_table``: held-out error against order N and data size.

Chapter 7.1 (randomtest.sce) is reproduced in ``randomtest``.

Run ``python -m flexure_sim.engine.fitting.datasets --help`` for the command-line front end
(generate a CSV, print the held-out error table, reproduce Chapter 7.1).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence

import numpy as np

from flexure_sim.errors import as_array
from flexure_sim.engine.fitting.least_squares import FitError, fit_polynomial, predict_wrench
from flexure_sim.engine.laws.quadratic import QuadraticLaw
from flexure_sim.engine.kinematics.planar import rot
from flexure_sim.engine.fitting.randomtest import randomtest_report, randomtest_spread
from flexure_sim.engine.hinges.stiffness import notch_stiffness, shear_modulus
from flexure_sim.engine.fitting.wrench_data import WrenchData, write_wrench_csv

# ------------------------------------------------------------------- hinge laws

#: The notch hinge of Chapter 6 (D 3 mm, h 0.25 mm, t 20 mm, E 69 GPa, nu 0.33).
NOTCH_K = notch_stiffness(0.003, 0.00025, 0.02, 69.0e9, 0.33)


def sample_box(n: int, alpha_max: float, p_max: Sequence[float],
               rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Return n displacements uniform in |alpha| <= alpha_max, |p_i| <= p_max[i]."""
    alpha = rng.uniform(-alpha_max, alpha_max, n)
    p = rng.uniform(-1.0, 1.0, (n, 2)) * as_array("p_max", p_max, (2,))
    return alpha, p


def law_data(law, alpha: np.ndarray, p: np.ndarray, source: str = "<law>") -> WrenchData:
    """Exact m_b of a hinge law at the displacements (alpha, p)."""
    return WrenchData(alpha, p, predict_wrench(law, alpha, p), source)


def add_noise(data: WrenchData, relative: float, rng: np.random.Generator) -> WrenchData:
    """
    Gaussian noise on the wrench.

    Standard deviation ``relative`` times the RMS of each component (a measurement of finite
    resolution).
    """
    sd = relative * np.sqrt(np.mean(data.wrench**2, axis=0))
    return WrenchData(
        data.alpha, data.p, data.wrench + rng.normal(size=data.wrench.shape) * sd, data.source
    )


# --------------------------------------------------------- large-deflection cantilever

@dataclass(frozen=True)
class Leaf:
    """
    A leaf (cantilever) hinge along the hinge frame's y axis, as stiffness.cantilever_stiffness.

    length, thickness (in the plane), width (m), E (Pa), nu; shear correction 5/6. Body A holds the
    end at (0, -length/2), body B the end at (0, +length/2); frames a and b sit at the leaf's
    centre (its centre of stiffness), unrotated.
    """

    length: float = 0.010
    thickness: float = 0.001
    width: float = 0.005
    E: float = 3.45e9
    nu: float = 0.3
    shear_factor: float = 5.0 / 6.0

    @property
    def EI(self) -> float:
        return self.E * self.width * self.thickness**3 / 12.0

    @property
    def EA(self) -> float:
        return self.E * self.width * self.thickness

    @property
    def GA(self) -> float:
        return self.shear_factor * shear_modulus(self.E, self.nu) * self.width * self.thickness

    def small_displacement_stiffness(self) -> np.ndarray:
        """
        K at the centre for small displacements (linear Timoshenko beam).

        EI/L in rotation, 1/(L^3/(12 EI) + L/GA) in shear (x), EA/L axially (y);
        cantilever_stiffness without the shear compliance.
        """
        L = self.length
        return np.diag([self.EI / L, 1.0 / (L**3 / (12 * self.EI) + L / self.GA), self.EA / L])


def leaf_tip(
    leaf: Leaf, force: np.ndarray, base_moment: np.ndarray, steps: int = 400
) -> tuple[np.ndarray, np.ndarray]:
    """
    Integrate the planar Reissner beam from the held end, vectorised over n load cases.

    force (n, 2): the force body B exerts on the leaf (frame a; constant along the leaf);
    base_moment (n,): the moment the leaf carries at the held end. Along the arc length,
    theta' = m / EI, r' = (1 + N/EA) d_axial + (V/GA) d_shear, m' = -(r' x force), where N, V
    are the force's components along the leaf's axis d_axial = R(theta) e_y and across it
    d_shear = R(theta) e_x. Classical RK4 with ``steps`` steps.
    Returns r = (alpha, px, py) of frame b in frame a, and m_b (moment, fx, fy) in frame b.
    """
    force = as_array("force", force, (None, 2))
    base_moment = as_array("base_moment", base_moment, (len(force),))
    L = leaf.length
    h = L / steps
    n = len(force)
    y = np.zeros((n, 4))  # theta, rx, ry, m
    y[:, 2] = -0.5 * L
    y[:, 3] = base_moment

    def rhs(y):
        th, m = y[:, 0], y[:, 3]
        c, s = np.cos(th), np.sin(th)
        d_ax = np.column_stack([-s, c])
        d_sh = np.column_stack([c, s])
        N = np.sum(force * d_ax, axis=1)
        V = np.sum(force * d_sh, axis=1)
        dr = (1.0 + N / leaf.EA)[:, None] * d_ax + (V / leaf.GA)[:, None] * d_sh
        dm = -(dr[:, 0] * force[:, 1] - dr[:, 1] * force[:, 0])
        return np.column_stack([m / leaf.EI, dr, dm])

    for _ in range(steps):
        k1 = rhs(y)
        k2 = rhs(y + 0.5 * h * k1)
        k3 = rhs(y + 0.5 * h * k2)
        k4 = rhs(y + h * k3)
        y = y + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    alpha, tip, m_tip = y[:, 0], y[:, 1:3], y[:, 3]
    Rb = rot(alpha)
    p = tip + np.einsum("nij,j->ni", Rb, [0.0, -0.5 * L])
    arm = tip - p
    moment_b = m_tip + arm[:, 0] * force[:, 1] - arm[:, 1] * force[:, 0]
    f_b = np.einsum("nji,nj->ni", Rb, force)
    return np.column_stack([alpha, p]), np.column_stack([moment_b, f_b])


def cantilever_data(n: int, rng: np.random.Generator, leaf: Leaf = Leaf(), load: float = 0.25,
                    steps: int = 400) -> WrenchData:
    """
    Return n load cases of a leaf hinge at large deflection.

    Base moment and force uniform in |M| <= load EI/L, |V|, |N| <= 2 load EI/L^2 (load = 0.25 gives
    rotations up to about 0.5 rad and centre displacements up to 0.45 mm for the 10 mm leaf),
    integrated by ``leaf_tip``.
    """
    EI, L = leaf.EI, leaf.length
    base = rng.uniform(-1.0, 1.0, n) * load * EI / L
    force = rng.uniform(-1.0, 1.0, (n, 2)) * 2.0 * load * EI / L**2
    r, w = leaf_tip(leaf, force, base, steps)
    return WrenchData(
        r[:, 0], r[:, 1:], w, f"leaf L={L:g} m, t={leaf.thickness:g} m, load {load:g}"
    )


# ------------------------------------------------------------------ error table

MODELS: dict[str, Callable[[int, np.random.Generator], WrenchData]] = {
    # Twistor quadratic law (4.7) of the Chapter 6 notch hinge at large deflections:
    # rotations up to 1.5 rad, translations up to 0.2 mm.
    "twistor-quadratic": lambda n, rng: law_data(
        QuadraticLaw("twistor", NOTCH_K, 0 * NOTCH_K), *sample_box(n, 1.5, (2e-4, 2e-4), rng),
        source="twistor quadratic law (4.7), notch K, |alpha| <= 1.5 rad, |p| <= 0.2 mm"),
    # Twist quadratic law (3.4) of the notch hinge at rotations up to 2.5 rad: not a
    # polynomial in twistor coordinates; sigma terms (sigma_degree 1) help near pi.
    "twist-quadratic": lambda n, rng: law_data(
        QuadraticLaw("twist", NOTCH_K, 0 * NOTCH_K), *sample_box(n, 2.5, (2e-4, 2e-4), rng),
        source="twist quadratic law (3.4), notch K, |alpha| <= 2.5 rad, |p| <= 0.2 mm"),
    # Large-deflection leaf (the four-bar's hinge), rotations up to about 0.5 rad.
    "cantilever": lambda n, rng: cantilever_data(n, rng),
    # The notch hinge at the stage's operating range (hinge a turns 0.11 mrad and is
    # compressed by 0.19 um at the 1.35 um input): |alpha| <= 0.5 mrad, |p| <= 0.5 um.
    "notch": lambda n, rng: law_data(
        QuadraticLaw("twistor", NOTCH_K, 0 * NOTCH_K), *sample_box(n, 5e-4, (5e-7, 5e-7), rng),
        source="twistor quadratic law (4.7), notch K, |alpha| <= 0.5 mrad, |p| <= 0.5 um"),
}


def error_table(
    model: str,
    coordinates: str,
    orders: Sequence[int],
    sizes: Sequence[int],
    test_rows: int = 2000,
    seed: int = 1,
    sigma_degree: int = 0,
    noise: float = 0.0,
) -> dict[str, Any]:
    """
    Return the held-out error of fits of each order.

    The error is test_max_rel (the worst component's max |error| / max |value|) of fits
    of each order to the first ``size`` rows of one training draw, on a separate test draw.
    Entries are None where the order has more unknowns than the rows give equations.
    """
    rng = np.random.default_rng(seed)
    make = MODELS[model]
    test = make(test_rows, rng)
    train_all = make(max(sizes), rng)
    if noise:
        train_all = add_noise(train_all, noise, rng)
    table: dict[str, Any] = {
        "model": model,
        "coordinates": coordinates,
        "sigma_degree": sigma_degree,
        "noise": noise,
        "test_rows": test_rows,
        "seed": seed,
        "source": test.source,
        "orders": list(orders),
        "sizes": list(sizes),
        "test_max_rel": [],
        "train_max_rel": [],
        "unknowns": [],
    }
    for N in orders:
        row: list[Optional[float]] = []
        trow: list[Optional[float]] = []
        unknowns = None
        for size in sizes:
            try:
                res = fit_polynomial(
                    train_all.subset(slice(0, size)),
                    N,
                    coordinates,
                    sigma_degree=sigma_degree,
                    test=test,
                )
            except FitError:
                row.append(None)
                trow.append(None)
                continue
            unknowns = res.report["unknowns"]
            row.append(res.report["test_max_rel"])
            trow.append(res.report["train_max_rel"])
        table["test_max_rel"].append(row)
        table["train_max_rel"].append(trow)
        table["unknowns"].append(unknowns)
    return table


def format_table(table: dict[str, Any]) -> str:
    """Markdown table: rows = order, columns = training rows."""
    head = "| order | unknowns | " + " | ".join(f"{s} rows" for s in table["sizes"]) + " |"
    sep = "|" + "---|" * (len(table["sizes"]) + 2)
    lines = [head, sep]
    for N, unknowns, row in zip(table["orders"], table["unknowns"], table["test_max_rel"]):
        cells = ["too few rows" if v is None else f"{v:.2e}" for v in row]
        lines.append(
            f"| {N} | {unknowns if unknowns is not None else '-'} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


# ----------------------------------------------------------------------- command

def _ints(text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}"
        ) from None


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m flexure_sim.engine.fitting.datasets", description=__doc__.split("\n\n")[0]
    )
    sub = parser.add_subparsers(dest="command", required=True)
    gen = sub.add_parser("generate", help="write a CSV of synthetic measurements")
    gen.add_argument("model", choices=sorted(MODELS))
    gen.add_argument("--rows", type=int, default=200)
    gen.add_argument("--seed", type=int, default=1)
    gen.add_argument("--noise", type=float, default=0.0, help="relative wrench noise (default 0)")
    gen.add_argument("-o", "--output", required=True)
    st = sub.add_parser("study", help="print the held-out error table (order x training rows)")
    st.add_argument("model", choices=sorted(MODELS))
    st.add_argument("--coords", choices=("twistor", "twist"), default="twistor")
    st.add_argument("--orders", type=_ints, default=[2, 3, 4, 5, 6, 7, 8])
    st.add_argument("--rows", type=_ints, default=[30, 60, 120, 250, 500, 1000])
    st.add_argument("--test-rows", type=int, default=2000)
    st.add_argument("--seed", type=int, default=1)
    st.add_argument("--sigma-degree", type=int, choices=(0, 1), default=0)
    st.add_argument("--noise", type=float, default=0.0)
    st.add_argument("--json", action="store_true")
    rt = sub.add_parser(
        "randomtest", help="reproduce Chapter 7.1 (17 random configurations, order 4)"
    )
    rt.add_argument("--seed", type=int, default=22)
    rt.add_argument("--alpha-dist", type=float, default=math.pi / 4)
    rt.add_argument(
        "--seeds", type=int, default=0, help="also report the training error over seeds 0..N-1"
    )
    args = parser.parse_args(argv)
    if args.command == "generate":
        rng = np.random.default_rng(args.seed)
        data = MODELS[args.model](args.rows, rng)
        if args.noise:
            data = add_noise(data, args.noise, rng)
        write_wrench_csv(
            args.output,
            data,
            f"{data.source}; {args.rows} rows, seed {args.seed}, noise {args.noise:g}\n"
            "alpha, px, py: frame b in frame a (rad, m); m, fx, fy: wrench of body B on the "
            "element in frame b (N m, N)",
        )
        return 0
    if args.command == "study":
        table = error_table(
            args.model,
            args.coords,
            args.orders,
            args.rows,
            args.test_rows,
            args.seed,
            args.sigma_degree,
            args.noise,
        )
        if args.json:
            print(json.dumps(table))
        else:
            print(
                f"{table['source']}; fit in {args.coords} coordinates; held-out max relative "
                "wrench error on "
                f"{args.test_rows} test rows (seed {args.seed})"
            )
            print(format_table(table))
        return 0
    out = randomtest_report(args.seed, args.alpha_dist)
    if args.seeds:
        out["spread"] = randomtest_spread(args.seeds, args.alpha_dist)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
