"""
Paths into a mechanism's YAML document.

Resolving ``hinges.a.stiffness.h`` to concrete steps, and setting a number at such a path without
changing the document.

A path is dot-separated: mapping keys, list indices, or the ``name`` of an element of a list
of named items (``hinges.a`` is the hinge named a). A path through a hinge's ``stiffness``
that names a shared stiffness model (``stiffness: notch``) reaches that hinge's own copy of
the model: ``own_stiffness`` makes the copy, from the shared model as the document has it.
"""
from __future__ import annotations

import math
from typing import Any, Iterable, Optional, Sequence


def set_path(doc: Any, path: Sequence, value: float) -> Any:
    """
    Return a copy of ``doc`` with the number at ``path`` replaced.

    Only the containers along the path are copied, the rest is shared with ``doc``.
    """
    return _replace(doc, path, value)


def resolve_path(doc: dict, text: str, fail) -> tuple[tuple, Optional[tuple], float]:
    """
    Resolve a dotted path against the mechanism document.

    Returns the concrete steps, the hinge stiffness the path reaches through (``(steps to
    the hinge's stiffness key, model name)``, or None) and the base value.
    ``fail(problem)`` builds the error.
    """
    if not isinstance(text, str) or not text:
        raise fail(f"expected a dotted path such as stiffness_models.notch.h, got {text!r}")
    parts = text.split(".")
    steps: list = []
    through: Optional[tuple] = None
    node: Any = doc
    for i, part in enumerate(parts):
        where = ".".join(parts[:i]) or "the document"
        if isinstance(node, str) and steps[-1:] == ["stiffness"] and through is None:
            models = doc.get("stiffness_models") or {}
            if node not in models:
                raise fail(f"{where} names {node!r}, which stiffness_models lacks")
            through, node = (tuple(steps), node), models[node]
        if isinstance(node, dict):
            if part not in node:
                raise fail(f"{where} has no key {part!r} (keys: {', '.join(map(str, node))})")
            steps.append(part)
        elif isinstance(node, list):
            steps.append(_list_index(node, part, where, fail))
        else:
            raise fail(f"{where} is {node!r}, not a mapping or list: cannot look up {part!r}")
        node = node[steps[-1]]
    if isinstance(node, str):
        try:
            node = float(node)  # PyYAML reads 69.0e9 as a string; the loader accepts it
        except ValueError:
            pass
    if isinstance(node, bool) or not isinstance(node, (int, float)) or not math.isfinite(node):
        raise fail(f"{text} is {node!r}, not a finite number")
    return tuple(steps), through, float(node)


def _list_index(node: list, part: str, where: str, fail) -> int:
    if part.lstrip("-").isdigit():
        k = int(part)
        if not -len(node) <= k < len(node):
            raise fail(f"{where} has {len(node)} elements, no index {k}")
        return k % len(node)
    names = [e.get("name") for e in node if isinstance(e, dict)]
    if part not in names:
        raise fail(f"{where} has no element named {part!r} (names: {', '.join(map(str, names))})")
    return names.index(part)


def apply(doc: dict, changes: Iterable[tuple[tuple, Optional[tuple], Any]]) -> dict:
    """
    Return a copy of ``doc`` with each (steps, through, value) of ``resolve_path`` set.

    Shared values first, then each hinge that gets its own stiffness copies the shared model
    as changed (``own_stiffness``), then that hinge's own values: the result does not depend
    on the order of ``changes``. Values may be any numbers, HyperDual too (values.py).
    """
    changes = list(changes)
    for own in (False, True):
        for steps, through, value in changes:
            if (through is not None) != own:
                continue
            if through is not None:
                doc = own_stiffness(doc, through)
            doc = set_path(doc, steps, value)
    return doc


def own_stiffness(doc: dict, through: tuple) -> dict:
    """
    Return ``doc`` with the hinge stiffness at ``through[0]`` replaced by its own model copy.

    The copy is of the shared model ``through[1]`` (as ``doc`` has it, i.e. with any values
    already set).
    """
    steps, model = through
    node: Any = doc
    for step in steps:
        node = node[step]
    if isinstance(node, dict):  # already the hinge's own
        return doc
    return _replace(doc, steps, dict(doc["stiffness_models"][model]))


def _replace(doc: Any, path: Sequence, value: Any) -> Any:
    if not path:
        return value
    new = list(doc) if isinstance(doc, list) else dict(doc)
    new[path[0]] = _replace(doc[path[0]], path[1:], value)
    return new
