"""
Running a study.

Batches as Dask tasks, each finished batch stored once as a Parquet part, merged at the end (the
engine of ``flexure-sim sweep``, see tools/design/sweep.py).

Locally a ``distributed.LocalCluster`` runs one single-threaded worker process per core, or
Dask's synchronous scheduler runs the batches in this process (``workers=1``); or an existing
scheduler runs them (its workers need flexure_sim installed). This process writes each
finished batch as one part file (``<output>.parts/part-<batch>.parquet``, written to a
temporary name and renamed), so a batch is stored once however often Dask re-runs its task (a
lost worker's tasks are re-run elsewhere), and an interrupted study keeps what finished:
``resume`` runs only the missing batches. At the end the parts are merged, in sample order,
into the output file and removed.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Optional

import pyarrow as pa
import pyarrow.parquet as pq
from distributed import WorkerPlugin

from flexure_sim.engine.analysis.study import Study
from flexure_sim.errors import FlexureSimError
from flexure_sim.tools.design.sweep_outputs import FAILED, columns, evaluate_batch

MANIFEST = "study.json"


class SweepError(FlexureSimError):
    """The sweep cannot go on (the message says why and what to do)."""


#: Key of the schema metadata that describes the study (JSON).
METADATA_KEY = "flexure_sim.study"


def schema(study: Study) -> pa.Schema:
    """
    Columns of the results.

    sample, parameters, output columns (float64; ``sweep_outputs.columns``), status, error; the
    schema's metadata ``flexure_sim.study`` holds what produced them (JSON: study, mechanism,
    its drives, seed, samples, batch size, input, parameters with their paths and distributions,
    each output column's unit, the study's fingerprint).
    """
    table = columns(study)
    about = {
        "name": study.name, "study": study.source, "mechanism": study.mechanism_source,
        "monte_carlo": study.monte_carlo, "seed": study.seed, "samples": study.samples,
        "batch_size": study.batch_size, "input": study.input, "step": study.step,
        "parameters": [{"name": p.name, "paths": [".".join(map(str, q)) for q in p.paths],
                        "offset": p.offset, "kind": p.kind, "loc": p.loc, "scale": p.scale}
                       for p in study.parameters],
        "drives": [d[0] for d in study.channels.drives],
        "units": {c.name: c.unit for c in table},
        "fingerprint": study.fingerprint(),
    }
    return pa.schema([("sample", pa.int64())]
                     + [(p.name, pa.float64()) for p in study.parameters]
                     + [(c.name, pa.float64()) for c in table]
                     + [("status", pa.string()), ("error", pa.string())],
                     metadata={METADATA_KEY: json.dumps(about)})


# ------------------------------------------------------------------------------ parts
class PartStore:
    """
    Finished batches as Parquet part files in ``<output>.parts/``.

    They come with a manifest holding the study's fingerprint (a study may only be resumed by
    itself).
    """

    def __init__(self, output: Path, study: Study, resume: bool):
        self.dir = output.with_name(output.name + ".parts")
        self.study = study
        self.schema = schema(study)
        manifest = self.dir / MANIFEST
        if self.dir.exists() and not self.done() and not resume:
            # only a manifest (a run that stopped before its first batch): nothing to keep
            manifest.unlink(missing_ok=True)
            for tmp in self.dir.glob("*.tmp"):
                tmp.unlink()
            self.dir.rmdir()
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
            manifest.write_text(json.dumps({
                "study": study.source, "fingerprint": study.fingerprint(),
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
        table = pa.concat_tables(
            [pq.read_table(self.path(k), schema=self.schema) for k in range(n)])
        samples = table.column("sample").to_numpy()
        if len(samples) != self.study.samples or (samples != range(self.study.samples)).any():
            raise SweepError(f"{self.dir}: the parts do not hold samples "
                             f"0..{self.study.samples - 1} once each")
        tmp = output.with_name(output.name + ".tmp")
        try:
            pq.write_table(table, tmp)
            os.replace(tmp, output)
        finally:
            tmp.unlink(missing_ok=True)
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
    resumed_designs: int = 0
    lost_batches: list = field(default_factory=list)


def run_study(study: Study, output: Path, workers: Optional[int] = None,
              scheduler: Optional[str] = None, resume: bool = False, client: Any = None,
              on_batch: Optional[Callable[[Progress], None]] = None) -> pa.Table:
    """
    Run the study's missing batches, store each as it finishes, merge into ``output``.

    ``client``: an existing ``distributed.Client`` to use; else ``scheduler`` (an address), else
    a LocalCluster of ``workers`` processes (default: one per core), or with ``workers == 1``
    Dask's synchronous scheduler in this process. ``on_batch`` is called after each stored batch.
    """
    store = PartStore(output, study, resume)
    batches = study.batches()
    done = store.done()
    todo = [k for k in range(len(batches)) if k not in done]
    prog = Progress(total_designs=study.samples, total_batches=len(batches),
                    resumed_batches=len(done))
    prog.batches = len(done)
    prog.designs = prog.resumed_designs = sum(b - a for k, (a, b) in enumerate(batches)
                                              if k in done)

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
            task = dask.delayed(evaluate_batch)(study, *batches[k])
            stored(k, task.compute(scheduler="synchronous"))
    else:
        _run_distributed(study, todo, batches, stored, prog, client, scheduler, workers)
    if prog.lost_batches:
        raise SweepError(f"{len(prog.lost_batches)} batches failed on the cluster (first: "
                         f"{prog.lost_batches[0]}); the finished ones are kept: run again "
                         "with --resume")
    return store.merge(output)


def _run_distributed(study, todo, batches, stored, prog, client, scheduler, workers) -> None:
    from distributed import Client, LocalCluster, as_completed

    own = []
    try:
        if client is None:
            if scheduler is not None:
                client = Client(scheduler)
            else:
                # Dask's own logs stay quiet (a worker busy in a batch when the study stops
                # misses heartbeats and would log tracebacks): what matters reaches the user
                # as a failed design or batch.
                with _sigint_ignored():  # inherited by the worker processes spawned now
                    cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1,
                                           threads_per_worker=1, processes=True,
                                           dashboard_address=None,
                                           silence_logs=logging.CRITICAL)
                own.append(cluster)
                client = Client(cluster)
                client.register_plugin(IgnoreSigint(), name="flexure-sweep-ignore-sigint")
            own.insert(0, client)
        shared = client.scatter(study, broadcast=True)
        tag = study.fingerprint()[:16]
        futures = [client.submit(evaluate_batch, shared, *batches[k],
                                 key=f"flexure-sweep-{tag}-{k}") for k in todo]
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


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """
    Ignore SIGINT while local workers are spawned.

    A process started with SIGINT ignored keeps ignoring it, so Ctrl-C at the terminal (sent to the
    whole process group) reaches only this process, which stops the study cleanly, not the workers
    (which would print tracebacks). Only in the main thread (elsewhere nothing can be changed).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


class IgnoreSigint(WorkerPlugin):
    """Dask worker plugin doing the same in local workers the nanny restarts later."""

    def setup(self, worker: Any) -> None:
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
