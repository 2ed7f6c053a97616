"""
``flexure-sim fit``: fit a polynomial hinge law to measured wrenches (dissertation Ch. 7).

    flexure-sim fit DATA.csv --order N [--coords twistor|twist] [-o hinge.yaml]
                    [--test TEST.csv] [--regularization L] [--sigma-degree 0|1] [--json]

DATA.csv has columns alpha, px, py (frame b relative to frame a, in a: rad, m) and m, fx, fy
(the wrench body B exerts on the element, in frame b, moment about b's origin: N m, N).
The output YAML is what a mechanism's hinge references as ``law: {polynomial: hinge.yaml}``.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from flexure_sim import __version__
from flexure_sim.engine.fitting.least_squares import FitError, fit_polynomial, summarize_errors
from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.laws.polynomial import MAX_ORDER
from flexure_sim.engine.mechanism.polynomial_files import save_law
from flexure_sim.engine.fitting.wrench_data import read_wrench_csv


def register(subparsers) -> None:
    """Add the ``fit`` subcommand."""
    p = subparsers.add_parser(
        "fit",
        help="fit a polynomial hinge law to measured (displacement, wrench) pairs",
        description="Fit a polynomial hinge law (eq. 4.69 or 3.67) to measured wrenches, by "
        "linear least squares as makeAB_Q.sci does (dissertation Ch. 7, Appendix B).",
    )
    p.add_argument("data", help="CSV with columns alpha, px, py, m, fx, fy")
    p.add_argument("--order", type=int, required=True,
                   help=f"polynomial order N (2..{MAX_ORDER}; up to 8 is well conditioned)")
    p.add_argument("--coords", choices=("twistor", "twist"), default="twistor",
                   help="law coordinates: twistor (sigma, xi, x1, x2; eq. 4.69, default) "
                        "or twist (tau, t1, t2; eq. 3.67)")
    p.add_argument("-o", "--output", help="write the fitted law to this YAML file")
    p.add_argument("--test", help="held-out CSV (same columns): report the fit's error on it")
    p.add_argument(
        "--regularization",
        type=float,
        default=0.0,
        help="ridge parameter lambda >= 0 on the scaled, unit-column system (default 0: none)",
    )
    p.add_argument(
        "--sigma-degree",
        type=int,
        choices=(0, 1),
        default=0,
        help="twistor only: highest power of sigma (0, default; 1 helps for rotations near pi)",
    )
    p.add_argument("--json", action="store_true", help="print the fit report as one JSON object")
    p.set_defaults(handler=run)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run(args: argparse.Namespace) -> int:
    """Handle the command: exit 0 on success, 2 with a message on stderr for any bad input."""
    try:
        out = _fit(args)
    except FlexureSimError as exc:  # DataError, FitError: one line, exit 2
        print(f"flexure-sim fit: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(
            f"flexure-sim fit: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr
        )
        return 2
    report = out["report"]
    if not report["stable_at_rest"]:
        print(
            "flexure-sim fit: warning: the fitted stiffness at rest is not positive definite, so "
            "the unstressed "
            "pose is not a stable equilibrium; a mechanism will refuse this law (more data near "
            "rest, a lower "
            "order or --regularization may help)",
            file=sys.stderr,
        )
    if args.json:
        print(json.dumps(out))
    else:
        _print(out)
    return 0


def _fit(args: argparse.Namespace) -> dict[str, Any]:
    if not np.isfinite(args.regularization) or args.regularization < 0:
        raise FitError(f"--regularization {args.regularization!r}: must be a non-negative number")
    data = read_wrench_csv(args.data)
    test = read_wrench_csv(args.test) if args.test else None
    result = fit_polynomial(data, args.order, args.coords, regularization=args.regularization,
                            sigma_degree=args.sigma_degree, test=test)
    report = result.report
    if args.output:
        provenance = {
            "tool": f"flexure-sim fit (flexure_sim {__version__})",
            "data": str(args.data),
            "data_sha256": _sha256(Path(args.data)),
            "test_data": str(args.test) if args.test else None,
            "options": {
                "order": args.order,
                "coords": args.coords,
                "regularization": args.regularization,
                "sigma_degree": args.sigma_degree,
            },
        }
        fit_section = {k: report[k] for k in (
            "rows", "equations", "unknowns", "rank", "condition_number", "regularization",
            "train_rms", "train_max_abs", "train_max_rel", "stable_at_rest")}
        for k in ("test_rms", "test_max_abs", "test_max_rel"):
            if k in report:
                fit_section[k] = report[k]
        if test is not None:
            fit_section["test_rows"] = report["test"]["rows"]
        save_law(result.law, args.output, {"fit": fit_section, "provenance": provenance})
    return {
        "data": str(args.data),
        "test_data": args.test,
        "output": args.output,
        "report": report,
        **{
            k: report[k]
            for k in (
                "train_rms",
                "train_max_abs",
                "train_max_rel",
                "test_rms",
                "test_max_abs",
                "test_max_rel",
            )
            if k in report
        },
    }


def _print(out: dict[str, Any]) -> None:
    r = out["report"]
    print(f"data: {out['data']} ({r['rows']} rows, {r['equations']} equations)")
    print(
        f"law: order {r['order']} polynomial in {r['coordinates']} coordinates, {r['unknowns']} "
        "coefficients, "
        f"rank {r['rank']}, condition number {r['condition_number']:.3g}"
        + (f", regularization {r['regularization']:g}" if r["regularization"] else "")
    )
    if r["equations_per_unknown"] < 2:
        print(
            f"note: only {r['equations_per_unknown']:.2g} equations per unknown: the training "
            "error says little; "
            "judge the fit by --test"
        )
    print(f"train: worst relative error {r['train_max_rel']:.3g}")
    print(summarize_errors(r, "train"))
    if "test" in r:
        print(
            f"test ({out['test_data']}, {r['test']['rows']} rows): worst relative error "
            f"{r['test_max_rel']:.3g}"
        )
        print(summarize_errors(r, "test"))
    K = np.array(r["stiffness_at_rest"])
    print("stiffness at rest (moment first, hinge frame):")
    for row in K:
        print("  " + "  ".join(f"{v:12.5g}" for v in row))
    if out["output"]:
        print(f"wrote {out['output']}")
