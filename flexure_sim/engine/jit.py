"""
Compiled kernels: Numba's ``njit``, and an on-disk cache that follows every compiled source.

Without Numba, ``njit`` returns the function unchanged (the engine stays importable).
Numba keys a cached function on its own source file's time stamp and size only, not on the
files of the functions it compiles in (a documented limitation: numba issue #1833, "Caching
issue: functions in different modules"). ``step_loop.advance`` compiles in ``step_energy``,
``kernels`` and the hinge force chain's formula modules (``laws.hinge_force`` and what it
calls): after a change to ``step_energy.py`` alone it loaded its old machine code, which then
failed on the new arguments. ``revalidate`` keeps a SHA-256 of
every source a kernel module imports from the package, transitively, next to each kernel's
cache, and flushes the cache when the digest differs. Hand-written because Numba offers no such key
(its issue #9304 asks for one).
"""
from __future__ import annotations

import ast
import hashlib
from pathlib import Path
from typing import Iterable

try:  # Numba is a declared dependency; the fallback keeps the engine importable without it.
    from numba import njit

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only where Numba is missing
    HAVE_NUMBA = False

    def njit(*args, **kwargs):  # type: ignore[no-redef]  # the stand-in without Numba
        if args and callable(args[0]):
            return args[0]
        return lambda f: f


_PACKAGE = "flexure_sim"
#: The folder holding the package (its absolute imports resolve from here).
_ROOT = Path(__file__).resolve().parents[2]


def kernel_sources(module_file: str) -> list[Path]:
    """Return ``module_file`` and every package module it imports, transitively."""
    start = Path(module_file).resolve()
    seen: dict[Path, None] = {}
    todo = [start]
    while todo:
        path = todo.pop()
        if path in seen or not path.is_file():
            continue
        seen[path] = None
        for node in ast.walk(ast.parse(path.read_bytes())):
            if not isinstance(node, ast.ImportFrom):
                continue
            module = node.module or ""
            if module.startswith(_PACKAGE):
                stem = _ROOT.joinpath(*module.split("."))
                todo.append(stem.with_suffix(".py"))
                todo.append(stem / "__init__.py")
                todo.extend(stem / f"{alias.name}.py" for alias in node.names)
    return sorted(seen)


def sources_digest(files: Iterable[Path]) -> str:
    """Return the SHA-256 of the files' names and contents."""
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def dispatchers_of(*namespaces) -> list:
    """
    Return the Numba dispatchers (``njit`` functions) defined in modules or module globals.

    Dispatchers a namespace imports from another module are left to that module: each
    dispatcher's digest stamp has one owner (two digests for one stamp would flush it on
    every import).
    """
    found = {}
    for space in namespaces:
        names = space if isinstance(space, dict) else vars(space)
        for value in names.values():
            if (hasattr(value, "py_func") and hasattr(value, "_cache")
                    and value.py_func.__module__ == names.get("__name__")):
                found[id(value)] = value
    return list(found.values())


def revalidate(dispatchers: Iterable, module_file: str) -> None:
    """
    Flush the disk caches of ``dispatchers`` whose recorded sources digest is not current.

    Call at import, after the dispatchers are made and before their first call (Numba loads
    a cache at the first call). Dispatchers without a disk cache are skipped; a cache
    directory that cannot be written is left to Numba (it then does not cache there either).
    """
    digest = sources_digest(kernel_sources(module_file))
    for dispatcher in dispatchers:
        cache = getattr(dispatcher, "_cache", None)
        path = getattr(cache, "cache_path", None)
        if cache is None or path is None:
            continue
        func = dispatcher.py_func
        stamp = Path(path) / f"{func.__module__}.{func.__qualname__}.sources-sha256"
        try:
            if stamp.read_text() == digest:
                continue
        except OSError:
            pass
        try:
            cache.flush()
            stamp.write_text(digest)
        except OSError:
            pass
