"""
What the exact linear model (``linear.LinearModel``) answers: modes, poles, FRF, static gain.

Undamped modes: K phi = omega^2 M phi on the free coordinates (the drives held at their
inputs); damped poles: eig A; the frequency response of one drive's input,
G(i w) = C (i w I - A)^-1 B_d + D_d; the static gain G(0) = D - C A^-1 B (module doc of
``linear``). Re-exported by ``linear``: call them as ``linear.modes`` etc.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional, Sequence

import numpy as np

from flexure_sim.engine.mechanism.damping_models import natural_modes

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from flexure_sim.engine.analysis.linear import LinearModel


@dataclass(frozen=True)
class Modes:
    """
    Undamped modes.

    Frequencies (Hz, ascending), shapes (nF, n) M-orthonormal columns on the free coordinates
    ``free``; damped poles (complex, 1/s, by |pole|), their natural frequencies |pole| / 2 pi (Hz)
    and damping ratios -Re/|pole| (1 for a real pole); modal damping ratios phi^T C phi / (2 omega)
    of the undamped modes (exact for the proportional damping B = t_char K, where they are omega
    t_char / 2: a mode above zeta = 1 splits into two real poles, one near -1/t_char).
    """

    frequencies: np.ndarray
    shapes: np.ndarray
    free: np.ndarray
    poles: np.ndarray
    pole_frequencies: np.ndarray
    damping_ratios: np.ndarray
    modal_damping: np.ndarray


def modes(model: LinearModel, mass_matrix: Optional[np.ndarray] = None) -> Modes:
    """
    Return undamped modes and damped poles.

    Undamped modes: the generalised eigenproblem K phi = w^2 M phi, M diagonal (``model.mass``)
    or ``mass_matrix`` (a spatial model's); damped poles: eig A.
    """
    w2, shapes = natural_modes(model.stiffness,
                               model.mass if mass_matrix is None else mass_matrix)
    poles = np.linalg.eigvals(model.A)
    poles = poles[np.lexsort((poles.imag, np.abs(poles)))]
    mag = np.abs(poles)
    zeta = np.where(mag > 0, -poles.real / np.where(mag > 0, mag, 1.0), 1.0)
    omega = np.sqrt(w2)
    modal = np.einsum("ik,ij,jk->k", shapes, model.damping, shapes) / (2.0 * omega)
    return Modes(omega / (2 * np.pi), shapes, model.free, poles, mag / (2 * np.pi), zeta, modal)


def _rows(model: LinearModel, outputs: Optional[Sequence[str]]) -> list:
    return ([model.output_index(o) for o in outputs] if outputs is not None
            else list(range(len(model.output_names))))


def frf(
    model: LinearModel, frequencies: Sequence[float], outputs: Optional[Sequence[str]] = None,
    source: Optional[str] = None,
) -> np.ndarray:
    """
    G(i 2 pi f) = C (i w I - A)^-1 (B_d + s B1_d) + D_d + s D1_d + s^2 D2_d, s = i w.

    For one input d: (n_outputs, n_frequencies). ``source``: the input (a drive's name,
    ``LinearModel.input_index``; None: the only one).
    The first-order system has the engine's block structure x = (z, v, u_1 .. u_m) with z' = v
    and each u_a a lag of its own command, so the solve is done in second-order form: with
    s = i w, u_a = command_a / (1 + tau_a s) for the driven actuator (the others stay 0) and
    v = s z, (s^2 I - s A_vv - A_vz) z = A_vu u + (B_v,d + s B1_v,d) input -- an (n_F x n_F)
    system per frequency instead of (2 n_F + m), with the same exact result. A force drive's
    input has no lag (B_v,d = M_F^-1 e_F, u = 0), nor has a displacement input (its rate and
    acceleration in B1, D1, D2: ``LinearModel``). The frequencies are solved ``FRF_CHUNK`` at
    a time, so the work arrays stay bounded (the result is n_outputs x n_frequencies).
    """
    k = model.input_index(source)
    rows = _rows(model, outputs)
    f = np.asarray(frequencies, dtype=float).ravel()
    out = np.empty((len(rows), len(f)), dtype=complex)
    for start in range(0, len(f), FRF_CHUNK):
        out[:, start:start + FRF_CHUNK] = _frf_chunk(model, f[start:start + FRF_CHUNK], rows, k)
    return out


#: Frequencies per solve of ``frf`` (its (chunk, n_F, n_F) work array: ~10 MB for the stage).
FRF_CHUNK = 4096


def _frf_chunk(model: LinearModel, f: np.ndarray, rows: list, k: int) -> np.ndarray:
    """``frf`` at the frequencies ``f`` (Hz) for the outputs ``rows`` and input column ``k``."""
    s = 2j * np.pi * f
    A, nF = model.A, len(model.free)
    na = A.shape[0] - 2 * nF
    Avz, Avv = A[nF:2 * nF, :nF], A[nF:2 * nF, nF:2 * nF]
    M = (s * s)[:, None, None] * np.eye(nF) - s[:, None, None] * Avv - Avz
    a = model.lags[k] if model.lags else 0
    U = np.zeros((len(s), na), dtype=complex)
    if a >= 0:
        tau = -1.0 / A[2 * nF + a, 2 * nF + a]
        u = 1.0 / (1.0 + tau * s)
        U[:, a] = u
        rhs = u[:, None] * A[nF:2 * nF, 2 * nF + a] + model.B[nF:2 * nF, k]
    else:
        rhs = np.broadcast_to(model.B[nF:2 * nF, k].astype(complex), (len(s), nF))
    if model.B1 is not None and np.any(model.B1[:, k]):
        rhs = rhs + s[:, None] * model.B1[nF:2 * nF, k]
    z = np.linalg.solve(M, rhs[..., None])[..., 0]
    x = np.concatenate([z, s[:, None] * z, U], axis=1)
    G = model.C[rows] @ x.T + model.D[rows][:, [k]]
    if model.D1 is not None:
        assert model.D2 is not None, "linearize gives D1 and D2 together"
        G = G + model.D1[rows][:, [k]] * s + model.D2[rows][:, [k]] * (s * s)
    return G


def gain_matrix(model: LinearModel, outputs: Optional[Sequence[str]] = None) -> np.ndarray:
    """
    G(0) = D - C A^-1 B: every output (rows) against every input (columns, ``input_names``).

    The derivative of the static outputs in each drive's input (the others held).
    """
    rows = _rows(model, outputs)
    return model.D[rows] - model.C[rows] @ np.linalg.solve(model.A, model.B)


def static_gain(model: LinearModel, outputs: Optional[Sequence[str]] = None,
                source: Optional[str] = None) -> np.ndarray:
    """Return one input's column of ``gain_matrix`` (``source``: its name; None: the only one)."""
    return gain_matrix(model, outputs)[:, model.input_index(source)]
