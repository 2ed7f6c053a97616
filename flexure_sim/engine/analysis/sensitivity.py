"""
Exact first and second design sensitivities by hyper-dual numbers.

The static equilibrium Q_F(z, p) = 0 at drive input u defines z(p). Seeding parameters p
(``mechanism.parameters.Parameters``: any number of the mechanism file by path) as hyper-dual
numbers -- p_i + e1 and p_j + e2, or p_i + e1 + e2 for one parameter -- and running Newton's method
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
largest hinge stress, engine/hinges/stress.py) and ``first_mode`` (Hz). With several drives (or
outputs) the equilibrium is at one input per drive and ``gain`` means every entry
``gain.<output>.<drive>`` of the static gain matrix at that equilibrium, the tangent
g = c_o . w with w = dz/du_d (what ``simulate --static`` reports at rest, ``linear.gain_matrix``
at any input): w_P = D_d (a displacement drive) and K w_F = dQ_F/dz_P D_d + e_dF (e_d: a force
drive's direction), solved in hyper-dual arithmetic like z by the iteration
w <- w + K^-1 (dQ/dz(z(p), p)[w] + e_d)_F with the real K, whose directional derivative
dQ/dz[w] is the imaginary part / h of the forces at z + i h w (the complex step below, on every
hyper-dual part): real part exact after one iteration, e1 and e2 parts after two, e1e2 after
three. The first natural frequency
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

from typing import Any, Sequence

import numpy as np
import scipy.linalg

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.analysis import linear
from flexure_sim.engine.mechanism.parameters import ParameterError, Parameters, hinge_indices
from flexure_sim.engine.analysis.parametric import forces
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.solver.statics import _applied
from flexure_sim.engine.hinges.stress import hinge_stress

OUTPUTS = ("gain", "compression", "first_mode", "peak_stress")

#: Complex step h (relative to z in m and rad, phi M-normalised): h^2 is below rounding.
COMPLEX_STEP = 1e-30


class Sensitivity:
    """
    Static equilibrium.

    Its tangent stiffness and first mode at drive input u, ready to differentiate outputs by
    hyper-dual evaluation.
    """

    def __init__(self, params: Parameters, u, static_outputs: bool = True):
        self.params = params
        mech = params.mechanism
        if static_outputs and mech.drive is None:
            raise ParameterError(
                f"mechanism {mech.name!r} has no drive: gain, compression and peak_stress "
                "need a drive input (first_mode does not)"
            )
        self.sim = Simulation(mech)
        model = self.sim.model
        try:
            inputs = model.drives.inputs(u) if model.drives else np.zeros(0)
        except ValueError as exc:
            raise ParameterError(f"--input: {exc}") from None
        single = len(inputs) <= 1
        if static_outputs and single and not np.any(inputs):
            raise ParameterError("the drive input must be non-zero (gain = output / input)")
        self.u = (float(inputs[0]) if len(inputs) else 0.0) if single else inputs
        self.applied = _applied(model, inputs)  # the force drives' generalised force
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
        # e1, e2 parts exact after one iteration, the e1e2 part after two
        return implicit_newton(
            z, lambda z: forces(design, self.twistor, self.ia, self.ib, z).Q + self.applied,
            self._solve, self.free, 2)

    def tangent(self, design, z, d: int):
        """
        Return w = dz/du_d (all coordinates) as a HyperDual (module docstring).

        ``d``: the drive's index (``DriveTable.names``); ``z``: the hyper-dual equilibrium.
        """
        model = self.sim.model
        F, N = self.free, len(self.z)
        w0, e = np.zeros(N), np.zeros(N)
        if d in model.drives.displacement:
            w0[model.part.prescribed] = model.part.D[:, list(model.drives.displacement).index(d)]
        else:
            e = model.drives.directions[d]
        w = hd.HyperDual(w0, np.zeros(N), np.zeros(N), np.zeros(N))
        h = COMPLEX_STEP
        for _ in range(3):
            zs = [zp + 1j * h * wp for zp, wp in zip(hd.parts_of(z), hd.parts_of(w))]
            Q = forces(design, self.twistor, self.ia, self.ib, hd.HyperDual(*zs)).Q
            r = [np.broadcast_to(np.imag(np.asarray(x)), (N,))[F] / h for x in hd.parts_of(Q)]
            r[0] = r[0] + e[F]
            for name, dr in zip("abcd", r):
                getattr(w, name)[F] += self._solve(dr)
        return w

    def outputs(self, design, z, which: Sequence[str]) -> dict:
        mech = self.params.mechanism
        out = {}
        model = self.sim.model
        tangents = {}
        for key in which:
            if not key.startswith("gain."):
                continue
            o, d = _gain_pair(model, key)
            if d not in tangents:
                tangents[d] = self.tangent(design, z, d)
            out[key] = (tangents[d] * model.output_matrix[o]).sum()
        if "gain" in which:
            output = mech.output
            if output is None:
                raise ParameterError(f"gain: mechanism {mech.name!r} names no output body")
            i = mech.body_index(output.body)
            axis = np.array(output.axis)
            out["gain"] = (
                (z[3 * i] - self.sim.z0[3 * i]) * axis[0]
                + (z[3 * i + 1] - self.sim.z0[3 * i + 1]) * axis[1]
            ) / self.u
        if "compression" in which:
            # The engine's one definition (engine/solver/compression.py): the drive side's centre
            # of stiffness minus the far side's, along the drive axis. The frames' positions
            # carry the design parameters; the centre's offset from the frame origin is the
            # model's (zero for the diagonal notch and leaf stiffness).
            if mech.compression_hinge is None:
                raise ParameterError(
                    f"compression: mechanism {mech.name!r} names no compression hinge")
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


def implicit_newton(z, residual, solve, free, iterations: int):
    """
    Return z (a HyperDual, changed in place) after Newton steps with the real stiffness.

    z_F <- z_F + K^-1 R_F(z) on every hyper-dual part, K = -dR_F/dz_F at the real solution
    (``solve`` applies K^-1): the implicit function theorem dz/dp = K^-1 dR_F/dp and its
    second-order form (module docstring). Each iteration makes one more order of the parts
    exact; the planar and the spatial sensitivities (``analysis.spatial_sensitivity``) share it.
    """
    for _ in range(iterations):
        step = [solve(np.asarray(p)[free]) for p in hd.parts_of(residual(z))]
        for name, dp in zip("abcd", step):
            part = getattr(z, name)
            part[free] += dp
    return z


def gain_keys(mech) -> list:
    """Every ``gain.<output>.<drive>`` of a mechanism (outputs, then drives, in file order)."""
    return [f"gain.{o.name}.{d.name}" for o in mech.all_outputs for d in mech.drives]


def _gain_pair(model, key: str) -> tuple:
    """(output row, drive index) of ``gain.<output>.<drive>``; ParameterError listing them."""
    for o, oname in enumerate(model.output_names):
        for d, dname in enumerate(model.drives.names):
            if key == f"gain.{oname}.{dname}":
                return o, d
    keys = ", ".join(gain_keys(model.mechanism)) or "none: the mechanism has no drive or output"
    raise ParameterError(f"--of {key!r}: no such gain (gain.<output>.<drive>: {keys})")


def _expand(mech, of: Sequence[str]) -> list:
    """
    Return ``of`` with ``gain`` meaning every gain.<output>.<drive> where it is ambiguous.

    ``gain`` stays output / input for one drive and the single ``output:``; with several
    drives or named outputs it is the gain matrix's entries. Unknown names: ParameterError.
    """
    out = []
    for o in of:
        if o == "gain" and mech.drives and mech.all_outputs and not (
                len(mech.drives) == 1 and mech.output is not None):
            out += [k for k in gain_keys(mech) if k not in out]
        elif o in OUTPUTS or o.startswith("gain."):
            out.append(o)
        else:
            raise ParameterError(f"--of {o!r}: outputs are {', '.join(OUTPUTS)} and "
                                 "gain.<output>.<drive>")
    return out


def default_input(mech):
    """Return the default drive input: the top of each drive's stroke (a number for one drive)."""
    tops = [d.stroke[1] for d in mech.drives]
    return tops[0] if len(tops) == 1 else 0.0 if not tops else tops


def check_wrt(params, wrt: Sequence[str]) -> None:
    """Raise ParameterError unless each path of ``wrt`` is a parameter, each number named once."""
    seen: dict[Any, str] = {}
    for p in wrt:
        params.check(p)
        steps = params.resolve(p)[0]
        if steps in seen:
            raise ParameterError(f"--wrt: {seen[steps]} and {p} name the same number")
        seen[steps] = p


def sensitivities(
    params: Parameters, wrt: Sequence[str], of: Sequence[str] = OUTPUTS, u=None,
    hessian: bool = False,
) -> dict:
    """
    Values.

    Gradients and second derivatives of the outputs ``of`` in the parameters ``wrt`` at drive input
    u (default: the top of each drive's stroke; with several drives one value per drive or a
    {name: value} mapping, ``Model.drive_inputs``). ``gain`` on a mechanism with several drives
    or named outputs means every ``gain.<output>.<drive>`` (``_expand``), which may also be asked
    for one by one.

    Returns {"input", "values": {out: v}, "gradient": {out: {p: d}}, "second": {out:
    {"p|q": d}}}: with one parameter per evaluation d2/dp2 (seeds p + e1 + e2); with exactly
    two parameters, or with ``hessian``, the mixed d2/dp dq of every pair p before q in ``wrt``,
    each from one evaluation (seeds p + e1, q + e2). With ``hessian`` also {"hessian": {out:
    H}}: the full Hessian, H[i][j] = d2 out / d wrt[i] d wrt[j] (symmetric, one evaluation per
    entry on and above the diagonal).
    """
    mech = params.mechanism
    if "gain" in of and mech.output is None and not (mech.drives and mech.all_outputs):
        raise ParameterError(f"gain: mechanism {mech.name!r} names no output body")
    of = _expand(mech, of)
    check_wrt(params, wrt)
    if u is None:
        u = default_input(mech)
    if "compression" in of and mech.compression_hinge is None:
        raise ParameterError(f"compression: mechanism {mech.name!r} names no compression hinge")
    sens = Sensitivity(params, u, any(o != "first_mode" for o in of))
    model = sens.sim.model
    loaded = [o for o in of if o in ("compression", "peak_stress")]
    if loaded and len(mech.drives) > 1 and not np.any(sens.u):
        raise ParameterError(f"{', '.join(loaded)}: every drive input is 0; give a loaded "
                             "equilibrium with --input")
    for o in of:
        if o.startswith("gain."):
            _gain_pair(model, o)
    base = params.design()
    res = sens.outputs(base, hd.HyperDual(sens.z), of)
    values = {k: float(hd.real(res[k])) for k in of}
    gradient: dict[str, dict[str, float]] = {o: {} for o in of}
    second: dict[str, dict[str, float]] = {o: {} for o in of}
    for p in wrt:
        design = params.design({p: hd.HyperDual(params.value(p), 1.0, 1.0, 0.0)})
        res = sens.outputs(design, sens.equilibrium(design), of)
        for o, v in res.items():
            gradient[o][p] = float(v.b)
            second[o][f"{p}|{p}"] = float(v.d)
    pairs = [(p, q) for i, p in enumerate(wrt) for q in wrt[i + 1:]]
    for p, q in pairs if hessian or len(wrt) == 2 else ():
        design = params.design(
            {
                p: hd.HyperDual(params.value(p), 1.0, 0.0, 0.0),
                q: hd.HyperDual(params.value(q), 0.0, 1.0, 0.0),
            }
        )
        for o, v in sens.outputs(design, sens.equilibrium(design), of).items():
            second[o][f"{p}|{q}"] = float(v.d)
    u0 = (dict(zip(model.drives.names, sens.u.tolist())) if isinstance(sens.u, np.ndarray)
          else sens.u)
    result = {"input": u0, "values": values, "gradient": gradient, "second": second}
    if hessian:
        result["hessian"] = {o: [[second[o][f"{p}|{q}" if i <= j else f"{q}|{p}"]
                                  for j, q in enumerate(wrt)] for i, p in enumerate(wrt)]
                             for o in of}
    return result
