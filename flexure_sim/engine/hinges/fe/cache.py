"""
On-disk cache of finite-element hinge solves, keyed by the solve's dimensionless inputs.

Location: ``$FLEXURE_SIM_CACHE/fe`` if that variable is set, else
``$XDG_CACHE_HOME/flexure_sim/fe``, else ``~/.cache/flexure_sim/fe``. One small JSON file per
solve, named by the SHA-256 of its canonical key (shape, ratios, Poisson's ratio, plane,
resolution, morph target, schema version), holding the key itself and the results. Results
are dimensionless (E = 1, unit plate thickness, lengths in the reference length), so a
sweep over E, the plate thickness or the yield strength, or over sizes at fixed proportions,
solves once.

Reading checks that the stored key equals the requested one and that every number is finite;
an entry that cannot be read, does not parse or fails a check is reported by a
``CacheWarning`` naming the file and the problem, and recomputed (the new result replaces it).
Writes go to a temporary file renamed into place, so a concurrent reader never sees half a
file. A cache directory that cannot be written only costs the speed-up (a warning says so).
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
from pathlib import Path
from typing import Any, Optional

import numpy as np

from flexure_sim.errors import FlexureSimError

#: Bump when the solver changes what a key means (mesh sizing, elements, stress sampling)
#: or what a result holds (2: the fibres' signed stresses, elastic.py).
SCHEMA = 2


class CacheWarning(FlexureSimError, UserWarning):
    """
    A cache entry was unreadable or inconsistent and is recomputed, or could not be stored.

    Under the package's root too, so warnings turned into errors are caught with the others.
    """


def directory() -> Path:
    """Return where the cache is (see the module docstring); it may not exist yet."""
    root = os.environ.get("FLEXURE_SIM_CACHE")
    if root:
        return Path(root) / "fe"
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "flexure_sim" / "fe"


def _canonical(key: dict) -> str:
    return json.dumps({"schema": SCHEMA, **key}, sort_keys=True, separators=(",", ":"))


def path_of(key: dict) -> Path:
    """Return the file of a key."""
    digest = hashlib.sha256(_canonical(key).encode()).hexdigest()[:40]
    return directory() / f"{digest}.json"


def load(key: dict, layout: dict[str, tuple[int, ...]]) -> Optional[dict[str, np.ndarray]]:
    """
    Return the stored results of ``key`` as arrays of the shapes in ``layout``, or None.

    None with a CacheWarning if the entry is bad (module docstring).
    """
    path = path_of(key)
    try:
        text = path.read_text(encoding="utf-8")
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, UnicodeDecodeError) as exc:
        return _bad(path, f"cannot be read ({exc})")
    try:
        entry = json.loads(text)
    except json.JSONDecodeError as exc:
        return _bad(path, f"is not valid JSON ({exc.msg} at line {exc.lineno})")
    if not isinstance(entry, dict) or entry.get("key") != json.loads(_canonical(key)):
        return _bad(path, "holds another solve's key")
    results = entry.get("results")
    if not isinstance(results, dict):
        return _bad(path, "has no results")
    try:
        values = {k: np.asarray(results[k], dtype=float).reshape(shape)
                  for k, shape in layout.items()}
    except KeyError as exc:
        return _bad(path, f"has no result {exc.args[0]!r}")
    except (TypeError, ValueError):
        return _bad(path, "holds a result that is not numeric or of the wrong size")
    if not all(np.all(np.isfinite(v)) for v in values.values()):
        return _bad(path, "holds a result that is not finite")
    return values


def _bad(path: Path, problem: str) -> Optional[dict[str, np.ndarray]]:
    """Warn that the entry at ``path`` is bad and return None: ``load``'s answer for it."""
    warnings.warn(f"finite-element cache entry {path} {problem}: recomputing it",
                  CacheWarning, stacklevel=3)
    return None


def store(key: dict, results: dict[str, Any]) -> None:
    """Write ``results`` (arrays or numbers) for ``key``; a failure only warns."""
    path = path_of(key)
    entry = {"key": json.loads(_canonical(key)),
             "results": {k: np.asarray(v, dtype=float).tolist() for k, v in results.items()}}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".json")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                json.dump(entry, f)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError as exc:
        warnings.warn(f"finite-element cache {path.parent} cannot be written ({exc}): the "
                      "solve is not cached", CacheWarning, stacklevel=2)
