"""
A colcon workspace holding flexure_sim.

Built by real colcon in a Python environment that has no pip copy of flexure_sim, as on a ROS 2
machine where the package only exists in the workspace.

That environment is a mirror of the test's virtual environment made of symbolic links (cheap:
no copies, no downloads), leaving out every file the pip install of flexure_sim put there
(its RECORD: the package, the console scripts, share/flexure_sim, the ament index marker).
Its Python imports rclpy, colcon and pytest from the virtual environment but cannot import
flexure_sim or find its data, so whatever the workspace's programs read comes from the
workspace.
"""
from __future__ import annotations

import csv
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

PACKAGE = "flexure_sim"
ROOT = Path(__file__).resolve().parent.parent
#: Folder of the ros2 command-line tool wheels (scripts/venv.sh installs them from there).
ROS2CLI_DIR = Path(os.environ.get("FLEXURE_ROS2CLI") or ROOT.parent / "shared" / "ros2cli")
#: What a copied source tree leaves out (build products, local runs, virtual environments).
_NOT_SOURCE = shutil.ignore_patterns(".git", ".venv", "runs", "build", "install", "log",
                                     "__pycache__", "*.egg-info", ".pytest_cache")
#: Environment variables of a sourced ROS/colcon environment or virtual environment, which a
#: fresh shell would not have.
_SHELL_STATE = ("PYTHONPATH", "AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH", "COLCON_PREFIX_PATH",
                "VIRTUAL_ENV", "PYTHONHOME", "LD_LIBRARY_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE")


def pip_installed_files(prefix: Path) -> set[Path]:
    """Every file and folder the pip install of flexure_sim put under ``prefix`` (a venv)."""
    found: set[Path] = set()
    for site in prefix.glob("lib/python*/site-packages"):
        for entry in site.iterdir():
            if entry.name.lower().startswith(PACKAGE):
                found.add(entry)
            record = entry / "RECORD"
            if entry.name.lower().startswith(PACKAGE) and record.is_file():
                with open(record, newline="") as f:
                    found.update(Path(os.path.normpath(site / row[0]))
                                 for row in csv.reader(f) if row)
    found.add(prefix / "share" / PACKAGE)
    found.add(prefix / "lib" / PACKAGE)
    found.add(prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE)
    return found


def _mirror(src: Path, dst: Path, leave_out: set[Path], parents: set[Path]) -> None:
    """
    Recreate ``src`` at ``dst`` as symbolic links.

    Descending only into the folders (``parents``) where something is left out.
    """
    dst.mkdir()
    for entry in src.iterdir():
        if entry in leave_out:
            continue
        if entry in parents and entry.is_dir() and not entry.is_symlink():
            _mirror(entry, dst / entry.name, leave_out, parents)
        else:
            (dst / entry.name).symlink_to(entry)


def environment_without_package(venv: Path, dest: Path) -> Path:
    """Mirror the virtual environment ``venv`` at ``dest`` without flexure_sim; its Python."""
    if not (venv / "pyvenv.cfg").is_file():
        raise RuntimeError(f"{venv}: not a virtual environment (run the tests through "
                           "scripts/run_tests.sh or source scripts/venv.sh first)")
    leave_out = pip_installed_files(venv)
    parents = {p for path in leave_out for p in path.parents}
    _mirror(venv, dest, leave_out, parents)
    for folder, _, _ in sorted(os.walk(dest), reverse=True):  # folders emptied by leaving out
        if not os.listdir(folder):
            os.rmdir(folder)
    return dest / "bin" / "python3"


def fresh_shell_env(python: Path, **extra: str) -> dict[str, str]:
    """
    Return the environment of a fresh shell with ``python``'s bin folder first on PATH.

    Nothing of the test's own virtual environment is kept (PATH without it, no PYTHONPATH).
    """
    env = {k: v for k, v in os.environ.items() if k not in _SHELL_STATE}
    own_bin = str(Path(sys.prefix) / "bin")
    path = [p for p in env.get("PATH", "").split(os.pathsep) if p and p != own_bin]
    env["PATH"] = os.pathsep.join([str(python.parent)] + path)
    env.update(PYTHONUNBUFFERED="1", RCUTILS_COLORIZED_OUTPUT="0", PYTHONDONTWRITEBYTECODE="1")
    env.update(extra)
    return env


def sourced(env: dict[str, str], setup: Path) -> dict[str, str]:
    """``env`` after ``source <setup>`` in bash (as a user does with install/setup.bash)."""
    out = subprocess.run(["bash", "-c", 'source "$0" >/dev/null && env -0', str(setup)],
                         env=env, capture_output=True, timeout=120, check=True)
    pairs = (item.split("=", 1) for item in out.stdout.decode().split("\0") if "=" in item)
    return dict(pairs)


@dataclass
class Workspace:
    """
    A built colcon workspace.

    ``root``/src/flexure_sim, ``root``/install, and the Python environment (``python``, prefix
    ``env_prefix``) that built it.
    """

    root: Path
    python: Path
    env_prefix: Path
    log: str

    @property
    def install(self) -> Path:
        return self.root / "install" / PACKAGE

    @property
    def source(self) -> Path:
        return self.root / "src" / PACKAGE

    def shell_env(self, **extra: str) -> dict[str, str]:
        """
        Return a fresh shell that sourced install/setup.bash over the environment's own prefix.

        That prefix is the ROS underlay, without flexure_sim.
        """
        env = fresh_shell_env(self.python, AMENT_PREFIX_PATH=str(self.env_prefix), **extra)
        return sourced(env, self.root / "install" / "setup.bash")

    def colcon(self, *args: str, timeout: float = 300,
               **extra: str) -> subprocess.CompletedProcess:
        """Run ``colcon ARGS`` in the workspace with the environment's Python."""
        colcon = Path(sys.prefix) / "bin" / "colcon"
        env = fresh_shell_env(self.python, AMENT_PREFIX_PATH=str(self.env_prefix), **extra)
        return subprocess.run([str(self.python), str(colcon), *args], cwd=self.root, env=env,
                              capture_output=True, text=True, timeout=timeout)


def build_workspace(root: Path) -> Workspace:
    """Copy the repository to ``root``/src/flexure_sim and ``colcon build`` it there."""
    python = environment_without_package(Path(sys.prefix), root / "env")
    shutil.copytree(ROOT, root / "ws" / "src" / PACKAGE, ignore=_NOT_SOURCE)
    ws = Workspace(root / "ws", python, root / "env", "")
    done = ws.colcon("build", "--event-handlers", "console_direct+")
    ws.log = done.stdout + done.stderr
    if done.returncode != 0:
        raise RuntimeError(f"colcon build failed ({done.returncode}):\n{ws.log[-4000:]}")
    return ws
