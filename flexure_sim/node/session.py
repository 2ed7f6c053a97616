"""Recordings of the stage node: file names and metadata record names.

Each recording holds a channel per published topic plus the drive command topic, and a
metadata record ``flexure_sim`` (mechanism, parameters, engine settings); the node records
the same CDR bytes it publishes (written by `record_process`).

Names are claimed, not just chosen: `claim_recording_path` creates the file with
``O_CREAT | O_EXCL`` (atomic on POSIX file systems, NFS v3+ included), so two nodes started in
the same second on one ``record_dir`` (as a launch file does) can never both take one name;
the loser moves on to the next suffix. Existing files are never overwritten.
"""
from __future__ import annotations

import datetime as _dt
import os
from pathlib import Path
from typing import Iterator, Optional

from ..topics import METADATA_NAME, PARAMETER_CHANGE_NAME  # noqa: F401  (the node's names)

#: Suffixes tried before giving up (a directory holding that many runs of one second).
MAX_SUFFIX = 10_000


def node_token(fully_qualified_name: str) -> str:
    """The node's namespace and name as one file-name part: ``/left/stage_node`` becomes
    ``left_stage_node``."""
    parts = [p for p in fully_qualified_name.split("/") if p]
    return "_".join(parts) or "stage_node"


def _candidates(record_dir: str, record_path: str, mechanism_name: str, node: str, index: int,
                now: Optional[_dt.datetime]) -> Iterator[Path]:
    if record_path:
        base = Path(record_path)
        suffix = base.suffix or ".mcap"
        if index == 0:
            yield base
        for k in range(max(index, 1), MAX_SUFFIX):
            yield base.with_name(f"{base.stem}_{k}{suffix}")
        return
    stamp = (now or _dt.datetime.now(_dt.timezone.utc)).strftime("%Y%m%dT%H%M%S")
    stem = f"{mechanism_name}_{node}_{stamp}" if node else f"{mechanism_name}_{stamp}"
    directory = Path(record_dir)
    yield directory / f"{stem}.mcap"
    for k in range(1, MAX_SUFFIX):
        yield directory / f"{stem}_{k}.mcap"


def claim_recording_path(
    record_dir: str,
    record_path: str,
    mechanism_name: str,
    index: int,
    now: Optional[_dt.datetime] = None,
    node: str = "",
) -> Path:
    """Claim the first free name for the ``index``-th recording of this node (0 first):
    create the (empty) file with ``O_EXCL``, so no other process can take it, and return its
    path. The recorder then writes into it. Creates the directory if missing; raises OSError
    if it cannot be written.

    ``record_path`` set: that file for index 0, then ``<stem>_<index><suffix>`` (the next
    free suffix if taken). Otherwise ``<record_dir>/<mechanism>_<node>_<UTC
    YYYYmmddTHHMMSS>.mcap`` (``_1``, ``_2``... appended if the name is taken), ``node`` being
    `node_token` of the node's fully qualified name. Relative paths are relative to the
    working directory.
    """
    parent_made = False
    for candidate in _candidates(record_dir, record_path, mechanism_name, node, index, now):
        if not parent_made:
            candidate.parent.mkdir(parents=True, exist_ok=True)
            parent_made = True
        try:
            fd = os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            continue
        os.close(fd)
        return candidate
    raise FileExistsError(f"{record_dir or record_path}: {MAX_SUFFIX} recordings of one name exist")


def release_claim(path: Path) -> None:
    """Remove a claimed name that was never written (the file is still empty)."""
    try:
        if path.stat().st_size == 0:
            path.unlink()
    except OSError:
        pass
