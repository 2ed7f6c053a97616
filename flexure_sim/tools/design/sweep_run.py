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

Memory stays bounded whatever the number of batches: a bounded number of tasks is in flight
(``IN_FLIGHT`` per worker thread), and the merge streams the parts, one at a time, into row
groups of up to ``ROW_GROUP`` rows. (The results themselves are read back for the summary:
a study too large for that is refused at load, engine/analysis/study_size.py.)
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
#: Tasks in flight per worker thread of a cluster (the rest are submitted as these finish).
IN_FLIGHT = 4
#: Rows per row group of the merged results file.
ROW_GROUP = 65536


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
        """
        All parts in batch order, checked complete, written to ``output``; parts removed.

        The parts are streamed one at a time into row groups (module doc); returns the results.
        """
        batches = self.study.batches()
        n = len(batches)
        done = self.done()
        missing = [k for k in range(n) if k not in done][:10]
        if missing:
            raise SweepError(f"batches {missing} are missing from {self.dir}")
        tmp = output.with_name(output.name + ".tmp")
        try:
            with pq.ParquetWriter(tmp, self.schema) as writer:
                pending: list[pa.Table] = []
                for k, (start, stop) in enumerate(batches):
                    part = pq.read_table(self.path(k), schema=self.schema)
                    samples = part.column("sample").to_numpy()
                    if len(samples) != stop - start or (samples != range(start, stop)).any():
                        raise SweepError(f"{self.dir}: the parts do not hold samples "
                                         f"0..{self.study.samples - 1} once each")
                    pending.append(part)
                    if sum(len(p) for p in pending) >= ROW_GROUP or k == n - 1:
                        writer.write_table(pa.concat_tables(pending), row_group_size=ROW_GROUP)
                        pending = []
            os.replace(tmp, output)
        finally:
            tmp.unlink(missing_ok=True)
        table = pq.read_table(output)
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
    own = None
    if client is None and scheduler is not None:  # before anything is written
        client = own = connect(scheduler)
    try:
        return _run(study, output, workers, resume, client, on_batch)
    finally:
        if own is not None:
            own.close()


def connect(address: str) -> Any:
    """
    Return a ``distributed.Client`` of the scheduler at ``address``.

    SweepError naming the option for an address that is not one (``not a url``); an
    unreachable one raises the OSError that the command reports.
    """
    from distributed import Client

    try:
        return Client(address)
    except (ValueError, TypeError) as exc:
        raise SweepError(f"--scheduler {address!r}: not a scheduler address ({exc}); expected "
                         "e.g. tcp://HOST:8786") from None


def _run(study, output, workers, resume, client, on_batch) -> pa.Table:
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

    if client is None and workers == 1:
        import dask

        for k in todo:
            task = dask.delayed(evaluate_batch)(study, *batches[k])
            stored(k, task.compute(scheduler="synchronous"))
    else:
        _run_distributed(study, todo, batches, stored, prog, client, workers)
    if prog.lost_batches:
        raise SweepError(f"{len(prog.lost_batches)} batches failed on the cluster (first: "
                         f"{prog.lost_batches[0]}); the finished ones are kept: run again "
                         "with --resume")
    return store.merge(output)


def _run_distributed(study, todo, batches, stored, prog, client, workers) -> None:
    from distributed import Client, LocalCluster, as_completed

    own = []
    try:
        if client is None:
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
        waiting = iter(todo)
        index = {}

        def submit() -> Any:
            k = next(waiting, None)
            if k is None:
                return None
            fut = client.submit(evaluate_batch, shared, *batches[k],
                                key=f"flexure-sweep-{tag}-{k}")
            index[fut.key] = k
            return fut

        window = IN_FLIGHT * max(1, sum(client.nthreads().values()))
        running = as_completed([f for f in (submit() for _ in range(window)) if f is not None])
        for fut in running:
            k = index.pop(fut.key)
            nxt = submit()  # keep the window full while this batch is stored
            if nxt is not None:
                running.add(nxt)
            if fut.status != "finished":
                prog.lost_batches.append(f"batch {k}: {fut.exception()!r}")
                continue
            stored(k, fut.result())
            fut.release()
    finally:
        with _distributed_silent():
            for thing in own:
                thing.close()


@contextlib.contextmanager
def _distributed_silent() -> Iterator[None]:
    """
    Keep Dask's loggers quiet while the study's own client and cluster close.

    The stored batches are final by then. A Ctrl-C lands while the scheduler is still telling
    the client about a finished task, and closing the client under it made the scheduler log
    a CRITICAL "Closed comm ... while trying to write" with its traceback on the user's
    terminal (seen once in the suite, two studies running at once); ``silence_logs`` stops
    short of CRITICAL.
    """
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


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
