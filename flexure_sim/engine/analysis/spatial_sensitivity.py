"""
Exact design sensitivities in 3-D: static gains and the first mode, by hyper-dual numbers.

The planar sensitivities' construction (``analysis.sensitivity``) on the spatial engine. A
parameter of the hinges' stiffness (``stiffness_models.<m>.<key>``, ``hinges.<h>.stiffness.
<key>``: a notch's h or plate thickness t, a leaf's thickness, a wire's diameter, E, nu) is
seeded as p + e1 in the parsed document; the spatial loader builds the mechanism from it
(``spatial_loader.spatial_from_dict``: a 3-D file, or a planar file opened in 3-D), the 6x6
stiffness formulas (``hinges.spatial_stiffness``) carry the derivative part into each hinge's
W = dU/dc matrix, and the spatial force chain ``spatial_chain.terms`` -- the formula the
stepping kernel compiles -- is evaluated on hyper-dual scalars. Then, with K = -dQ_F/dz_F at
the real solution:

- equilibrium: z_F <- z_F + K^-1 Q_F(z, p) (``sensitivity.implicit_newton``, one definition):
  the e1 part becomes dz/dp = K^-1 dQ_F/dp, the implicit function theorem; ``gain`` of one
  drive and one output is c . (z - z0) / u (the planar definition, a secant at input u);
- gain matrix entries ``gain.<output>.<drive>``: the tangent w = dz/du_d at the equilibrium
  solves R(w) = (dQ/dz w + dQ/du_d)_F = 0, w_P = D_d (a displacement drive) or a force
  drive's command seeded. Carrying w in the e2 part, Z = z + z_p e1 + w e2 + w_p e1e2 with
  the drive's force command f_d + e2, the e1e2 part of Q(Z, p + e1) is the total derivative
  dR/dp = Q_zz[z_p, w] + Q_zp w + Q_fz z_p + Q_z w_p, so one Newton step on the e1e2 part
  gives w_p = K^-1 (e1e2 part)_F exactly, and dg/dp = c_o . w_p;
- ``first_mode`` (Hz) at rest (every drive input 0), where z = z0 for every design and
  dz/dtheta = I: with the undamped mode K phi = lambda M phi, phi^T M phi = 1,
  lambda_p = phi^T (K_p - lambda M_p) phi (Nelson's eigenvalue derivative, as the planar
  ``Sensitivity._first_mode``), K_p phi = -(e1e2 part of Q(z0 + e2 phi, p + e1))_F and M_p
  from the bodies' inertia (a planar file opened in 3-D takes its plate thickness, and so
  its in-plane axes' inertia, from its hinges' width: ``mechanism.planar_in_space``);
  ``out_of_plane_mode`` likewise for the lowest mode whose kinetic energy is mostly (> 1/2)
  in the out-of-plane coordinates z, rx, ry (``spatial_linear.out_of_plane_shares``): a
  planar stage's lowest mode its controller does not see.

First derivatives only (e2 carries w or phi). Body masses, inertias, hinge frames and damping
are not seeded in 3-D (their derivative parts would have to reach the model's constants).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np
import scipy.linalg

from flexure_sim.engine.analysis.sensitivity import _gain_pair, default_input, gain_keys
from flexure_sim.engine.analysis.sensitivity import check_wrt, implicit_newton
from flexure_sim.engine.analysis.spatial_linear import mass_matrix
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.kinematics import scalar
from flexure_sim.engine.mechanism.doc_paths import apply
from flexure_sim.engine.mechanism.loader import load_document
from flexure_sim.engine.mechanism.parameters import ParameterError, Parameters
from flexure_sim.engine.mechanism.spatial_loader import spatial_from_dict
from flexure_sim.engine.solver import spatial_chain as chain
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.engine.solver.spatial_statics import static

OUTPUTS = ("gain", "first_mode", "out_of_plane_mode")
#: Two lowest eigenvalues closer than this (relative) have no derivative of the first one.
REPEATED = 1e-6


class SpatialParameters(Parameters):
    """A mechanism file's numbers by path (``Parameters``), built in 3-D."""

    #: The mechanism built in 3-D (a ``spatial_parts.Mechanism``).
    mechanism: Any

    def __init__(self, name_or_path: str | Path, data: Optional[dict] = None):
        """From a built-in name or YAML path: a ``space: 3d`` file, or a planar one in 3-D."""
        source = str(name_or_path)
        if data is None:
            data, source = load_document(name_or_path)
        self.path = Path(source)
        self.data = data
        self.mechanism = spatial_from_dict(data, source=source)

    def check(self, path: str) -> float:
        """Value of a stiffness parameter; ParameterError naming the problem for any other."""
        keys = path.split(".")
        stiffness = (keys[0] == "stiffness_models" and len(keys) >= 3) or (
            keys[0] == "hinges" and len(keys) >= 4 and keys[2] == "stiffness")
        v = self.value(path)
        if not stiffness or keys[-1] in ("model", "resolution", "sigma_y"):
            raise ParameterError(
                f"{path}: in 3-D the sensitivities vary the hinges' stiffness parameters "
                "(stiffness_models.<model>.<key>, hinges.<hinge>.stiffness.<key>); body masses, "
                "hinge frames and damping are not design parameters in 3-D")
        return v

    def spatial(self, overrides: dict[str, Any]):
        """Return the spatial mechanism with the numbers at the given paths replaced."""
        for path in overrides:
            self.check(path)
        doc = apply(self.data, [self.resolve(path)[:2] + (value,)
                                for path, value in overrides.items()])
        return spatial_from_dict(doc, source=str(self.path))


def _objects(x) -> np.ndarray:
    """Return a float or HyperDual array as an object array of scalars (floats where exact)."""
    parts = hd.parts_of(hd.asarray(x))
    shape = np.broadcast_shapes(*(p.shape for p in parts))
    a, b, c, d = (np.broadcast_to(p, shape) for p in parts)
    out = np.empty(shape, dtype=object)
    for idx in np.ndindex(shape):
        out[idx] = (float(a[idx]) if b[idx] == 0 and c[idx] == 0 and d[idx] == 0
                    else hd.HyperDual(a[idx], b[idx], c[idx], d[idx]))
    return out


class SpatialSensitivity:
    """A spatial mechanism's equilibrium at drive input u, ready for hyper-dual evaluation."""

    def __init__(self, params: SpatialParameters, u):
        self.params = params
        self.model = model = SpatialModel(params.mechanism)
        self.inputs = model.drive_inputs(u) if model.drives else np.zeros(0)
        self.command = model.actuator_command(self.inputs) if model.drives else np.zeros(0)
        self.z = static(model, self.inputs).z
        self.free = model.part.free
        self.lu = scipy.linalg.lu_factor(self._stiffness(self.z, self.command))
        self.solve = lambda x: scipy.linalg.lu_solve(self.lu, x)
        self._modes: dict[str, tuple] = {}

    def _stiffness(self, z: np.ndarray, command: np.ndarray) -> np.ndarray:
        """Return K = -dQ_F/dz_F at z (the compiled complex step of the same chain)."""
        F, N = self.free, self.model.n_coordinates
        Zx = np.zeros((N, len(F)))
        Zx[F, np.arange(len(F))] = 1.0
        dQ = self.model.derivatives(z, np.zeros(N), command, Zx, np.zeros_like(Zx))[0]
        return -dQ[F]

    def constants(self, mechanism) -> tuple:
        """Return the model's constants with each hinge's W from ``mechanism`` (hyper-dual)."""
        q0, inertia, geometry, *forces = self.model.constants
        W = _objects(hd.asarray([h.law.metric() for h in mechanism.hinges]))
        return (q0, inertia, geometry[:9] + (W,) + geometry[10:], *forces)

    def forces(self, constants, z: hd.HyperDual, command) -> hd.HyperDual:
        """Return Q(z, p) from ``spatial_chain.terms`` on hyper-dual scalars, at rest (w = 0)."""
        N, nh = self.model.n_coordinates, len(self.model.mechanism.hinges)
        Q = scalar.zeros(N)
        chain.terms(_objects(z), np.zeros(N), command, self.model.first_force, constants, Q,
                    scalar.zeros(N), scalar.zeros((nh, 6)), scalar.zeros((nh, 6)),
                    scalar.zeros((nh, 3)), False)
        return hd.from_objects(Q)

    def equilibrium(self, constants) -> hd.HyperDual:
        """Return z(p) with its e1 part dz/dp (module docstring)."""
        z = hd.HyperDual(self.z.copy(), np.zeros_like(self.z), np.zeros_like(self.z),
                         np.zeros_like(self.z))
        return implicit_newton(z, lambda z: self.forces(constants, z, self.command),
                               self.solve, self.free, 1)

    def tangent(self, constants, z: hd.HyperDual, d: int) -> tuple[np.ndarray, np.ndarray]:
        """Return (w, dw/dp): dz/du_d at the equilibrium and its parameter derivative."""
        model, F = self.model, self.free
        N = model.n_coordinates
        w = np.zeros(N)
        command = self.command.astype(object)
        if d in model.displacement_index:
            P = model.part.prescribed
            w[P] = model.part.D[:, list(model.displacement_index).index(d)]
        else:
            k = model.first_force + list(model.force_index).index(d)
            command[k] = hd.HyperDual(self.command[k], 0.0, 1.0, 0.0)
        Zx = w[:, None].copy()
        Cx = np.zeros((len(self.command), 1))
        if d not in model.displacement_index:
            Cx[k, 0] = 1.0
        dQ = model.derivatives(self.z, np.zeros(N), self.command, Zx, np.zeros_like(Zx), Cx)[0]
        w[F] = self.solve(dQ[F, 0])
        Z = hd.HyperDual(z.a.copy(), z.b.copy(), w.copy(), np.zeros(N))
        Z = implicit_newton(Z, lambda Z: self.forces(constants, Z, command), self.solve, F, 1)
        return w, Z.d

    def _mass_derivative(self, mechanism) -> np.ndarray:
        """Return dM/dp on the free coordinates (the inertia tensors' e1 parts)."""
        N = self.model.n_coordinates
        Mp = np.zeros((N, N))
        for i, body in enumerate(mechanism.bodies):
            Mp[6 * i + 3:6 * i + 6, 6 * i + 3:6 * i + 6] = np.broadcast_to(
                hd.parts_of(hd.asarray(body.inertia))[1], (3, 3))
        return Mp[np.ix_(self.free, self.free)]

    def mode(self, mechanism, constants, which: str) -> tuple[float, float]:
        """Return (f, df/dp) of ``first_mode`` or ``out_of_plane_mode`` at rest (module doc)."""
        model, F = self.model, self.free
        if which not in self._modes:
            K = self._stiffness(model.z0, np.zeros_like(self.command))
            M = mass_matrix(model)
            lam, shapes = scipy.linalg.eigh(0.5 * (K + K.T), M)
            k = 0
            if which == "out_of_plane_mode":
                out = np.isin(F % 6, (2, 3, 4))
                shares = np.einsum("ik,ik->k", shapes[out], (M @ shapes)[out])
                if not np.any(shares > 0.5):
                    raise ParameterError(f"out_of_plane_mode: mechanism "
                                         f"{model.mechanism.name!r} has no out-of-plane mode")
                k = int(np.argmax(shares > 0.5))
            near = np.abs(np.delete(lam, k) - lam[k]) < REPEATED * abs(lam[k])
            if np.any(near):
                raise ParameterError(
                    f"{which}: mechanism {model.mechanism.name!r} has two modes at "
                    f"{np.sqrt(lam[k]) / (2 * np.pi):.6g} Hz: a repeated eigenvalue has no "
                    f"derivative (leave {which} out of --of)")
            self._modes[which] = (lam[k], shapes[:, k])
        lam, phi = self._modes[which]
        zd = np.zeros(model.n_coordinates)
        zd[F] = phi
        N = model.n_coordinates
        Z = hd.HyperDual(model.z0.copy(), np.zeros(N), zd, np.zeros(N))
        k_p = -np.asarray(self.forces(constants, Z, np.zeros_like(self.command)).d)[F]
        m_p = self._mass_derivative(mechanism)
        f = np.sqrt(hd.HyperDual(lam, phi @ k_p - lam * phi @ (m_p @ phi))) / (2.0 * np.pi)
        return float(f.a), float(f.b)


def expand(mech, of: Sequence[str]) -> list:
    """Return ``of`` with ``gain`` as the planar ``sensitivity._expand`` means it; check names."""
    out: list = []
    for o in of:
        if o == "gain" and not (len(mech.drives) == 1 and len(mech.all_outputs) == 1):
            out += [k for k in gain_keys(mech) if k not in out]
        elif o in OUTPUTS or o.startswith("gain."):
            out.append(o)
        else:
            raise ParameterError(f"--of {o!r}: outputs in 3-D are {', '.join(OUTPUTS)} and "
                                 "gain.<output>.<drive>")
    return out


def sensitivities(params: SpatialParameters, wrt: Sequence[str], of: Sequence[str] = OUTPUTS,
                  u=None) -> dict:
    """
    Return {"input", "values": {out: v}, "gradient": {out: {p: d}}} in 3-D (module docstring).

    As the planar ``sensitivity.sensitivities`` (u: default the top of each drive's stroke)
    without second derivatives.
    """
    mech = params.mechanism
    if any(o.startswith("gain") for o in of) and not (mech.drives and mech.all_outputs):
        raise ParameterError(f"gain: mechanism {mech.name!r} needs a drive and an output")
    of = expand(mech, of)
    check_wrt(params, wrt)
    if u is None:
        u = default_input(mech)
    try:
        sens = SpatialSensitivity(params, u)
    except ValueError as exc:
        raise ParameterError(f"--input: {exc}") from None
    model = sens.model
    pairs = {o: _gain_pair(model, o) for o in of if o.startswith("gain.")}
    if "gain" in of and not np.any(sens.inputs):
        raise ParameterError("the drive input must be non-zero (gain = output / input)")
    values: dict[str, float] = {}
    gradient: dict[str, dict[str, float]] = {o: {} for o in of}
    for p in [None, *wrt]:
        seeds = {} if p is None else {p: hd.HyperDual(params.value(p), 1.0, 0.0, 0.0)}
        design = params.spatial(seeds) if seeds else mech
        constants = sens.constants(design)
        z = sens.equilibrium(constants)
        tangents: dict[int, tuple] = {}
        for o in of:
            if o == "gain":
                c, u0 = model.output_matrix[0], float(sens.inputs[0])
                v, dv = c @ (z.a - model.z0) / u0, c @ z.b / u0
            elif o in ("first_mode", "out_of_plane_mode"):
                v, dv = sens.mode(design, constants, o)
            else:
                row, d = pairs[o]
                if d not in tangents:
                    tangents[d] = sens.tangent(constants, z, d)
                w, wp = tangents[d]
                v, dv = model.output_matrix[row] @ w, model.output_matrix[row] @ wp
            if p is None:
                values[o] = float(v)
            else:
                gradient[o][p] = float(dv)
    inputs = (float(sens.inputs[0]) if len(sens.inputs) == 1
              else dict(zip(model.drive_names, sens.inputs.tolist())))
    return {"input": inputs, "values": values, "gradient": gradient}
