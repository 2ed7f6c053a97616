"""Recordings of the stage node: file names and metadata record names.

Each recording holds a channel per published topic plus the drive command topic, and a
metadata record ``flexure_sim`` (mechanism, parameters, engine settings); the node records
the same CDR bytes it publishes (written by `record_process`).
"""
from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Optional

from ..topics import METADATA_NAME, PARAMETER_CHANGE_NAME  # noqa: F401  (the node's names)


def recording_path(
    record_dir: str,
    record_path: str,
    mechanism_name: str,
    index: int,
    now: Optional[_dt.datetime] = None,
) -> Path:
    """Where the ``index``-th recording of this node (0 first) goes.

    ``record_path`` set: that file for index 0, then ``<stem>_<index><suffix>``. Otherwise
    ``<record_dir>/<mechanism>_<UTC YYYYmmddTHHMMSS>.mcap`` (``_1``, ``_2``... appended if
    the name is taken). Relative paths are relative to the working directory.
    """
    if record_path:
        base = Path(record_path)
        if index == 0:
            return base
        return base.with_name(f"{base.stem}_{index}{base.suffix or '.mcap'}")
    stamp = (now or _dt.datetime.now(_dt.timezone.utc)).strftime("%Y%m%dT%H%M%S")
    directory = Path(record_dir)
    candidate = directory / f"{mechanism_name}_{stamp}.mcap"
    k = 1
    while candidate.exists():
        candidate = directory / f"{mechanism_name}_{stamp}_{k}.mcap"
        k += 1
    return candidate
