"""
What every program that reads a log shares (the flexure-sim tools and the replay node).

Opening a log given on the command line, warnings, and `tool_errors`, the one place where bad files
and bad usage become one line on stderr and an exit code (`EXIT_BAD_FILE` for a bad or unusable
file, `EXIT_USAGE` for bad usage). No traceback reaches the user, whatever the file holds.
"""
from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from flexure_sim.recording.exceptions import (
    EXIT_BAD_FILE, EXIT_OK, CorruptLogError, RecordingError, RunError, UndecodableMessageError,
)
from flexure_sim.recording.bag import is_bag_directory
from flexure_sim.recording.reader import LogReader, open_reader, undecodable_note


def check_path(path: str | os.PathLike[str]) -> Path:
    """
    Return ``path`` as a Path.

    `RunError` (usage) if it is missing or a directory that is not a bag (no metadata.yaml,
    no MCAP file).
    """
    p = Path(path)
    if not p.exists():
        raise RunError(f"{p}: no such file", 2)
    if p.is_dir() and not is_bag_directory(p):
        raise RunError(f"{p}: is a directory without metadata.yaml or MCAP files, not a bag", 2)
    return p


def open_log(
    path: str | os.PathLike[str], recover: bool = False, strict: bool = False
) -> LogReader:
    """Return a `LogReader` of a checked path (a `bag_read.BagReader` of a bag directory)."""
    return open_reader(check_path(path), recover=recover, strict=strict)


def check_readable(reader: LogReader) -> None:
    """After the pass: with ``recover``, a file with nothing readable still fails."""
    if not reader.complete and not reader.message_count:
        raise RunError(f"{reader.path}: nothing readable: {reader.note}")


def warn(prog: str, message: str) -> None:
    print(f"{prog}: warning: {message}", file=sys.stderr)


def report_reading(prog: str, reader: Any) -> None:
    """
    After the pass, say on stderr what was not read.

    The part of a damaged file lost (``--recover``) and the messages skipped because they do not
    decode (one line each).
    """
    path = getattr(reader, "path", "")
    note = getattr(reader, "note", "")
    if note:
        warn(prog, f"{path}: incomplete file: {note}")
    skipped = undecodable_note(getattr(reader, "undecodable", {}))
    if skipped:
        warn(prog, f"{path}: {skipped} (skipped; --strict refuses such a file)")


@contextlib.contextmanager
def _no_broken_pipe() -> Iterator[None]:
    try:
        yield
    except BrokenPipeError:
        # Output piped into `head` & co.: stop quietly (and keep Python from complaining).
        with contextlib.suppress(Exception):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        raise


def tool_errors(prog: str, work: Callable[[], int], can_recover: bool = True) -> int:
    """
    Run ``work`` and turn every expected failure into a message and an exit code.

    ``can_recover``: the command has a ``--recover`` option the user did not give, so a
    damaged file with readable messages gets the hint to use it.
    """
    try:
        with _no_broken_pipe():
            return work()
    except UndecodableMessageError as exc:
        print(f"{prog}: error: {exc.path}: {exc.reason} (--strict; without it such messages "
              "are skipped and counted)", file=sys.stderr)
        return EXIT_BAD_FILE
    except CorruptLogError as exc:
        hint = ""
        if can_recover and exc.readable_messages:
            hint = "; --recover reads the readable part"
        print(f"{prog}: error: {_plain(exc)}{hint}", file=sys.stderr)
        return EXIT_BAD_FILE
    except RunError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except RecordingError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_FILE
    except BrokenPipeError:
        return EXIT_OK
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:
        name = f"{exc.filename}: " if exc.filename else ""
        print(f"{prog}: error: {name}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_FILE
    except Exception as exc:  # noqa: BLE001 - last resort: a message, never a traceback
        if os.environ.get("FLEXURE_SIM_DEBUG"):
            raise
        print(f"{prog}: error: unexpected {type(exc).__name__}: {exc} "
              "(set FLEXURE_SIM_DEBUG=1 for the traceback)", file=sys.stderr)
        return EXIT_BAD_FILE


def _plain(exc: CorruptLogError) -> str:
    """Return the error without the library's Python hint (``recover=True``)."""
    return str(exc).split("; open it with recover=True")[0]
