"""The command-line options every file tool shares."""
from __future__ import annotations

from typing import Any


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
