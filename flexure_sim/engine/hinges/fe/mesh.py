"""
Quadratic triangle meshes of a hinge outline, made by gmsh (Python API).

The element size follows the local width of the material, size(x) = 2 y_top(x) / n, so every
cross-section has about n elements across it whatever the shape; refining means doubling n,
which halves every element (the refinement the convergence study of convergence.py needs).
Six-node triangles (``setOrder(2)``) put their edge nodes on the exact arcs, so the outline is
represented to third order and the P2 isoparametric elements of elastic.py converge at their
full rate.

gmsh keeps one global model per process and is not thread-safe: every call holds a lock,
initialises gmsh (not interruptible, so it works outside the main thread), meshes and
finalises. gmsh's initialisation sets SIGPIPE back to its default action (terminate) at the C
level; Python ignores it so that a closed pipe is a BrokenPipeError, and a process killed by
its pipe (a recorder whose reader went away, `flexure-sim hinge | head`) must not follow from
meshing a hinge: ``_keep_sigpipe`` puts Python's setting back. The PyPI wheel needs the
X11/OpenGL client libraries of the system (libGLU, libXcursor, libXft, libXinerama); an import
failure names them.
"""
from __future__ import annotations

import ctypes
import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Iterator

import numpy as np

from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.hinges.fe.shapes import Profile, build_outline

_LOCK = threading.Lock()


class MeshError(FlexureSimError, RuntimeError):
    """gmsh cannot be loaded or did not mesh the outline (says why)."""


def _gmsh():
    """Import gmsh, or MeshError naming what is missing."""
    try:
        import gmsh
    except (ImportError, OSError) as exc:  # the wheel's shared library needs X11/GL clients
        raise MeshError(
            f"gmsh could not be loaded ({exc}); it is a dependency (pip install gmsh) and its "
            "shared library needs the system's libGLU, libXcursor, libXft and libXinerama"
        ) from None
    return gmsh


def _keep_sigpipe(handler) -> None:
    """
    Put back the SIGPIPE action Python had (``handler``) after gmsh reset it to the default.

    ``signal.signal`` only works in the main thread; elsewhere (a sweep's worker thread) the C
    library's ``signal`` sets ignore or default directly (a Python handler is not possible
    there, and ignoring is what Python itself starts with).
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, handler)
        return
    action = 0 if handler == signal.SIG_DFL else 1  # SIG_DFL = 0, SIG_IGN = 1 (C's values)
    libc = ctypes.CDLL(None, use_errno=True)
    libc.signal.restype = ctypes.c_void_p
    libc.signal(int(signal.SIGPIPE), ctypes.c_void_p(action))


@dataclass(frozen=True)
class HingeMesh:
    """
    A six-node triangle mesh of a hinge outline (lengths in units of the reference length).

    ``nodes`` (N, 2); ``triangles`` (M, 6): vertices then the mid-edge nodes of edges 01, 12,
    20 (gmsh's and meshio's order); ``left``, ``right``: node indices on the clamp lines
    x = -l and x = +l; ``n``: the resolution (elements across a section).
    """

    nodes: np.ndarray
    triangles: np.ndarray
    left: np.ndarray
    right: np.ndarray
    n: int


@contextmanager
def gmsh_session(model: str, what: str = "the hinge") -> Iterator[Any]:
    """
    Yield gmsh initialised for one mesh, and finalise it after.

    Under the module's lock, SIGPIPE kept (module docstring), quiet, ``model`` added; gmsh's
    own exceptions become MeshError naming ``what``.
    """
    gmsh = _gmsh()
    with _LOCK:
        sigpipe = signal.getsignal(signal.SIGPIPE)
        gmsh.initialize(interruptible=False)
        _keep_sigpipe(sigpipe)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.model.add(model)
            yield gmsh
        except (MeshError, ValueError):
            raise
        except Exception as exc:
            raise MeshError(f"gmsh failed to mesh {what}: {exc}") from None
        finally:
            gmsh.finalize()


def size_by_section(gmsh: Any, prof: Profile, n: int) -> None:
    """Size elements at 1/n of the local cross-section height (at least 2 neck / n)."""
    for name in ("MeshSizeFromPoints", "MeshSizeFromCurvature", "MeshSizeExtendFromBoundary"):
        gmsh.option.setNumber(f"Mesh.{name}", 0)
    floor = 2.0 * prof.neck / n

    def size(dim, tag, x, y, z, lc):
        return max(float(2.0 * prof.y_top(min(abs(x), prof.half))) / n, floor)

    gmsh.model.mesh.setSizeCallback(size)  # gmsh keeps the callback referenced


def mesh_profile(prof: Profile, n: int) -> HingeMesh:
    """Mesh ``prof`` with about ``n`` quadratic triangles across every cross-section."""
    if n < 2:
        raise ValueError(f"n: at least 2 elements across the neck, got {n}")
    with gmsh_session("hinge") as gmsh:
        groups = build_outline(gmsh, prof)
        size_by_section(gmsh, prof, n)
        gmsh.model.mesh.generate(2)
        gmsh.model.mesh.setOrder(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
        index[tags.astype(np.int64)] = np.arange(len(tags))
        nodes = coords.reshape(-1, 3)[:, :2].copy()
        types, _, elem_nodes = gmsh.model.mesh.getElements(2)
        if list(types) != [9]:
            raise MeshError(f"gmsh returned element types {list(types)}, not six-node "
                            "triangles (type 9)")
        triangles = index[elem_nodes[0].astype(np.int64)].reshape(-1, 6)

        def on(group):
            return index[gmsh.model.mesh.getNodesForPhysicalGroup(1, group)[0]
                         .astype(np.int64)]

        left, right = on(groups["left"]), on(groups["right"])
    return HingeMesh(nodes, triangles, np.sort(left), np.sort(right), n)
