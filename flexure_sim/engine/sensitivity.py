"""
Exact first and second design sensitivities by hyper-dual numbers.

The static equilibrium Q_F(z, p) = 0 at drive input u defines z(p). Seeding parameters p
(``parametric.Parameters``: any number of the mechanism file by path) as hyper-dual numbers
-- p_i + e1 and p_j + e2, or p_i + e1 + e2 for one parameter -- and running Newton's method
*in hyper-dual arithmetic* with the real tangent stiffness K = -dQ_F/dz_F,

    z <- z + K^-1 Q_F(z, p),

converges in the derivative parts in two iterations from the real solution: the e1, e2
parts become dz/dp_i = K^-1 dQ_F/dp_i (the implicit function theorem) and then the e1e2
part d2z/dp_i dp_j (its second-order form, Q_zz[z_i, z_j] + Q_zp_i z_j + Q_zp_j z_i +
Q_p_ip_j + Q_z z_ij = 0). The outputs are evaluated from this hyper-dual z and parameters,
so their parts are their exact first and mixed second derivatives. This is the construction
of ``reference/hyper-dual-twist-of-a-joint.md``: there a joint's twist is carried as
(omega + e omega_dot)(s + e s_dot) so the e part is the exact derivative of the real part;
here every quantity of the force chain (stiffness from h, frame positions, the relative
displacement r and the twistor built from it, the wrench) is carried the same way, with two
independent infinitesimals e1, e2 and their product for the second derivative.

Outputs: ``gain`` (output displacement / u), ``compression`` (m), ``peak_stress`` (Pa, the
largest hinge stress, engine/stress.py) and ``first_mode`` (Hz). The first natural frequency
uses eigenvalue sensitivity, d lambda/dp = phi^T (dK/dp - lambda dM/dp) phi with phi
M-normalised, where dK/dp phi (total: z moves with p) is the e1e2 part of one hyper-dual
force evaluation at z + e1 phi + e2 dz/dp with p + e2; its second derivative would need
third derivatives of the forces and is not computed (None).
"""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
import scipy.linalg

from . import hyperdual as hd
from . import linear
from .design import ParameterError, Parameters, hinge_indices
from .parametric import forces
from .solver import Simulation
from .stress import hinge_stress

OUTPUTS = ("gain", "compression", "first_mode", "peak_stress")


class Sensitivity:
    """
    Static equilibrium.

    Its tangent stiffness and first mode at drive input u, ready to differentiate outputs by
    hyper-dual evaluation.
    """

    def __init__(self, params: Parameters, u: float, static_outputs: bool = True):
        self.params = params
        mech = params.mechanism
        if static_outputs and mech.drive is None:
            raise ParameterError(
                f"mechanism {mech.name!r} has no drive: gain, compression and peak_stress "
                "need a drive input (first_mode does not)"
            )
        if static_outputs and u == 0:
            raise ParameterError("the drive input must be non-zero (gain = output / input)")
        self.u = float(u)
        self.sim = Simulation(mech)
        self.z = self.sim.static(self.u).z
        lay = linear.layout(self.sim)
        self.free = lay.free
        dQz, _ = linear.tangent_at(self.sim, self.z)
        K = -dQz[np.ix_(lay.free, lay.free)]
        self.lu = scipy.linalg.lu_factor(K)
        w2, shapes = scipy.linalg.eigh(0.5 * (K + K.T), np.diag(lay.mass[lay.free]))
        self.lam, self.phi = w2[0], shapes[:, 0]
        self.ia, self.ib = hinge_indices(mech)
        self.twistor = params.twistor

    def _solve(self, x: np.ndarray) -> np.ndarray:
        return scipy.linalg.lu_solve(self.lu, x.T).T

    def equilibrium(self, design):
        """Hyper-dual z(p) by Newton with the real stiffness (module docstring)."""
        z = hd.HyperDual(
            self.z.copy(), np.zeros_like(self.z), np.zeros_like(self.z), np.zeros_like(self.z)
        )
        F = self.free
        for _ in range(2):  # e1, e2 parts exact after one, the e1e2 part after two
            Q = forces(design, self.twistor, self.ia, self.ib, z).Q
            step = [self._solve(np.asarray(p)[F]) for p in hd.parts_of(Q)]
            for name, dp in zip("abcd", step):
                part = getattr(z, name)
                part[F] += dp
        return z

    def outputs(self, design, z, which: Sequence[str]) -> dict:
        mech = self.params.mechanism
        out = {}
        if "gain" in which:
            i = mech.body_index(mech.output.body)
            axis = np.array(mech.output.axis)
            out["gain"] = (
                (z[3 * i] - self.sim.z0[3 * i]) * axis[0]
                + (z[3 * i + 1] - self.sim.z0[3 * i + 1]) * axis[1]
            ) / self.u
        if "compression" in which:
            # The engine's one definition (engine/compression.py): the drive side's centre of
            # stiffness minus the far side's, along the drive axis. The frames' positions
            # carry the design parameters; the centre's offset from the frame origin is the
            # model's (zero for the diagonal notch and leaf stiffness).
            k = mech.hinge_index(mech.compression_hinge)
            h = mech.hinges[k]
            frames = {mech.body_index(h.b.body): (h.b, design.cb[k]),
                      mech.body_index(h.a.body): (h.a, design.ca[k])}
            (i_drive, c_drive), (i_far, c_far), axis = self.sim.model.compression

            def moved(i, c):
                frame, at = frames[i]
                off = (c[0] - frame.position[0], c[1] - frame.position[1])
                return self._frame_move(mech.bodies[i].name, (at[0] + off[0], at[1] + off[1]), z)

            (dx, dy), (fx, fy) = moved(i_drive, c_drive), moved(i_far, c_far)
            out["compression"] = (dx - fx) * axis[0] + (dy - fy) * axis[1]
        if "peak_stress" in which:
            wrench = forces(design, self.twistor, self.ia, self.ib, z).wrench
            best = None
            for k, g in enumerate(design.geometry):
                s = hinge_stress(wrench[..., k, :], g)
                if s is not None and (best is None or hd.real(s) > hd.real(best)):
                    best = s
            if best is None:
                raise ParameterError("peak_stress: no hinge has a notch or leaf geometry")
            out["peak_stress"] = best
        return out

    def _frame_move(self, body: str, c, z):
        i = self.params.mechanism.body_index(body)
        th, th0 = z[3 * i + 2], self.sim.z0[3 * i + 2]
        dx = (
            z[3 * i]
            - self.sim.z0[3 * i]
            + np.cos(th) * c[0]
            - np.sin(th) * c[1]
            - (np.cos(th0) * c[0] - np.sin(th0) * c[1])
        )
        dy = (
            z[3 * i + 1]
            - self.sim.z0[3 * i + 1]
            + np.sin(th) * c[0]
            + np.cos(th) * c[1]
            - (np.sin(th0) * c[0] + np.cos(th0) * c[1])
        )
        return dx, dy

    def first_mode_derivative(self, path: str, z_p: Optional[np.ndarray] = None) -> float:
        """Return d f_1 / dp (Hz per unit of p) by eigenvalue sensitivity; z_p = dz/dp if known."""
        v = self.params.check(path)
        design = self.params.design({path: hd.HyperDual(v, 0.0, 1.0, 0.0)})
        if z_p is None:
            z_p = self.equilibrium(design).c
        F = self.free
        phi = np.zeros_like(self.z)
        phi[F] = self.phi
        zz = hd.HyperDual(self.z, phi, z_p, 0.0)
        Q = forces(design, self.twistor, self.ia, self.ib, zz).Q
        dK_phi = -np.asarray(hd.parts_of(Q)[3])[F]
        mass = design.mass
        dM = (
            np.asarray(hd.parts_of(mass)[2])[F]
            if isinstance(mass, hd.HyperDual)
            else np.zeros(len(F))
        )
        dlam = self.phi @ dK_phi - self.lam * self.phi @ (dM * self.phi)
        return float(dlam / (2.0 * np.sqrt(self.lam)) / (2.0 * np.pi))

    def first_mode(self) -> float:
        return float(np.sqrt(self.lam) / (2.0 * np.pi))


def sensitivities(
    params: Parameters, wrt: Sequence[str], of: Sequence[str] = OUTPUTS, u: Optional[float] = None
) -> dict:
    """
    Values.

    Gradients and second derivatives of the outputs ``of`` in the parameters ``wrt`` at drive input
    u (default: the top of the drive's stroke).

    Returns {"input", "values": {out: v}, "gradient": {out: {p: d}}, "second": {out:
    {"p|q": d}}}: with one parameter per evaluation d2/dp2 (seeds p + e1 + e2); with exactly
    two parameters also the mixed d2/dp dq (seeds p + e1, q + e2).
    """
    unknown = [o for o in of if o not in OUTPUTS]
    if unknown:
        raise ParameterError(f"--of {unknown[0]!r}: outputs are {', '.join(OUTPUTS)}")
    for p in wrt:
        params.check(p)
    mech = params.mechanism
    if u is None:
        u = mech.drive.stroke[1] if mech.drive else 0.0
    if "gain" in of and mech.output is None:
        raise ParameterError(f"gain: mechanism {mech.name!r} names no output body")
    if "compression" in of and mech.compression_hinge is None:
        raise ParameterError(f"compression: mechanism {mech.name!r} names no compression hinge")
    static = [o for o in of if o != "first_mode"]
    sens = Sensitivity(params, u, bool(static))
    base = params.design()
    values = {
        k: float(hd.real(v)) for k, v in sens.outputs(base, hd.HyperDual(sens.z), static).items()
    }
    gradient = {o: {} for o in of}
    second = {o: {} for o in of}
    z_p = {}
    for p in wrt:
        design = params.design({p: hd.HyperDual(params.value(p), 1.0, 1.0, 0.0)})
        z = sens.equilibrium(design)
        z_p[p] = np.asarray(z.b)
        res = sens.outputs(design, z, static)
        for o, v in res.items():
            gradient[o][p] = float(v.b)
            second[o][f"{p}|{p}"] = float(v.d)
    if len(wrt) == 2:
        p, q = wrt
        design = params.design(
            {
                p: hd.HyperDual(params.value(p), 1.0, 0.0, 0.0),
                q: hd.HyperDual(params.value(q), 0.0, 1.0, 0.0),
            }
        )
        for o, v in sens.outputs(design, sens.equilibrium(design), static).items():
            second[o][f"{p}|{q}"] = float(v.d)
    if "first_mode" in of:
        values["first_mode"] = sens.first_mode()
        for p in wrt:
            gradient["first_mode"][p] = sens.first_mode_derivative(p, z_p[p])
            second["first_mode"] = None
    return {"input": u, "values": values, "gradient": gradient, "second": second}
