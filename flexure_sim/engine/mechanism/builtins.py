"""
Where the built-in mechanisms (the ``config/*.yaml`` files shipped with the package) live.

The same files are found in three layouts:

- an install (``pip install .``, ``colcon build``, a Debian package): the code sits in
  ``<prefix>/lib/pythonX.Y/site-packages/flexure_sim`` (or ``lib/python3/dist-packages``)
  and setup.py's data_files put the files in ``<prefix>/share/flexure_sim/config``, the
  directory the ament index names (``get_package_share_directory('flexure_sim')``);
- a source checkout (tests, ``pip install -e .``, ``colcon build --symlink-install``, whose
  symlinks resolve to the sources): ``config/`` beside ``flexure_sim/`` and ``package.xml``;
- an unusual layout (zipped, vendored) where the code's location names no prefix: then only
  the ament index knows.

Order, and why the ament index is not asked first: the files must be those of the install
whose code is running, because a mechanism file and the loader that reads it belong to one
version. When a colcon workspace is sourced over a virtual environment that also holds a pip
copy, both prefixes are on ``AMENT_PREFIX_PATH`` and the index answers with the first one,
which depends on the order the setup scripts were sourced in, while Python imports the code
of whichever copy comes first on ``sys.path``. The two orders need not agree, and the old
lookup (``sys.prefix/share``) loaded a pip copy's files under a colcon install's code. So:

1. the running code's own install: ``<prefix>/share/flexure_sim/config`` of the prefix the
   module lies in (the directory the ament index names when that prefix is the one it
   finds), or the source checkout's ``config/``;
2. else the ament index (``ament_index_python``, imported lazily and optionally: the engine
   works without ROS), for layouts where the code's location names no prefix;
3. else nothing: :func:`builtin_dir` returns None and the caller says where it looked.

Whichever file is used is named by the caller (``stage_node``'s start-up log and its
``mechanism_path`` metadata, ``flexure-sim simulate``'s first line).
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

PACKAGE = "flexure_sim"
#: Folder of the built-in mechanisms inside the package's share directory (and the checkout).
SUBDIR = "config"

_PACKAGE_DIR = Path(__file__).resolve().parents[2]


def install_prefix(package_dir: Path = _PACKAGE_DIR) -> Optional[Path]:
    """
    Return the prefix an installed package directory belongs to, or None if it is not installed.

    ``<prefix>/lib/pythonX.Y/site-packages/<pkg>``, ``<prefix>/lib64/pythonX.Y/...`` and
    Debian's ``<prefix>/lib/python3/dist-packages/<pkg>`` give ``<prefix>``.
    """
    site = package_dir.parent
    if site.name not in ("site-packages", "dist-packages"):
        return None
    pyver, lib = site.parent, site.parent.parent
    if not pyver.name.startswith("python") or lib.name not in ("lib", "lib64"):
        return None
    return lib.parent


def own_data_dir(package_dir: Path = _PACKAGE_DIR) -> Optional[Path]:
    """Return the built-in mechanisms of the install (or checkout) ``package_dir`` belongs to."""
    prefix = install_prefix(package_dir)
    if prefix is not None:
        candidate = prefix / "share" / PACKAGE / SUBDIR
    else:
        checkout = package_dir.parent
        if not (checkout / "package.xml").is_file():
            return None
        candidate = checkout / SUBDIR
    return candidate if candidate.is_dir() else None


def ament_index_dir() -> Optional[Path]:
    """
    ``<share>/config`` of the first prefix on AMENT_PREFIX_PATH that registers the package.

    None without ``ament_index_python`` (no ROS), without AMENT_PREFIX_PATH, or when no prefix
    registers the package.
    """
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )
    except ImportError:
        return None
    try:
        share = Path(get_package_share_directory(PACKAGE))
    except (PackageNotFoundError, OSError, ValueError):
        # OSError: AMENT_PREFIX_PATH unset or empty (ament_index_python raises EnvironmentError).
        return None
    candidate = share / SUBDIR
    return candidate if candidate.is_dir() else None


def builtin_dir() -> Optional[Path]:
    """Return the directory the built-in mechanisms are read from (see the module docstring)."""
    return own_data_dir() or ament_index_dir()


def builtin_names() -> list[str]:
    """Names of the built-in mechanisms (file stems), sorted; empty if none are found."""
    folder = builtin_dir()
    if folder is None:
        return []
    # *.params.yaml next to the mechanisms are node parameter files, not mechanisms.
    return sorted(p.stem for p in folder.glob("*.yaml") if not p.stem.endswith(".params"))


def find_builtin(name: str) -> Optional[Path]:
    """Return the file of built-in mechanism ``name``, or None."""
    folder = builtin_dir()
    if folder is None:
        return None
    path = folder / f"{name}.yaml"
    return path if path.is_file() else None


def searched() -> str:
    """Where the built-ins were looked for, for an error message."""
    prefix = install_prefix(_PACKAGE_DIR)
    own = (prefix / "share" / PACKAGE / SUBDIR) if prefix else _PACKAGE_DIR.parent / SUBDIR
    return f"{own} and the ament index (AMENT_PREFIX_PATH)"
