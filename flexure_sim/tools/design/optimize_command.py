"""
``flexure-sim optimize STUDY.yaml``: a better design with exact gradients.

    flexure-sim optimize config/studies/stage_first_mode.yaml -o out/
    flexure-sim optimize STUDY.yaml --method trust-constr
    flexure-sim optimize STUDY.yaml --starts 8 --workers 2            # multi-start, Dask
    flexure-sim optimize STUDY.yaml --starts 8 --scheduler tcp://HOST:8786

The study format is in docs/optimization.md (engine/analysis/optimize_study.py), the problem and
the KKT report in engine/analysis/optimize.py, the files in tools/design/optimize_report.py.
Several starts (the study's start, then Sobol points within the bounds, scipy.stats.qmc) run as
Dask tasks on the sweeps' kind of cluster (tools/design/sweep_run.py): a LocalCluster of
single-threaded worker processes, this process with ``--workers 1``, or a running scheduler.
The best feasible result is kept; without one, the least violating.

Exit codes: 0 optimal, 1 a bad study file or a design that cannot be evaluated, 2 a bad
argument, 3 no feasible design (the least-violating one is written), 4 stopped short of the
first-order conditions (the last design is written), 130 interrupted (Ctrl-C).
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

PROG = "flexure-sim optimize"
EXIT = {"optimal": 0, "infeasible": 3, "not_converged": 4}
EXIT_BAD_FILE, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130


def register(subparsers: Any) -> None:
    p = subparsers.add_parser("optimize", aliases=["optimise"],
                              help="optimise a design with exact gradients (scipy.optimize)",
                              description=__doc__.split("\n\n")[0].replace("``", ""))
    p.add_argument("study", help="optimisation study (YAML, see docs/optimization.md)")
    p.add_argument("-o", "--output", default=None,
                   help="directory for the files (default: ./<study name>)")
    p.add_argument("--method", choices=("SLSQP", "trust-constr"), default=None,
                   help="the study's method instead (default: the study's, else SLSQP)")
    p.add_argument("--starts", type=int, default=None,
                   help="number of starting designs (default: the study's, else 1)")
    p.add_argument("--workers", type=int, default=None,
                   help="local worker processes for several starts (default: one per core; "
                   "1: in this process)")
    p.add_argument("--scheduler", default=None, help="address of a running Dask scheduler")
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")
    p.add_argument("--no-plots", action="store_true", help="skip the iterations plot")
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from flexure_sim.engine.analysis.optimize import OptimizeError
    from flexure_sim.engine.analysis.optimize_study import load_optimize_study
    from flexure_sim.engine.analysis.study import StudyError
    from flexure_sim.tools.design import optimize_report

    if args.starts is not None and args.starts < 1:
        return _fail(f"--starts {args.starts}: must be at least 1", EXIT_USAGE)
    if args.workers is not None and args.workers < 1:
        return _fail(f"--workers {args.workers}: must be at least 1", EXIT_USAGE)
    try:
        study = load_optimize_study(args.study)
    except StudyError as exc:
        return _fail(str(exc), EXIT_BAD_FILE)
    study = replace(study, method=args.method or study.method,
                    starts=args.starts or study.starts)
    folder = Path(args.output or study.name)
    if folder.exists() and not folder.is_dir():
        return _fail(f"{folder}: exists and is not a directory", EXIT_USAGE)
    try:
        results = run_starts(study, args.workers, args.scheduler)
    except OptimizeError as exc:
        return _fail(str(exc), EXIT_BAD_FILE)
    except OSError as exc:  # an unreachable scheduler
        return _fail(f"{exc.strerror or exc}", EXIT_BAD_FILE)
    except KeyboardInterrupt:
        return _fail("interrupted: nothing written", EXIT_INTERRUPTED)
    best = pick(results, study.sense)
    if len(results) > 1:
        best.extra["starts"] = [{"start": r.start.tolist(), "status": r.status,
                                 "objective": r.objective,
                                 "violation": r.kkt["violation"]} for r in results]
    try:
        files = optimize_report.write_files(study, best, folder, plots=not args.no_plots)
    except OSError as exc:
        return _fail(f"{folder}: cannot write the results: {exc.strerror or exc}", EXIT_BAD_FILE)
    if args.json:
        print(Path(files["report"]).read_text(encoding="utf-8"))
    else:
        optimize_report.print_result(study, best, files)
        if len(results) > 1:
            print(f"\n{len(results)} starts: " + ", ".join(
                f"{r.status} {r.objective:.8g}" for r in results))
    if best.status != "optimal":
        print(f"{PROG}: {best.status.replace('_', ' ')}: {best.message}", file=sys.stderr)
    return EXIT[best.status]


def starting_points(study) -> np.ndarray:
    """Return the starts: the study's, then scrambled Sobol points within the bounds."""
    from scipy.stats import qmc

    points = [study.start]
    if study.starts > 1:
        sobol = qmc.Sobol(len(study.variables), scramble=True, seed=study.seed)
        unit = sobol.random(study.starts - 1)
        points += list(study.lower + unit * (study.upper - study.lower))
    return np.array(points)


def pick(results: list, sense: str):
    """Return the best feasible result (objective in the study's sense), else least violating."""
    feasible = [r for r in results if r.status != "infeasible"]
    if not feasible:
        return min(results, key=lambda r: r.kkt["violation"])
    optimal = [r for r in feasible if r.status == "optimal"] or feasible
    sign = -1.0 if sense == "maximize" else 1.0
    return min(optimal, key=lambda r: sign * r.objective)


def _solve(study, start):
    from flexure_sim.engine.analysis.optimize import solve

    return solve(study, start)


def run_starts(study, workers: Optional[int], scheduler: Optional[str]) -> list:
    """Solve from every start: in this process, or as Dask tasks (module docstring)."""
    points = starting_points(study)
    if len(points) == 1 or (workers == 1 and scheduler is None):
        return [_solve(study, p) for p in points]
    from distributed import Client, LocalCluster

    from flexure_sim.tools.design.sweep_run import IgnoreSigint, _sigint_ignored

    own = []
    try:
        if scheduler is not None:
            client = Client(scheduler)
        else:
            with _sigint_ignored():
                cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1,
                                       threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=logging.CRITICAL)
            own.append(cluster)
            client = Client(cluster)
            client.register_plugin(IgnoreSigint(), name="flexure-optimize-ignore-sigint")
        own.insert(0, client)
        futures = client.map(_solve, [study] * len(points), list(points), pure=False)
        return client.gather(futures)
    finally:
        for thing in own:
            thing.close()


def _fail(message: str, code: int) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return code


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG)
    register(parser.add_subparsers(dest="command", required=True))
    return handle(parser.parse_args(["optimize", *(argv or sys.argv[1:])]))


if __name__ == "__main__":
    sys.exit(main())
