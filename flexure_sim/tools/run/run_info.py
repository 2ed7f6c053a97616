"""
``flexure-sim info RUN.mcap``.

topics, types, counts, rates, duration, and the mechanism and parameters of the run (the
``flexure_sim`` metadata record stage_node writes when recording).

    flexure-sim info runs/stage.mcap [--json] [--yaml] [--recover] [--strict] [--no-decode]

The whole file is read once: every chunk's CRC is checked and every message decoded, so that
damage and messages that do not decode are reported.
"""
from __future__ import annotations

import argparse
import json
from typing import Any, Optional

from flexure_sim.recording import LogInfo, log_info
from flexure_sim.recording.command_line import check_path, report_reading, tool_errors
from flexure_sim.recording.exceptions import EXIT_OK
from flexure_sim.recording.reader import undecodable_note
from flexure_sim.topics import METADATA_NAME, PARAMETER_CHANGE_NAME
from flexure_sim.tools.options import add_file_arguments
from flexure_sim.tools.tables import columns

PROG = "flexure-sim info"

#: The node's parameters as recorded (node/params/table.py), with their units.
PARAMETER_UNITS = {
    "mechanism": "", "time_mode": "", "publish_rate": "Hz", "sim_step": "s", "stroke_min": "m",
    "stroke_max": "m", "slew_rate": "m/s", "record": "", "record_dir": "", "record_path": "",
}
MECHANISM_KEYS = ("mechanism_name", "mechanism_path", "mechanism_yaml")
RUN_KEYS = (
    "node",
    "flexure_sim_version",
    "run",
    "started_utc",
    "sim_time_start",
    "steps_per_tick",
    "relinearize_tol",
    "root_frame",
    "bodies",
    "hinges",
)


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "info", help="topics, counts, duration, mechanism and parameters of a recorded run",
        description=__doc__.split("\n\n")[0].replace("``", ""))
    add_file_arguments(p, namespace=False)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--yaml", action="store_true", help="also print the recorded mechanism YAML")
    p.add_argument("--no-decode", action="store_true",
                   help="check the CRCs but decode no message (faster on long recordings; "
                   "messages that do not decode are then not counted)")
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    return tool_errors(PROG, lambda: _run(args), can_recover=not args.recover)


def _run(args: argparse.Namespace) -> int:
    info = log_info(check_path(args.run), recover=args.recover, strict=args.strict,
                    decode=not args.no_decode)
    report_reading(PROG, info)
    summary = summarize(info)
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(format_summary(summary, show_yaml=args.yaml))
    return EXIT_OK


def summarize(info: LogInfo) -> dict:
    """Return the info of a log as a JSON-ready dict (times in s, sizes in bytes)."""
    duration = info.duration_ns / 1e9
    topics = []
    for name, topic in sorted(info.topics.items()):
        rate = (
            (topic.message_count - 1) / duration
            if duration > 0 and topic.message_count > 1
            else None
        )
        qos = topic.qos[0] if topic.qos else None
        topics.append(
            {
                "name": name,
                "type": topic.type,
                "count": topic.message_count,
                "rate_hz": rate,
                "qos": (
                    None
                    if qos is None
                    else {
                        "reliability": qos.reliability,
                        "durability": qos.durability,
                        "history": qos.history,
                        "depth": qos.depth,
                    }
                ),
            }
        )
    meta = info.flexure_sim
    changes = [dict(d) for name, d in info.metadata_records if name == PARAMETER_CHANGE_NAME]
    other_records = sorted({name for name, _ in info.metadata_records}
                           - {METADATA_NAME, PARAMETER_CHANGE_NAME, "rosbag2"})
    return {
        "path": str(info.path),
        "size_bytes": info.size_bytes,
        "profile": info.profile,
        "library": info.library,
        "complete": info.complete,
        "note": info.note,
        "chunk_count": info.chunk_count,
        # A bag directory: its files, in order (relative to it); None for one MCAP file.
        "bag_files": ([f["path"] for f in (info.bag_metadata or {}).get("files") or []]
                      if info.path.is_dir() else None),
        "unchecked_chunks": info.unchecked_chunks,
        "message_count": info.message_count,
        "start": info.start_ns / 1e9 if info.message_count else None,
        "end": info.end_ns / 1e9 if info.message_count else None,
        "duration": duration,
        "topics": topics,
        "mechanism": (
            {
                "name": meta.get("mechanism_name") or meta.get("mechanism"),
                "path": meta.get("mechanism_path"),
                "yaml": meta.get("mechanism_yaml"),
                "bodies": [b for b in meta.get("bodies", "").split(",") if b],
                "hinges": [h for h in meta.get("hinges", "").split(",") if h],
            }
            if meta
            else None
        ),
        "parameters": _parameters(meta),
        "run": {k: meta[k] for k in RUN_KEYS if k in meta},
        "other_metadata": {
            k: v
            for k, v in sorted(meta.items())
            if k not in PARAMETER_UNITS and k not in RUN_KEYS and k not in MECHANISM_KEYS
        },
        "parameter_changes": changes,
        "other_metadata_records": other_records,
        "dropped_messages": info.dropped_messages,
        "undecodable": dict(sorted(info.undecodable.items())) if info.decoded else None,
        **drives_and_outputs(info),
    }


def _parameters(meta: dict) -> dict:
    """
    Return the node's recorded parameters of `PARAMETER_UNITS`.

    Without the single drive's stroke and slew rate when the run had per-drive ones
    (``drives.<name>.stroke_min``...: node/inputs/drive_bank.py): the node declares the
    single-drive ones then but never uses them; `drives_and_outputs` lists each drive's own.
    """
    per_drive = any(k.startswith("drives.") for k in meta)
    return {k: meta[k] for k in PARAMETER_UNITS
            if k in meta and not (per_drive and k in ("stroke_min", "stroke_max", "slew_rate"))}


def drives_and_outputs(info: LogInfo) -> dict:
    """
    ``drives`` and ``outputs`` of a run with several drives or outputs (issue 13), else {}.

    Each drive: name, kind, unit and its topics (command, input, force or position); each
    output: name, unit, topic. A single-drive, single-output run reports nothing more.
    """
    from flexure_sim.recording.exceptions import RunError
    from flexure_sim.tools.run.run_channels import drive_channels, is_single_drive, output_channels
    from flexure_sim.tools.run.mechanism_reload import load_recorded_mechanism
    from flexure_sim.tools.run.runlog import find_namespace

    try:
        ns = find_namespace(info)
    except RunError:
        return {}

    def topic(rel: str) -> str:
        return f"{ns}/{rel}"

    meta = info.flexure_sim or {}
    if is_single_drive(info.topics, topic):
        return {}
    mech = load_recorded_mechanism(meta)[0] if meta else None
    drives = drive_channels(info.topics, topic, meta, mech)
    outputs = output_channels(info.topics, topic, meta, mech)
    if not drives and not outputs:
        return {}

    def limit(drive: str, key: str) -> Optional[str]:  # the node's per-drive parameters
        return meta.get(f"drives.{drive}.{key}") if len(drives) > 1 or drives[0].command != \
            "drive/displacement" else meta.get(key)

    return {
        "drives": [{"name": d.name, "kind": d.kind, "unit": d.unit, "command": topic(d.command),
                    "command_unit": d.command_unit, "input": topic(d.input),
                    "response": topic(d.response) if d.response else None,
                    "response_unit": d.response_unit,
                    "stroke_min": limit(d.name, "stroke_min"),
                    "stroke_max": limit(d.name, "stroke_max"),
                    "slew_rate": limit(d.name, "slew_rate")} for d in drives],
        "outputs": [{"name": o.name, "unit": o.unit, "topic": topic(o.topic)} for o in outputs],
    }


def _size(n: int) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} B"


def format_summary(s: dict, show_yaml: bool = False) -> str:
    state = "complete" if s["complete"] else "INCOMPLETE (recovered part)"
    lines = [
        f"File:         {s['path']}  ({_size(s['size_bytes'])}, {state})",
        f"Format:       MCAP, profile {s['profile']} (rosbag2), written by "
        f"{s['library'] or 'unknown'}; "
        f"{s['chunk_count']} chunk(s)",
    ]
    if s.get("bag_files") is not None:
        lines.append(f"Bag:          rosbag2 bag directory (metadata.yaml), "
                     f"{len(s['bag_files'])} file(s): {', '.join(s['bag_files'])}")
    if s["message_count"]:
        lines.append(f"Duration:     {s['duration']:.6f} s of log time (simulation time), "
                     f"{s['start']:.6f} s to {s['end']:.6f} s")
    else:
        lines.append("Duration:     0 s (no messages)")
    lines.append(f"Messages:     {s['message_count']}")
    if s["unchecked_chunks"]:
        lines.append(f"Integrity:    no CRC in {s['unchecked_chunks']} of {s['chunk_count']} "
                     "chunk(s) (the writer wrote none): damage inside them cannot be detected")
    elif s["chunk_count"]:
        lines.append(f"Integrity:    the CRCs of all {s['chunk_count']} chunk(s) match")
    if s["dropped_messages"] not in (None, "0"):
        lines.append(f"Dropped:      {s['dropped_messages']} message(s) could not be recorded")
    if s["undecodable"]:
        lines.append(f"Undecodable:  {undecodable_note(s['undecodable'])} (skipped by the tools; "
                     "the bytes are kept in the file)")
    if not s["complete"] and s["note"]:
        lines.append(f"Recovered:    {s['note']}")
    lines.append("")
    rows = [[t["name"], t["type"], str(t["count"]), f"{t['rate_hz']:.6g}" if t["rate_hz"] else "-",
             (t["qos"]["reliability"] if t["qos"] else "-")] for t in s["topics"]]
    lines.append(columns(rows, ["topic", "type", "count", "rate [Hz]", "qos"], "<<>><"))
    if s.get("drives") or s.get("outputs"):
        lines.append("")
        for d in s.get("drives", []):
            response = f", {d['response']} [{d['response_unit']}]" if d["response"] else ""
            cu = d["command_unit"]  # the node's limits are in the command's unit
            limits = (f"; stroke [{d['stroke_min']}, {d['stroke_max']}] {cu}"
                      if d["stroke_min"] is not None else "")
            if d["slew_rate"] is not None:
                limits += f", slew rate {d['slew_rate']} {cu}/s"
            lines.append(f"{'Drives:' if d is s['drives'][0] else '':14s}{d['name']} "
                         f"({d['kind']}, {d['unit']}{limits}): command {d['command']}"
                         + (f" [{d['command_unit']}]" if d["command_unit"] != d["unit"] else "")
                         + ", "
                         f"input {d['input']}{response}")
        for o in s.get("outputs", []):
            lines.append(f"{'Outputs:' if o is s['outputs'][0] else '':14s}{o['name']} "
                         f"({o['unit']}): {o['topic']}")
    lines.append("")
    mech = s["mechanism"]
    if mech is None:
        lines.append("Mechanism:    not recorded (the file has no flexure_sim metadata record: "
                     "not written by stage_node)")
    else:
        yaml_text = mech["yaml"] or ""
        stored = f"; YAML recorded, {len(yaml_text.splitlines())} lines" if yaml_text else ""
        lines.append(
            f"Mechanism:    {mech['name'] or 'unknown'}  "
            f"({mech['path'] or 'path not recorded'}{stored})"
        )
        if mech["bodies"] or mech["hinges"]:
            lines.append(
                f"              bodies {', '.join(mech['bodies'])}; hinges "
                f"{', '.join(mech['hinges'])}"
            )
        run = s["run"]
        if run:
            parts = [
                f"node {run['node']}" if "node" in run else "",
                (
                    f"flexure_sim {run['flexure_sim_version']}"
                    if "flexure_sim_version" in run
                    else ""
                ),
                f"run {run['run']}" if "run" in run else "",
                f"started {run['started_utc']}" if "started_utc" in run else "",
            ]
            lines.append(f"Recorded by:  {', '.join(p for p in parts if p)}")
        if s["parameters"]:
            lines.append("Parameters:")
            width = max(len(k) for k in s["parameters"])
            for k, v in s["parameters"].items():
                unit = PARAMETER_UNITS.get(k, "")
                extra = ""
                if k == "sim_step" and "steps_per_tick" in run:
                    extra = f"  ({run['steps_per_tick']} engine steps per tick)"
                shown = v if v != "" else "''"
                lines.append(f"  {k:<{width}}  {shown}{' ' + unit if unit else ''}{extra}")
        rest = {
            k: v
            for k, v in s["run"].items()
            if k not in ("node", "flexure_sim_version", "run", "started_utc", "bodies", "hinges")
        }
        rest.update(s["other_metadata"])
        if rest:
            lines.append("Run settings:")
            width = max(len(k) for k in rest)
            for k, v in rest.items():
                lines.append(f"  {k:<{width}}  {v}")
        if s["parameter_changes"]:
            lines.append("Parameter changes during the run:")
            for change in s["parameter_changes"]:
                t = change.pop("t", "?")
                lines.append(f"  t = {t} s: " + ", ".join(f"{k} = {v}" for k, v in change.items()))
        if show_yaml and yaml_text:
            lines += ["", f"--- recorded mechanism YAML ({mech['name']}) ---", yaml_text.rstrip()]
    if s["other_metadata_records"]:
        lines.append(f"Other metadata records: {', '.join(s['other_metadata_records'])}")
    return "\n".join(lines)
