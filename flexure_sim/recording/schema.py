"""
ROS 2 message schemas for MCAP, built as rosbag2 (Jazzy) builds them.

The schema of ``pkg/msg/Type`` is the text of ``share/pkg/msg/Type.msg`` followed by every
message type it depends on, once each, depth-first, dependencies of one definition taken in
sorted order (rosbag2 keeps them in a ``std::set``). Each dependency is preceded by a blank
line, a line of 80 ``=`` and ``MSG: pkg/Type`` (the type as the field names it). The type hash
(``RIHS01_<hex>``) is read from ``share/pkg/msg/Type.json``.

Definitions are looked up in the ament prefixes: the entries of ``AMENT_PREFIX_PATH``, then
``sys.prefix`` (a virtual environment holding ROS wheels is an ament prefix).
"""
from __future__ import annotations

import json
import os
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from flexure_sim.recording.exceptions import RecordingError, SchemaNotFoundError

SCHEMA_ENCODING = "ros2msg"
SEPARATOR = "=" * 80

# rosbag2's pattern for the field type at the start of each line of a .msg file.
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
# rosbag2's primitive set, plus wstring (rosbag2 would look for a "pkg/wstring" message).
_PRIMITIVES = frozenset(
    {
        "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
        "int32", "uint32", "int64", "uint64", "string", "wstring",
    }
)
_NAME = r"[a-zA-Z][a-zA-Z0-9_]*"
_TYPE_NAME = re.compile(rf"^({_NAME})/(?:({_NAME})/)?({_NAME})$")
_MAX_DEPTH = 50


@dataclass(frozen=True)
class MessageSchema:
    """
    Schema record contents of one message type.

    ``name`` is ``pkg/msg/Type``; ``text`` the concatenated definitions; ``type_hash`` the
    ``RIHS01_...`` string, or ``""`` when the package ships no ``.json`` type description.
    """

    name: str
    text: str
    type_hash: str
    encoding: str = SCHEMA_ENCODING


def normalize_type_name(type_name: str) -> str:
    """Return ``pkg/msg/Type`` for ``pkg/Type`` or ``pkg/msg/Type``; raise ValueError otherwise."""
    package, namespace, name = _split_type_name(type_name)
    return f"{package}/{namespace}/{name}"


def _split_type_name(type_name: str) -> tuple[str, str, str]:
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise ValueError(f"type_name: expected 'pkg/msg/Type' or 'pkg/Type', got {type_name!r}")
    package, namespace, name = match.groups()
    return package, namespace or "msg", name


def ament_prefixes(environ: Mapping[str, str] | None = None) -> tuple[Path, ...]:
    """Prefixes searched for definitions: ``AMENT_PREFIX_PATH`` entries, then ``sys.prefix``."""
    env = os.environ if environ is None else environ
    entries = [Path(p) for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes: list[Path] = []
    for prefix in [*entries, Path(sys.prefix)]:
        if prefix not in prefixes:
            prefixes.append(prefix)
    return tuple(prefixes)


def parse_dependencies(msg_text: str, package: str) -> list[str]:
    """Message types a .msg text refers to, as ``pkg/Type``, sorted and unique (as rosbag2)."""
    found: set[str] = set()
    for match in _FIELD_TYPE.finditer(msg_text):
        field_type = match.group(1)
        if field_type in _PRIMITIVES:
            continue
        found.add(field_type if "/" in field_type else f"{package}/{field_type}")
    return sorted(found)


class SchemaResolver:
    """
    Builds and caches `MessageSchema` objects from the .msg/.json files of ament prefixes.

    One resolver per recorder: the cache lives in the instance.
    """

    def __init__(self, prefixes: Sequence[str | os.PathLike[str]] | None = None) -> None:
        self.prefixes: tuple[Path, ...] = (
            ament_prefixes() if prefixes is None else tuple(Path(p) for p in prefixes)
        )
        self._texts: dict[tuple[str, str, str], str] = {}
        self._schemas: dict[str, MessageSchema] = {}

    def schema(self, type_name: str) -> MessageSchema:
        """Return the schema of ``type_name`` (``pkg/msg/Type`` or ``pkg/Type``)."""
        full_name = normalize_type_name(type_name)
        cached = self._schemas.get(full_name)
        if cached is None:
            cached = MessageSchema(
                name=full_name,
                text=self.full_text(full_name),
                type_hash=self.type_hash(full_name),
            )
            self._schemas[full_name] = cached
        return cached

    def full_text(self, type_name: str) -> str:
        """
        Return the ros2msg schema text.

        The type's .msg, then each dependency once, depth-first.
        """
        seen: set[tuple[str, str, str]] = set()

        def append(key: tuple[str, str, str], depth: int) -> str:
            if depth <= 0:
                raise RecordingError(f"dependencies of {type_name} nest deeper than {_MAX_DEPTH}")
            text = self._msg_text(key)
            parts = [text]
            for dependency in parse_dependencies(text, key[0]):
                dep_key = _split_type_name(dependency)
                if dep_key in seen:
                    continue
                seen.add(dep_key)
                parts.append(f"\n{SEPARATOR}\nMSG: {dependency}\n")
                parts.append(append(dep_key, depth - 1))
            return "".join(parts)

        return append(_split_type_name(type_name), _MAX_DEPTH)

    def type_hash(self, type_name: str) -> str:
        """``RIHS01_<hex>`` of the type from its ``.json`` description, ``""`` if there is none."""
        package, namespace, name = _split_type_name(type_name)
        full_name = f"{package}/{namespace}/{name}"
        path = self._find_file(package, namespace, f"{name}.json")
        if path is None:
            return ""
        try:
            description = json.loads(path.read_text(encoding="utf-8"))
            entries = description["type_hashes"]
            hashes = {entry["type_name"]: entry["hash_string"] for entry in entries}
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise RecordingError(f"{path}: unreadable type description ({exc})") from exc
        if full_name not in hashes:
            raise RecordingError(f"{path}: no type hash for {full_name}")
        return str(hashes[full_name])

    def _msg_text(self, key: tuple[str, str, str]) -> str:
        text = self._texts.get(key)
        if text is None:
            package, namespace, name = key
            path = self._find_file(package, namespace, f"{name}.msg")
            if path is None:
                searched = ", ".join(str(p) for p in self.prefixes) or "(none)"
                raise SchemaNotFoundError(
                    f"no definition of {package}/{namespace}/{name}: "
                    f"share/{package}/{namespace}/{name}.msg is in none of the ament prefixes "
                    f"[{searched}]; install the package or extend AMENT_PREFIX_PATH"
                )
            text = path.read_text(encoding="utf-8")
            self._texts[key] = text
        return text

    def _find_file(self, package: str, namespace: str, file_name: str) -> Path | None:
        """First match under a prefix registering the package (ament index), else any prefix."""
        relative = Path("share", package, namespace, file_name)
        marker = Path("share", "ament_index", "resource_index", "packages", package)
        for prefix in self.prefixes:
            if (prefix / marker).is_file():
                candidate = prefix / relative
                return candidate if candidate.is_file() else None
        for prefix in self.prefixes:
            candidate = prefix / relative
            if candidate.is_file():
                return candidate
        return None


def load_schema(
    type_name: str, prefixes: Sequence[str | os.PathLike[str]] | None = None
) -> MessageSchema:
    """Return the schema of one type, searched in ``prefixes`` (default: `ament_prefixes()`)."""
    return SchemaResolver(prefixes).schema(type_name)
