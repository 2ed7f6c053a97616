"""``flexure-sim sweep STUDY.yaml -o results.parquet``: design sweeps and Monte Carlo studies.

    flexure-sim sweep config/studies/stage_tolerance.yaml -o tol.parquet
    flexure-sim sweep STUDY.yaml -o out.parquet --workers 1          # in this process
    flexure-sim sweep STUDY.yaml -o out.parquet --scheduler tcp://host:8786
    flexure-sim sweep STUDY.yaml -o out.parquet --resume             # after Ctrl-C / a crash

The designs are cut into batches (``batch_size`` designs per task). Locally a Dask
``LocalCluster`` runs one single-threaded worker process per core (``--workers N`` to
choose; ``--workers 1`` uses Dask's synchronous scheduler in this process), or an existing
Dask scheduler runs them (its workers need flexure_sim installed). This process writes each
finished batch as one Parquet part file (``<output>.parts/part-<batch>.parquet``, written to
a temporary name and renamed), so a batch is stored once however often Dask re-runs its task
(a lost worker's tasks are re-run elsewhere), and an interrupted study keeps what finished:
``--resume`` runs only the missing batches. At the end the parts are merged, in sample order,
into the output file and removed; the summary (sweep_summary.py) follows.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import pyarrow as pa
import pyarrow.parquet as pq

from ..engine.study import Study, StudyError, load_study
from . import sweep_summary
from .sweep_outputs import FAILED, OUTPUTS, evaluate_batch

PROG = "flexure-sim sweep"
EXIT_OK, EXIT_BAD_FILE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
MANIFEST = "study.json"


class SweepError(Exception):
    """The sweep cannot go on (the message says why and what to do)."""


def schema(study: Study) -> pa.Schema:
    """Columns of the results: sample, parameters, outputs (float64), status, error."""
    return pa.schema([("sample", pa.int64())]
                     + [(p.name, pa.float64()) for p in study.parameters]
                     + [(o, pa.float64()) for o in study.outputs]
                     + [("status", pa.string()), ("error", pa.string())])


# ------------------------------------------------------------------------------ parts
class PartStore:
    """Finished batches as Parquet part files in ``<output>.parts/``, with a manifest holding
    the study's fingerprint (a study may only be resumed by itself)."""

    def __init__(self, output: Path, study: Study, resume: bool):
        self.dir = output.with_name(output.name + ".parts")
        self.study = study
        self.schema = schema(study)
        manifest = self.dir / MANIFEST
        if self.dir.exists():
            if not resume:
                raise SweepError(f"{self.dir} holds batches of an earlier run: continue it with "
                                 "--resume, or remove it")
            try:
                found = json.loads(manifest.read_text()).get("fingerprint")
            except (OSError, ValueError, AttributeError):
                found = None
            if found != study.fingerprint():
                raise SweepError(f"{self.dir} was written for another study (or its manifest is "
                                 f"unreadable): remove it to start again")
            for tmp in self.dir.glob("*.tmp"):
                tmp.unlink()  # a part whose writing was interrupted: its batch runs again
        else:
            self.dir.mkdir(parents=True)
            manifest.write_text(json.dumps({"study": study.source, "fingerprint": study.fingerprint(),
                                            "samples": study.samples, "batches": len(study.batches())}))

    def path(self, batch: int) -> Path:
        return self.dir / f"part-{batch:06d}.parquet"

    def done(self) -> set[int]:
        return {int(p.stem.split("-")[1]) for p in self.dir.glob("part-*.parquet")}

    def write(self, batch: int, columns: dict) -> None:
        table = pa.Table.from_pydict(columns, schema=self.schema)
        tmp = self.path(batch).with_suffix(".parquet.tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, self.path(batch))

    def merge(self, output: Path) -> pa.Table:
        """All parts in batch order, checked complete, written to ``output``; parts removed."""
        n = len(self.study.batches())
        missing = sorted(set(range(n)) - self.done())
        if missing:
            raise SweepError(f"batches {missing[:10]} are missing from {self.dir}")
        table = pa.concat_tables([pq.read_table(self.path(k), schema=self.schema) for k in range(n)])
        samples = table.column("sample").to_numpy()
        if len(samples) != self.study.samples or (samples != range(self.study.samples)).any():
            raise SweepError(f"{self.dir}: the parts do not hold samples 0..{self.study.samples - 1} "
                             "once each")
        tmp = output.with_name(output.name + ".tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, output)
        for k in range(n):
            self.path(k).unlink()
        (self.dir / MANIFEST).unlink()
        self.dir.rmdir()
        return table


# ----------------------------------------------------------------------------- running
@dataclass
class Progress:
    """Counts of finished designs and batches, handed to the progress callback."""

    designs: int = 0
    failed: int = 0
    batches: int = 0
    total_designs: int = 0
    total_batches: int = 0
    resumed_batches: int = 0
    lost_batches: list = field(default_factory=list)


def run_study(study: Study, output: Path, workers: Optional[int] = None,
              scheduler: Optional[str] = None, resume: bool = False, client: Any = None,
              on_batch: Optional[Callable[[Progress], None]] = None) -> pa.Table:
    """Run the study's missing batches, store each as it finishes, merge into ``output``.

    ``client``: an existing ``distributed.Client`` to use; else ``scheduler`` (an address), else
    a LocalCluster of ``workers`` processes (default: one per core), or with ``workers == 1``
    Dask's synchronous scheduler in this process. ``on_batch`` is called after each stored batch.
    """
    store = PartStore(output, study, resume)
    batches = study.batches()
    done = store.done()
    todo = [k for k in range(len(batches)) if k not in done]
    prog = Progress(total_designs=study.samples, total_batches=len(batches), resumed_batches=len(done))
    prog.batches = len(done)
    prog.designs = sum(b - a for k, (a, b) in enumerate(batches) if k in done)

    def stored(k: int, columns: dict) -> None:
        store.write(k, columns)
        prog.batches += 1
        prog.designs += len(columns["sample"])
        prog.failed += sum(s == FAILED for s in columns["status"])
        if on_batch is not None:
            on_batch(prog)

    if client is None and scheduler is None and workers == 1:
        import dask

        for k in todo:
            stored(k, dask.delayed(evaluate_batch)(study, *batches[k]).compute(scheduler="synchronous"))
    else:
        _run_distributed(study, todo, batches, stored, prog, client, scheduler, workers)
    if prog.lost_batches:
        raise SweepError(f"{len(prog.lost_batches)} batches failed on the cluster (first: "
                         f"{prog.lost_batches[0]}); the finished ones are kept: run again with --resume")
    return store.merge(output)


def _run_distributed(study, todo, batches, stored, prog, client, scheduler, workers) -> None:
    from distributed import Client, LocalCluster, as_completed

    own = []
    try:
        if client is None:
            if scheduler is not None:
                client = Client(scheduler)
            else:
                cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                                       processes=True, dashboard_address=None)
                own.append(cluster)
                client = Client(cluster)
            own.insert(0, client)
        shared = client.scatter(study, broadcast=True)
        tag = study.fingerprint()[:16]
        futures = [client.submit(evaluate_batch, shared, *batches[k], key=f"flexure-sweep-{tag}-{k}")
                   for k in todo]
        index = {f.key: k for f, k in zip(futures, todo)}
        for fut in as_completed(futures):
            k = index[fut.key]
            if fut.status != "finished":
                prog.lost_batches.append(f"batch {k}: {fut.exception()!r}")
                continue
            stored(k, fut.result())
            fut.release()
    finally:
        for thing in own:
            thing.close()


# --------------------------------------------------------------------------------- CLI
def register(subparsers: Any) -> None:
    p = subparsers.add_parser("sweep", help="design sweeps and Monte Carlo tolerance studies (Dask)",
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
        return _fail("--workers and --scheduler exclude each other (the scheduler has its workers)",
                     EXIT_USAGE)
    output = Path(args.output)
    if not output.parent.is_dir():
        return _fail(f"{output.parent}: no such directory for the output", EXIT_USAGE)
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
              "failed": summary["failed"], "wall_s": wall, "designs_per_s": study.samples / wall,
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
    """Progress on stderr: a tqdm bar on a terminal, else a line per tenth of the study."""

    def __init__(self, study: Study):
        self.total = study.samples
        self.bar = None
        self.shown = 0
        self.next_tenth = 0
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=study.samples, unit="design", desc="sweep", file=sys.stderr)

    def batch(self, prog: Progress) -> None:
        if self.bar is not None:
            self.bar.update(prog.designs - self.shown)
            self.bar.set_postfix(failed=prog.failed)
            self.shown = prog.designs
            return
        tenth = 10 * prog.designs // self.total
        if tenth >= self.next_tenth:
            self.next_tenth = tenth + 1
            print(f"{PROG}: {prog.designs}/{self.total} designs ({prog.batches}/{prog.total_batches} "
                  f"batches, {prog.failed} failed)", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG)
    register(parser.add_subparsers(dest="command", required=True))
    return handle(parser.parse_args(["sweep", *(argv or sys.argv[1:])]))


if __name__ == "__main__":
    sys.exit(main())
