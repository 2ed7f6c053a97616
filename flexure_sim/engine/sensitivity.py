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
f = sqrt(lambda) / 2 pi comes from eigenvalue sensitivity of (K - lambda M) phi = 0,
phi^T M phi = 1 (K, M on the free coordinates; K = -dQ_F/dz_F total in p, since z moves with
p), with r_p = (K_p - lambda_p M - lambda M_p) phi:

    lambda_p  = phi^T (K_p - lambda M_p) phi,
    lambda_pq = phi^T (K_pq - lambda_p M_q - lambda_q M_p - lambda M_pq) phi
                + phi_p^T r_q + phi_q^T r_p,

the second form by differentiating the first once more and multiplying by phi^T. The
eigenvector derivative phi_p solves (K - lambda M) phi_p = -r_p; only its part M-orthogonal
to phi matters (phi^T r_q = 0), so it comes from the bordered system with phi^T M phi_p = 0
instead of Nelson's normalisation (R. B. Nelson, "Simplified calculation of eigenvector
derivatives", AIAA J. 14 (1976) 1201). K_pq phi is a third derivative of the forces
(Q_zpq[phi] with the chain through z(p, q)): one force evaluation at the hyper-dual z(p, q)
with a complex step i h phi added to its real part gives all of K phi, K_p phi, K_q phi and
K_pq phi as the imaginary parts / h of the four hyper-dual parts of Q (complex step, Lyness
and Moler 1967; Martins, Sturdza and Alonso, ACM TOMS 29 (2003) 245: there is no
subtraction, so with h = 1e-30 the step error h^2 is far below rounding -- exact in double
precision, like the hyper-dual parts).
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

#: Complex step h (relative to z in m and rad, phi M-normalised): h^2 is below rounding.
COMPLEX_STEP = 1e-30


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
        mass = lay.mass[lay.free]
        w2, shapes = scipy.linalg.eigh(0.5 * (K + K.T), np.diag(mass))
        self.lam, self.phi = w2[0], shapes[:, 0]
        n = len(self.free)  # Nelson's bordered matrix [[K - lambda M, M phi], [phi^T M, 0]]
        bordered = np.zeros((n + 1, n + 1))
        bordered[:n, :n] = 0.5 * (K + K.T) - self.lam * np.diag(mass)
        bordered[:n, n] = bordered[n, :n] = mass * self.phi
        self.bordered = scipy.linalg.lu_factor(bordered)
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
        if "first_mode" in which:
            out["first_mode"] = self._first_mode(design, z)
        return out

    def _first_mode(self, design, z):
        """
        First natural frequency (Hz) as a HyperDual: its parts d/dp, d/dq, d2/dp dq.

        From the hyper-dual design and equilibrium z(p, q) (module docstring).
        """
        F, n = self.free, len(self.free)
        phi = np.zeros(len(self.z))
        phi[F] = self.phi
        za, zb, zc, zd = hd.parts_of(z)
        Q = forces(design, self.twistor, self.ia, self.ib,
                   hd.HyperDual(za + 1j * COMPLEX_STEP * phi, zb, zc, zd)).Q
        # -Im(Q parts) / h = (K phi, K_p phi, K_q phi, K_pq phi) on the free coordinates.
        _, kp, kq, kpq = (-np.imag(np.asarray(x))[..., F] / COMPLEX_STEP for x in hd.parts_of(Q))
        m, mp, mq, mpq = (np.broadcast_to(np.asarray(x)[..., F], (n,))
                          for x in hd.parts_of(design.mass))
        lam, ph = self.lam, self.phi
        lam_p = ph @ kp - lam * ph @ (mp * ph)
        lam_q = ph @ kq - lam * ph @ (mq * ph)
        r_p = kp - (lam_p * m + lam * mp) * ph
        r_q = kq - (lam_q * m + lam * mq) * ph
        rhs = np.zeros((n + 1, 2))
        rhs[:n, 0], rhs[:n, 1] = -r_p, -r_q
        phi_pq = scipy.linalg.lu_solve(self.bordered, rhs)[:n]
        lam_pq = (ph @ kpq - ph @ ((lam_p * mq + lam_q * mp + lam * mpq) * ph)
                  + phi_pq[:, 0] @ r_q + phi_pq[:, 1] @ r_p)
        return np.sqrt(hd.HyperDual(lam, lam_p, lam_q, lam_pq)) / (2.0 * np.pi)

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
    sens = Sensitivity(params, u, any(o != "first_mode" for o in of))
    base = params.design()
    values = {
        k: float(hd.real(v)) for k, v in sens.outputs(base, hd.HyperDual(sens.z), of).items()
    }
    gradient = {o: {} for o in of}
    second = {o: {} for o in of}
    for p in wrt:
        design = params.design({p: hd.HyperDual(params.value(p), 1.0, 1.0, 0.0)})
        res = sens.outputs(design, sens.equilibrium(design), of)
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
        for o, v in sens.outputs(design, sens.equilibrium(design), of).items():
            second[o][f"{p}|{q}"] = float(v.d)
    return {"input": u, "values": values, "gradient": gradient, "second": second}
