"""
``flexure-sim sweep STUDY.yaml -o results.parquet``: design sweeps and Monte Carlo studies.

    flexure-sim sweep config/studies/stage_tolerance.yaml -o tol.parquet
    flexure-sim sweep STUDY.yaml -o out.parquet --workers 1          # in this process
    flexure-sim sweep STUDY.yaml -o out.parquet --scheduler tcp://host:8786
    flexure-sim sweep STUDY.yaml -o out.parquet --resume             # after Ctrl-C / a crash

The study file format is in docs/sweeps.md (engine/analysis/study.py), the outputs in
tools/design/sweep_outputs.py, the running (Dask, Parquet parts, resume) in
tools/design/sweep_run.py, the summary and plots in tools/design/sweep_summary.py. This module is
the command line only (it imports Dask and pyarrow only when a sweep runs, so other commands start
fast).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, Optional, Sequence

PROG = "flexure-sim sweep"
EXIT_OK, EXIT_BAD_FILE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


# --------------------------------------------------------------------------------- CLI
def register(subparsers: Any) -> None:
    p = subparsers.add_parser("sweep",
                              help="design sweeps and Monte Carlo tolerance studies (Dask)",
                              description=__doc__.split("\n\n")[0])
    p.add_argument("study", help="study file (YAML, see docs/sweeps.md)")
    p.add_argument("-o", "--output", required=True, help="results file (Parquet)")
    p.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: one per core; 1: in this process)")
    p.add_argument("--scheduler", default=None, help="address of a running Dask scheduler, "
                   "e.g. tcp://HOST:8786 (instead of a local cluster)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted study")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--no-plots", action="store_true", help="skip the tornado plot and histograms")
    p.set_defaults(handler=handle)


def handle(args: argparse.Namespace) -> int:
    if args.workers is not None and args.workers < 1:
        return _fail(f"--workers {args.workers}: must be at least 1", EXIT_USAGE)
    if args.workers is not None and args.scheduler:
        return _fail("--workers and --scheduler exclude each other (the scheduler has its "
                     "workers)", EXIT_USAGE)
    output = Path(args.output)
    if not output.parent.is_dir():
        return _fail(f"{output.parent}: no such directory for the output", EXIT_USAGE)
    if output.is_dir():
        return _fail(f"{output}: is a directory (the output is one Parquet file)", EXIT_USAGE)
    from flexure_sim.engine.analysis.study import StudyError, load_study
    try:
        from flexure_sim.tools.design import sweep_summary
        from flexure_sim.tools.design.sweep_run import SweepError, run_study
    except ImportError as exc:  # dask, distributed, pyarrow or tqdm missing
        return _fail(f"sweeps need {exc.name} (flexure_sim's extra 'sweep': "
                     "pip install 'flexure_sim[sweep]')", 1)
    from flexure_sim.tools.design.sweep_outputs import OUTPUTS

    try:
        study = load_study(args.study, OUTPUTS)
    except StudyError as exc:
        return _fail(str(exc), EXIT_BAD_FILE)
    report = _Reporter(study)
    start = time.perf_counter()
    try:
        table = run_study(study, output, args.workers, args.scheduler, args.resume,
                          on_batch=report.batch)
    except SweepError as exc:
        return _fail(str(exc), EXIT_USAGE)
    except OSError as exc:  # unwritable output, unreachable scheduler
        report.close()
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        return _fail(f"{where}{exc.strerror or exc}", EXIT_BAD_FILE)
    except KeyboardInterrupt:
        report.close()
        parts = output.with_name(output.name + ".parts")
        return _fail(f"interrupted: the finished batches are kept in {parts}; continue with "
                     "--resume", EXIT_INTERRUPTED)
    wall = time.perf_counter() - start
    report.close()
    summary = sweep_summary.summarize(table, study)
    plots = [] if args.no_plots else sweep_summary.plot(table, study, summary, output)
    result = {"study": study.source, "output": str(output), "designs": study.samples,
              "failed": summary["failed"], "computed": report.computed, "resumed": report.resumed,
              "wall_s": wall, "designs_per_s": report.computed / wall,
              "plots": [str(p) for p in plots], "outputs": summary["outputs"]}
    if args.json:
        print(json.dumps(result))
    else:
        sweep_summary.print_summary(result, study)
    return EXIT_OK


def _fail(message: str, code: int) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return code


class _Reporter:
    """
    Progress on stderr: a tqdm bar on a terminal, else a line per tenth of the study.

    ``computed``: designs computed by this run (not resumed from an earlier one).
    """

    def __init__(self, study: Any):
        self.total = study.samples
        self.bar: Any = None
        self.resumed = 0
        self.computed = 0
        self.next_tenth = 0

    def batch(self, prog: Any) -> None:
        self.resumed = prog.resumed_designs
        new = prog.designs - self.resumed - self.computed
        self.computed += new
        if sys.stderr.isatty():
            if self.bar is None:
                from tqdm import tqdm

                self.bar = tqdm(total=self.total, initial=self.resumed, unit="design",
                                desc="sweep", file=sys.stderr)
            self.bar.update(new)
            self.bar.set_postfix(failed=prog.failed)
            return
        tenth = 10 * prog.designs // self.total
        if tenth >= self.next_tenth:
            self.next_tenth = tenth + 1
            print(f"{PROG}: {prog.designs}/{self.total} designs "
                  f"({prog.batches}/{prog.total_batches} batches, {prog.failed} failed)",
                  file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG)
    register(parser.add_subparsers(dest="command", required=True))
    return handle(parser.parse_args(["sweep", *(argv or sys.argv[1:])]))


if __name__ == "__main__":
    sys.exit(main())
