"""Reading text and YAML data files, with one-line errors that name the file and the problem."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml


def read_text(path: str | Path, error: type[Exception]) -> str:
    """
    Return the UTF-8 text of a file.

    A file that cannot be read, or is binary or in another encoding, raises ``error`` naming the
    file and where the first bad byte is.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:  # e.g. a NUL byte in the path
        raise error(f"{str(path)!r}: cannot read: {exc}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        where = f"byte 0x{data[exc.start]:02x} at line {line}, column {column}"
        if _looks_binary(data):
            raise error(f"{path}: a binary file, not text ({where} is not UTF-8)") from None
        raise error(
            f"{path}: not UTF-8 text: {where} is not UTF-8 (re-save the file as UTF-8)"
        ) from None


def _looks_binary(data: bytes) -> bool:
    """NUL bytes or many control bytes in the first kilobyte: not a text file at all."""
    head = data[:1024]
    control = sum(1 for b in head if b < 32 and b not in (9, 10, 13))
    return b"\0" in head or control > len(head) // 10


def read_yaml(path: str | Path, error: type[Exception]) -> Any:
    """
    Parse a YAML file.

    unreadable, non-UTF-8 or invalid files raise ``error`` with a one-line message naming the file
    (and the line and column of a syntax error).
    """
    path = Path(path)
    text = read_text(path, error)
    try:
        return yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        problem = exc.problem or exc.context or "syntax error"
        context = f" ({exc.context})" if exc.context and exc.problem else ""
        raise error(f"{path}: not valid YAML: {where}{problem}{context}") from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        column = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        raise error(
            f"{path}: not valid YAML: line {line}, column {column}: character "
            f"#x{exc.character:04x} is not allowed in YAML (a binary file?)"
        ) from None
    except yaml.YAMLError as exc:
        raise error(f"{path}: not valid YAML: {_one_line(exc)}") from None
    except (ValueError, OverflowError) as exc:
        # PyYAML lets the constructors' own errors through, e.g. the date 2024-13-01.
        raise error(f"{path}: not valid YAML: a value cannot be read: {_one_line(exc)}") from None
    except RecursionError:
        raise error(f"{path}: not valid YAML: the document is nested too deeply") from None


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())
