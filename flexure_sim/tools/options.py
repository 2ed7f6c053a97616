"""The command-line options the tools share: file tools' RUN options, drive inputs."""
from __future__ import annotations

import argparse
import math
from typing import Any, Optional


def add_file_arguments(parser: Any, recover: bool = True, namespace: bool = True) -> None:
    """RUN, --recover, --strict and --namespace."""
    parser.add_argument("run", metavar="RUN",
                        help="recording of stage_node (or ros2 bag record): a bag directory "
                        "(its files in order, as one run) or one MCAP file")
    if recover:
        parser.add_argument("--recover", action="store_true",
                            help="read what is readable of a truncated or damaged file "
                            "instead of failing")
    parser.add_argument("--strict", action="store_true",
                        help="refuse a file holding a message that does not decode as its "
                        "topic's type (by default such messages are skipped and counted)")
    if namespace:
        parser.add_argument("--namespace", default=None,
                            help="namespace of the stage's topics when the file holds several "
                            "(default: inferred)")


def parse_drive_inputs(text: Optional[str], option: str = "--input"):
    """
    Return the drive inputs written on the command line, as ``Model.drive_inputs`` takes them.

    ``NAME=VALUE,...`` (a mapping; every drive named), ``V1,V2,...`` (one value per drive, in
    the mechanism's drive order) or one number (a single drive); None stays None. ValueError
    naming ``option`` for anything that is not a number, and for a drive named twice.
    """
    if text is None:
        return None
    parts = [p.strip() for p in str(text).split(",")]
    if any("=" in p for p in parts):
        out = {}
        for p in parts:
            name, eq, value = p.partition("=")
            if not eq or not name.strip():
                raise ValueError(f"{option} {text!r}: expected NAME=VALUE for every drive "
                                 f"(e.g. x=1e-6,y=0), got {p!r}")
            if name.strip() in out:
                raise ValueError(f"{option} {text!r}: drive {name.strip()} is given twice")
            out[name.strip()] = _float(value, option, text)
        return out
    values = [_float(p, option, text) for p in parts]
    return values[0] if len(values) == 1 else values


def _float(value: str, option: str, text: str) -> float:
    try:
        return float(value)
    except ValueError:
        raise ValueError(f"{option} {text!r}: {value.strip()!r} is not a number") from None


def count(text: str) -> int:
    """
    Return a count of things given on the command line (an argparse type): a positive integer.

    Written as an integer or as a number with an integral value (``1e8``).
    """
    try:
        value = int(text)
    except ValueError:
        try:
            number = float(text)
        except ValueError:
            number = float("nan")
        value = int(number) if math.isfinite(number) and number == int(number) else 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a positive integer")
    return value
