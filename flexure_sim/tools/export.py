"""``flexure-sim export RUN.mcap --csv DIR``: one CSV file per topic, for PlotJuggler,
spreadsheets and pandas.

    flexure-sim export runs/stage.mcap --csv runs/csv [--topics /output/displacement ...] [--recover]

Each file is named after its topic with ``.`` for ``/`` (``/hinges/a/wrench`` ->
``hinges.a.wrench.csv``; ROS names cannot contain dots, so names never clash) and has one row
per message, in log-time order: first ``time`` (the MCAP log time, i.e. the simulation time,
in seconds with nanosecond digits), then every field of the message flattened with ``/``
between levels and ``[i]`` for array elements, as PlotJuggler names them
(``pose/position/x``, ``poses[2]/orientation/z``). A ``diagnostic_msgs/KeyValue`` array
becomes one column per key (``status[0]/values/real_time_factor``). Floats are written with
full precision (Python repr). A topic without messages gets a file with the ``time`` column
only.
"""
from __future__ import annotations

import argparse
import csv
from pathlib import Path
from typing import Any, Iterable, Iterator

from .runlog import EXIT_OK, RunError, add_file_arguments, check_path, open_log, report_recovered, tool_errors

PROG = "flexure-sim export"


def register(subparsers: Any) -> None:
    p = subparsers.add_parser("export", help="one CSV per topic (time column in seconds, flattened fields)",
                              description=__doc__.split("\n\n")[0].replace("``", ""))
    add_file_arguments(p, namespace=False)
    p.add_argument("--csv", metavar="DIR", required=True, help="directory for the CSV files (created)")
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="export only these topics")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    return tool_errors(PROG, lambda: _run(args), can_recover=not args.recover)


def _run(args: argparse.Namespace) -> int:
    check_path(args.run)
    out_dir = Path(args.csv)
    if out_dir.exists() and not out_dir.is_dir():
        raise RunError(f"--csv {out_dir}: exists and is not a directory", 2)
    log = open_log(args.run, recover=args.recover)
    if args.recover:
        report_recovered(PROG, log)
    topics = sorted(log.topics)
    if args.topics:
        unknown = [t for t in args.topics if t not in log.topics]
        if unknown:
            raise RunError(f"--topics: {', '.join(unknown)} not in {args.run} "
                           f"(topics: {', '.join(topics)})", 2)
        topics = [t for t in topics if t in set(args.topics)]
    out_dir.mkdir(parents=True, exist_ok=True)
    by_topic: dict[str, list] = {t: [] for t in topics}
    for m in log.messages:
        if m.topic in by_topic:
            by_topic[m.topic].append(m)
    written = []
    for topic in topics:
        msgs = sorted(by_topic[topic], key=lambda m: m.log_time_ns)  # stable: file order on ties
        path = out_dir / csv_name(topic)
        written.append((path, write_csv(path, ((m.log_time_ns, m.message) for m in msgs)), topic))
    print(f"wrote {len(written)} CSV file(s) to {out_dir}/:")
    for path, rows, topic in written:
        print(f"  {path.name:34s} {rows:7d} rows  {log.topics[topic].type}")
    return EXIT_OK


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


def write_csv(path: Path, messages: Iterable[tuple[int, Any]]) -> int:
    """Write (log time ns, decoded message) rows; returns the number of rows."""
    rows: list[dict[str, Any]] = []
    columns: dict[str, None] = {}
    for ns, msg in messages:
        row = {"time": f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"}
        for key, value in flatten(msg):
            key = key or "data"
            if key == "time":  # a field called time must not hide the time column
                key = "/time"
            columns.setdefault(key, None)
            row[key] = _cell(value)
        rows.append(row)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["time", *columns], restval="", extrasaction="raise")
        writer.writeheader()
        writer.writerows(rows)
    return len(rows)
