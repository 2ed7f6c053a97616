"""
``flexure-sim export RUN.mcap --csv DIR``.

One CSV file per topic, for PlotJuggler, spreadsheets and pandas.

    flexure-sim export runs/stage.mcap --csv runs/csv [--topics /output/displacement ...]
                       [--recover] [--strict]

Each file is named after its topic with ``.`` for ``/`` (``/hinges/a/wrench`` ->
``hinges.a.wrench.csv``; ROS names cannot contain dots, so names never clash) and has one row
per message, in log-time order: first ``time`` (the MCAP log time, i.e. the simulation time,
in seconds with nanosecond digits), then every field of the message flattened with ``/``
between levels and ``[i]`` for array elements, as PlotJuggler names them
(``pose/position/x``, ``poses[2]/orientation/z``). A ``diagnostic_msgs/KeyValue`` array
becomes one column per key (``status[0]/values/real_time_factor``). Floats are written with
full precision (Python repr). A topic without messages gets a file with the ``time`` column
only. ``--signals`` also writes ``signals.csv``: every drive and output of the run in one
table with named columns (`export_signals`).
"""
from __future__ import annotations

import argparse
import csv
import json
import tempfile
from pathlib import Path
from typing import Any, Iterable, Iterator, TextIO

from flexure_sim.recording.command_line import (
    check_path, check_readable, open_log, report_reading, tool_errors,
)
from flexure_sim.recording.exceptions import EXIT_OK, RunError
from flexure_sim.tools.options import add_file_arguments

PROG = "flexure-sim export"


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "export", help="one CSV per topic (time column in seconds, flattened fields)",
        description=__doc__.split("\n\n")[0].replace("``", ""))
    add_file_arguments(p, namespace=False)
    p.add_argument("--csv", metavar="DIR", required=True,
                   help="directory for the CSV files (created)")
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="export only these topics")
    p.add_argument("--signals", action="store_true",
                   help="also write signals.csv: every drive's command, input and force and "
                   "every output, one named column each, one row per tick")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    return tool_errors(PROG, lambda: _run(args), can_recover=not args.recover)


def _run(args: argparse.Namespace) -> int:
    check_path(args.run)
    out_dir = Path(args.csv)
    if out_dir.exists() and not out_dir.is_dir():
        raise RunError(f"--csv {out_dir}: exists and is not a directory", 2)
    reader = open_log(args.run, recover=args.recover, strict=args.strict)
    if args.topics and reader.summary_ok:  # checked before the pass when the summary says
        _check_topics(args.topics, reader.topics, args.run)
    wanted = set(args.topics or ())
    with tempfile.TemporaryDirectory(prefix="flexure_export_") as spool_dir:
        spools: dict[str, _Spool] = {}
        try:
            for m in reader.messages(lambda t: not wanted or t.name in wanted):
                spool = spools.get(m.topic)
                if spool is None:
                    spool = spools[m.topic] = _Spool(Path(spool_dir) / f"{len(spools)}.jsonl")
                spool.add(m.log_time_ns, m.message)
            check_readable(reader)
            if args.topics:
                _check_topics(args.topics, reader.topics, args.run)
            report_reading(PROG, reader)
            topics = sorted(t for t in reader.topics if not wanted or t in wanted)
            out_dir.mkdir(parents=True, exist_ok=True)
            written = []
            for topic in topics:
                path = out_dir / csv_name(topic)
                spool = spools.get(topic)
                rows = spool.write_csv(path) if spool else _write_rows(path, {}, ())
                written.append((path, rows, topic))
        finally:
            for spool in spools.values():
                spool.close()
    signals = None
    if args.signals:
        from flexure_sim.tools.run.export_signals import write_signals
        from flexure_sim.tools.run.runlog import load_run

        signals = write_signals(load_run(args.run, recover=args.recover, strict=args.strict,
                                         poses=False), out_dir)
    print(f"wrote {len(written) + (signals is not None)} CSV file(s) to {out_dir}/:")
    for path, rows, topic in written:
        print(f"  {path.name:34s} {rows:7d} rows  {reader.topics[topic].type}")
    if signals is not None:
        print(f"  {signals[0].name:34s} {signals[1]:7d} rows  drives and outputs, one column each")
    return EXIT_OK


def _check_topics(requested: list[str], topics: dict[str, Any], run_path: str) -> None:
    unknown = [t for t in requested if t not in topics]
    if unknown:
        raise RunError(f"--topics: {', '.join(unknown)} not in {run_path} "
                       f"(topics: {', '.join(sorted(topics))})", 2)


class _Spool:
    """
    The rows of one topic.

    Flattened as they stream past and kept on disk (one JSON line each), with the union of their
    columns, until the CSV can be written with all columns.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.file: TextIO = path.open("w")
        self.columns: dict[str, None] = {}
        self.rows = 0
        self.in_order = True
        self.last_ns = -(1 << 63)

    def add(self, log_time_ns: int, message: Any) -> None:
        row = _row(message, self.columns)
        self.file.write(json.dumps([log_time_ns, row], default=str) + "\n")
        self.rows += 1
        self.in_order = self.in_order and log_time_ns >= self.last_ns
        self.last_ns = max(self.last_ns, log_time_ns)

    def close(self) -> None:
        self.file.close()

    def write_csv(self, path: Path) -> int:
        self.file.close()
        with self.path.open() as f:
            items: Iterable[tuple[int, dict]] = (json.loads(line) for line in f)
            if not self.in_order:  # rare (merged bags): sort this topic alone, by log time
                items = sorted(items, key=lambda item: item[0])  # stable: file order on ties
            return _write_rows(path, self.columns, items)


def _row(msg: Any, columns: dict[str, None]) -> dict[str, Any]:
    row: dict[str, Any] = {}
    for key, value in flatten(msg):
        key = key or "data"
        if key == "time":  # a field called time must not hide the time column
            key = "/time"
        columns.setdefault(key, None)
        row[key] = _cell(value)
    return row


def _time_cell(ns: int) -> str:
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def _write_rows(path: Path, columns: dict[str, None], items: Iterable[tuple[int, dict]]) -> int:
    count = 0
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["time", *columns], restval="", extrasaction="raise")
        writer.writeheader()
        for ns, row in items:
            writer.writerow({"time": _time_cell(ns), **row})
            count += 1
    return count


def csv_name(topic: str) -> str:
    """File name of a topic's CSV: ``/a/b`` -> ``a.b.csv``."""
    return topic.strip("/").replace("/", ".") + ".csv"


def flatten(msg: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """(column, value) of every leaf field of a decoded message, in field order."""
    slots = getattr(msg, "__slots__", None)
    if slots is not None and not isinstance(msg, (str, bytes)):
        for name in slots:
            yield from flatten(getattr(msg, name), f"{prefix}/{name}" if prefix else name)
        return
    if isinstance(msg, (list, tuple)):
        if msg and all(_is_key_value(x) for x in msg):
            for x in msg:
                yield f"{prefix}/{x.key}", x.value
            return
        for i, x in enumerate(msg):
            yield from flatten(x, f"{prefix}[{i}]")
        return
    if isinstance(msg, (bytes, bytearray)):
        if len(msg) == 1:
            yield prefix, msg[0]
        else:
            yield prefix, bytes(msg).hex()
        return
    yield prefix, msg


def _is_key_value(x: Any) -> bool:
    return tuple(getattr(x, "__slots__", ())) == ("key", "value")


def _cell(value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, float):
        return repr(value)
    return value
