"""
``flexure-sim hinge``: finite-element stiffness next to the closed forms; stress; wrench data.

The stiffness at the hinge frame, its stress per unit load, and large-deflection wrench data
for ``flexure-sim fit``.

    flexure-sim hinge SHAPE KEY=VALUE... [--plane auto|stress|strain] [--resolution N]
                      [--convergence] [--json]
    flexure-sim hinge --from MECHANISM:MODEL [...]
    flexure-sim hinge ... --samples N --alpha-max RAD [--seed S] -o DATA.csv
    flexure-sim hinge ... --plot DIR

SHAPE is circular, elliptical, corner_filleted or leaf; KEY=VALUE gives its lengths (m, see
docs/hinges.md), E (Pa) and nu. ``--from`` takes a stiffness model of a mechanism file
(``microstage:notch``): a ``notch`` model is the circular shape, a ``cantilever`` the leaf,
an ``fe`` model itself. ``--samples`` solves the hinge with large deflection over its working
range and writes the CSV ``flexure-sim fit`` reads (columns alpha, px, py, m, fx, fy: m_b, the
wrench body B exerts on the element), and reports how far the twistor quadratic law of the
finite-element stiffness is from those wrenches.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from flexure_sim.engine.fitting.least_squares import wrench_errors
from flexure_sim.engine.fitting.wrench_data import WrenchData, write_wrench_csv
from flexure_sim.engine.hinges import materials
from flexure_sim.engine.hinges.fe import fe_model
from flexure_sim.engine.hinges.fe import report as fe_report
from flexure_sim.engine.hinges.fe.samples import wrench_samples, working_box
from flexure_sim.engine.hinges.fe.shapes import SHAPES
from flexure_sim.engine.hinges.fe.solves import DEFAULT_RESOLUTION
from flexure_sim.engine.laws.quadratic import QuadraticLaw
from flexure_sim.engine.mechanism.fe_block import fe_numbers
from flexure_sim.engine.mechanism.loader import ConfigError, resolve_mechanism_path
from flexure_sim.engine.mechanism.values import Ctx
from flexure_sim.engine.mechanism.yaml_files import read_yaml
from flexure_sim.errors import FlexureSimError

#: Closed-form models of a mechanism file -> (shape, {shape key: model key}).
_FROM = {"notch": ("circular", {"D": "D", "h": "h", "t": "t"}),
         "cantilever": ("leaf", {"length": "length", "thickness": "thickness",
                                 "width": "width"})}


def register(subparsers) -> None:
    """Add the ``hinge`` subcommand."""
    p = subparsers.add_parser(
        "hinge",
        help="a hinge's finite-element stiffness next to the closed forms; its wrench data",
        description="Solve a hinge's geometry by finite elements (gmsh, scikit-fem) and print "
        "its 3x3 stiffness at the hinge frame next to every closed-form formula that applies, "
        "with the differences (docs/hinges.md).",
    )
    p.add_argument("shape", nargs="?", choices=sorted(SHAPES), help="the hinge's shape")
    p.add_argument("values", nargs="*", metavar="KEY=VALUE",
                   help="the shape's lengths (m), E (Pa) and nu, e.g. D=3e-3 h=0.25e-3 t=0.02 "
                        "E=69e9 nu=0.33")
    p.add_argument("--from", dest="source", metavar="MECHANISM:MODEL",
                   help="take the hinge from a stiffness model of a mechanism file "
                        "(a built-in name or a YAML path), e.g. microstage:notch")
    p.add_argument("--plane", choices=("auto", "stress", "strain"),
                   help="plane stress or strain (default: the model's, else auto: strain when "
                        "the plate is at least as thick as the hinge is long)")
    p.add_argument("--resolution", type=int,
                   help=f"elements across a section (default {DEFAULT_RESOLUTION})")
    p.add_argument("--convergence", action="store_true",
                   help="also run the mesh convergence study (resolutions n/2, n, 2n)")
    p.add_argument("--samples", type=int, metavar="N",
                   help="write N large-deflection wrench samples (needs --alpha-max, -o)")
    p.add_argument("--alpha-max", type=float, metavar="RAD",
                   help="largest rotation of the working range (rad)")
    p.add_argument("--seed", type=int, default=0, help="seed of the sample draw (default 0)")
    p.add_argument("-o", "--output", help="the samples' CSV file")
    p.add_argument("--plot", metavar="DIR", help="write pictures of the mesh and stress field")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=run)


def _spec(args: argparse.Namespace) -> tuple[str, dict[str, Any], str]:
    """Return (the fe spec to check, its key path for messages, the source for messages)."""
    if args.source:
        if args.shape or args.values:
            raise ConfigError("--from: give either --from or a shape with its values, not both")
        mech, sep, name = args.source.rpartition(":")
        if not sep or not mech or not name:
            raise ConfigError(f"--from {args.source!r}: expected MECHANISM:MODEL")
        path = resolve_mechanism_path(mech)
        models = (read_yaml(path, ConfigError) or {}).get("stiffness_models") or {}
        if name not in models or not isinstance(models[name], dict):
            raise ConfigError(f"{path}: stiffness_models.{name}: no such stiffness model "
                              f"({', '.join(models) or 'none'})")
        # a named material gives E and nu (engine/hinges/materials.py); strengths are not used
        spec = materials.resolve(models[name], lambda k, problem: ConfigError(
            f"{path}: stiffness_models.{name}.{k}: {problem}"))
        for k in ("material", *materials.STRENGTH_KEYS):
            spec.pop(k, None)
        kind = spec.get("model")
        if kind in _FROM:
            shape, keys = _FROM[kind]
            spec = {"model": "fe", "shape": shape, "E": spec.get("E"), "nu": spec.get("nu"),
                    **{k: spec.get(v) for k, v in keys.items()}}
        elif kind != "fe":
            raise ConfigError(f"{path}: stiffness_models.{name}: a {kind!r} model has no "
                              "geometry (notch, cantilever or fe)")
        return spec, f"stiffness_models.{name}", str(path)
    if not args.shape:
        raise ConfigError("give a shape with its values, or --from MECHANISM:MODEL")
    spec: dict[str, Any] = {"model": "fe", "shape": args.shape}
    for item in args.values:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"{item!r}: expected KEY=VALUE")
        try:
            spec[key] = float(value)
        except ValueError:
            raise ConfigError(f"{key}: expected a number, got {value!r}") from None
    return spec, "hinge", "flexure-sim hinge"


def _run(args: argparse.Namespace) -> dict[str, Any]:
    spec, key, source = _spec(args)
    if args.plane:
        spec["plane"] = args.plane
    if args.resolution is not None:
        spec["resolution"] = args.resolution
    v = fe_numbers(Ctx(source), key, spec)
    name, geo, E, nu, n = v["shape"], v["geometry"], v["E"], v["nu"], v["resolution"]
    out = fe_report.compare(name, geo, E, nu, v["plane"], n, study=args.convergence)
    if args.samples is not None:
        if args.samples < 1 or not args.alpha_max or not args.alpha_max > 0 or not args.output:
            raise ConfigError("--samples N needs N >= 1, --alpha-max > 0 (rad) and -o FILE")
        r, w = wrench_samples(name, geo, E, nu, args.alpha_max, args.samples, args.seed,
                              v["plane"], n)
        data = WrenchData(r[:, 0], r[:, 1:], w, args.output)
        K = fe_model.stiffness(name, geo, E, nu, v["plane"], n)
        comment = (f"large-deflection finite-element samples of a {name} hinge "
                   f"({', '.join(f'{k}={x:g}' for k, x in geo.items())}, E={E:g}, nu={nu:g}, "
                   f"plane {out['plane']}, resolution {n}), |alpha| <= {args.alpha_max:g} rad, "
                   f"seed {args.seed}\nm, fx, fy: m_b, the wrench body B exerts on the element, "
                   "in frame b, moment about b's origin")
        write_wrench_csv(args.output, data, comment)
        err = wrench_errors(QuadraticLaw("twistor", K, np.zeros((3, 3))), data)
        out["samples"] = {"rows": args.samples, "file": args.output,
                          "alpha_max": args.alpha_max,
                          "box": working_box(name, geo, nu, args.alpha_max, v["plane"],
                                             n).tolist(),
                          "quadratic_twistor_law": {"max_rel": err["max_rel"],
                                                    "worst_rel": err["worst_rel"]}}
    if args.plot:
        from flexure_sim.tools.design.hinge_plots import plot_hinge

        out["plots"] = plot_hinge(name, geo, nu, out["plane"], n, Path(args.plot))
    return out


def run(args: argparse.Namespace) -> int:
    """Handle the command: exit 0, or 2 with one line on stderr for bad input."""
    try:
        out = _run(args)
    except FlexureSimError as exc:
        print(f"flexure-sim hinge: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"flexure-sim hinge: error: {exc.filename or ''}: {exc.strerror or exc}",
              file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(out))
        return 0
    print(fe_report.text(out))
    if "samples" in out:
        s = out["samples"]
        q = s["quadratic_twistor_law"]["max_rel"]
        print(f"\n{s['rows']} large-deflection samples, |alpha| <= {s['alpha_max']:g} rad, "
              f"written to {s['file']}; the twistor quadratic law of this stiffness is off by "
              f"up to {q[0]:.2%} (m), {q[1]:.2%} (fx), {q[2]:.2%} (fy) of each component's "
              "largest sampled value")
    for p in out.get("plots", []):
        print(f"wrote {p}")
    return 0
