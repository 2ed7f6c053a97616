"""
What a real-time consumer reads at each instant, in one compiled call into one flat array.

``snapshot.snapshot`` builds a ``Snapshot`` from a dozen NumPy calls on the ``Model``: ~50 us
of Python for the stage, several times the engine work of a 1 ms tick of ten steps, which is
what the stage node needs at every tick. `TickReport` computes the same numbers (poses, hinge
deflections and wrenches, the drives' inputs, forces, positions and wrenches, the outputs, the
compression, the hinges' stress ratios) in one compiled call (`report_kernel`, ~3 us), into
one preallocated array whose layout (`TickReport.index`) a consumer resolves once.

Each number is the ``Snapshot``'s, to the bit (``test/test_tick_report.py``):

- hinge deflections r and wrenches on body B: ``kernels.quadratic_forces``, the stepping
  kernel's force evaluation itself; Q gets the damping matrix's -C v (``Model.add_damping``);
- prescribed motion a_P: ``motion.prescribed_motion``, the stepping kernel's;
- drive inputs (``DriveTable.state_inputs``): a lagged drive's output u, a prescribed drive's
  displacement (its program's piece, ``programs.piece_motion``), a force drive's force;
- drive forces D_k^T lambda_P, lambda_P = M_P a_P - Q_P, of the displacement drives (eq. 6.4,
  ``Model.drive_forces``), a force drive's commanded force; each drive's full wrench on its
  body, in the body's frame (``DriveTable.wrenches``);
- drive positions e_d . (z - z0), outputs c_k . (z - z0) (``DriveTable.positions``,
  ``Model.output_values``);
- the compression (``compression.compression_of``, the same source compiled);
- stress ratios (C_h . |wrench_h|) of the hinges with a yield strength
  (``hinges.stress.ratio_map``); NaN for the others.

Mechanisms the kernel does not cover (a hinge law without the compiled force path, or a piezo
actuator whose stack report is per drive: ``actuation.report``) are reported through
``snapshot.snapshot`` into the same layout, so a consumer needs no second path.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.hinges.stress import ratio_map
from flexure_sim.engine.jit import njit
from flexure_sim.engine.solver.compression import compression_of
from flexure_sim.engine.solver.kernels import quadratic_forces
from flexure_sim.engine.solver.model import Model
from flexure_sim.engine.solver.snapshot import Snapshot, snapshot
from flexure_sim.engine.solver.state import Data, State
from flexure_sim.engine.solver.motion import prescribed_motion
from flexure_sim.engine.solver.programs import PIECE_WIDTH, piece_motion

_compression = njit(cache=True)(compression_of)


@njit(cache=True)
def stress_ratios(out, wrenches, index, coefficients):
    """
    Fill ``out`` (one per hinge) with the stress ratios sigma / sigma_y.

    sigma / sigma_y = C_h . |wrench_h| for the hinges ``index`` (``hinges.stress.ratio_map``'s
    coefficients C), NaN for the others.
    """
    for h in range(out.shape[0]):
        out[h] = math.nan
    for j in range(index.shape[0]):
        h = index[j]
        out[h] = (coefficients[j, 0] * abs(wrenches[h, 0])
                  + coefficients[j, 1] * abs(wrenches[h, 1])
                  + coefficients[j, 2] * abs(wrenches[h, 2]))


#: Sizes heading the integer constants of `report_kernel` (`TickReport._pack`).
_N_SIZES = 15


@njit(cache=True)
def drive_report(out, k, z, t, u, command, Q, aP, mass, prescribed, D, lagged, prescribed_drives,
                 first_program, force_index, displacement_index, held, bodies, directions):
    """
    Fill the drives' inputs, forces (``out[k:]``, ``out[k + nd:]``) and wrenches (at ``3 nd``).

    Inputs as ``DriveTable.state_inputs``; forces D^T lambda_P of the displacement drives
    (columns of D, ``displacement_index``) and the force drives' commands (eq. 6.4,
    ``DriveTable.forces``); wrenches (moment, f_x, f_y) in the driven body's frame from the
    reactions on the coordinates each drive holds (``held``: per drive its count, then its
    (coordinate, prescribed index) pairs) and the force drives' forces (``DriveTable.wrenches``).
    """
    nd, na, nP = bodies.shape[0], lagged.shape[0], prescribed.shape[0]
    for d in range(nd):
        out[k + d] = 0.0
        out[k + nd + d] = 0.0
    for j in range(na):
        out[k + lagged[j]] = u[j]
    for j in range(prescribed_drives.shape[0]):
        o = first_program + j * PIECE_WIDTH
        out[k + prescribed_drives[j]] = piece_motion(command[o:o + PIECE_WIDTH], t)[0]
    reactions = np.empty(nP)
    for i in range(nP):
        reactions[i] = mass[prescribed[i]] * aP[i] - Q[prescribed[i]]
    for j in range(displacement_index.shape[0]):
        force = 0.0
        for i in range(nP):
            force += D[i, j] * reactions[i]
        out[k + nd + displacement_index[j]] = force
    for j in range(force_index.shape[0]):
        out[k + force_index[j]] = command[na + j]
        out[k + nd + force_index[j]] = command[na + j]
    w = k + 3 * nd
    h = nd
    root = np.empty(3)
    for d in range(nd):
        root[:] = 0.0
        for m in range(held[d]):
            root[held[h + 2 * m]] += reactions[held[h + 2 * m + 1]]
        h += 2 * held[d]
        b = bodies[d]
        for j in range(force_index.shape[0]):
            if force_index[j] == d:
                for c in range(3):
                    root[c] += directions[d, 3 * b + c] * out[k + nd + d]
        cs, sn = math.cos(z[3 * b + 2]), math.sin(z[3 * b + 2])
        out[w + 3 * d] = root[2]
        out[w + 3 * d + 1] = cs * root[0] + sn * root[1]
        out[w + 3 * d + 2] = -sn * root[0] + cs * root[1]


@njit(cache=True)
def report_kernel(out, z, v, t, u, command, ints, floats):
    """
    Fill ``out`` (`TickReport` layout) at (z, v, t); return whether every entry is finite.

    u: the lagged drives' outputs, command: the kernel's command vector (``DriveTable``).
    ``ints``, ``floats``: the model's constants packed by `TickReport._pack` (one array each: a
    call with many array arguments costs Numba's dispatcher ~0.1 us per array).
    """
    (nq, nh, na, nP, ns, nd, no, n_disp, n_force, n_stress, nC, n_comp, n_prog, first_program,
     n_held) = ints[:_N_SIZES]
    i = _N_SIZES
    ia = ints[i:i + nh]
    ib = ints[i + nh:i + 2 * nh]
    kind = ints[i + 2 * nh:i + 3 * nh]
    i += 3 * nh
    sine_index = ints[i:i + ns]
    prescribed = ints[i + ns:i + ns + nP]
    i += ns + nP
    lagged = ints[i:i + na]
    prescribed_drives = ints[i + na:i + na + n_prog]
    i += na + n_prog
    displacement_index = ints[i:i + n_disp]
    force_index = ints[i + n_disp:i + n_disp + n_force]
    stress_index = ints[i + n_disp + n_force:i + n_disp + n_force + n_stress]
    i += n_disp + n_force + n_stress
    bodies = ints[i:i + nd]
    held = ints[i + nd:i + 2 * nd + 2 * n_held]
    f = 0
    ca = floats[f:f + 2 * nh].reshape((nh, 2))
    cb = floats[f + 2 * nh:f + 4 * nh].reshape((nh, 2))
    phia = floats[f + 4 * nh:f + 5 * nh]
    phib = floats[f + 5 * nh:f + 6 * nh]
    f += 6 * nh
    W = floats[f:f + 9 * nh].reshape((nh, 3, 3))
    C = floats[f + 9 * nh:f + 18 * nh].reshape((nh, 3, 3))
    f += 18 * nh
    damping = floats[f:f + nC * nC].reshape((nC, nC))
    f += nC * nC
    tau = floats[f:f + na]
    zP0 = floats[f + na:f + na + nP]
    f += na + nP
    D = floats[f:f + nP * na].reshape((nP, na))
    f += nP * na
    Dp = floats[f:f + nP * n_prog].reshape((nP, n_prog))
    f += nP * n_prog
    D_all = floats[f:f + nP * n_disp].reshape((nP, n_disp))
    f += nP * n_disp
    sine_amp = floats[f:f + ns]
    sine_w = floats[f + ns:f + 2 * ns]
    sine_phase = floats[f + 2 * ns:f + 3 * ns]
    f += 3 * ns
    mass = floats[f:f + nq]
    z0 = floats[f + nq:f + 2 * nq]
    f += 2 * nq
    drive_rows = floats[f:f + nd * nq].reshape((nd, nq))
    f += nd * nq
    output_rows = floats[f:f + no * nq].reshape((no, nq))
    f += no * nq
    compression = floats[f:f + n_comp]
    f += n_comp
    stress_coefficients = floats[f:f + 3 * n_stress].reshape((n_stress, 3))

    r = np.empty((nh, 3))
    wrench = np.empty((nh, 3))
    Q = np.empty(nq)
    quadratic_forces(z, v, ia, ib, ca, cb, phia, phib, kind, W, C, Q, r, wrench)
    if nC:
        Q -= damping @ v
    aP = prescribed_motion(t, u, command, tau, zP0, D, sine_index, sine_amp, sine_w,
                           sine_phase, Dp, first_program)[2]
    k = 0
    for i in range(nq):
        out[k] = z[i]
        k += 1
    for h in range(nh):
        for j in range(3):
            out[k + 3 * h + j] = r[h, j]
            out[k + 3 * nh + 3 * h + j] = wrench[h, j]
    k += 6 * nh
    drive_report(out, k, z, t, u, command, Q, aP, mass, prescribed, D_all, lagged,
                 prescribed_drives, first_program, force_index, displacement_index, held, bodies,
                 drive_rows)
    k += 2 * nd  # the positions follow the inputs and forces, then the wrenches
    for d in range(nd):
        s = 0.0
        for i in range(nq):
            s += drive_rows[d, i] * (z[i] - z0[i])
        out[k + d] = s
    k += 4 * nd
    for o in range(no):
        s = 0.0
        for i in range(nq):
            s += output_rows[o, i] * (z[i] - z0[i])
        out[k + o] = s
    k += no
    finite = True
    for i in range(k):
        if not math.isfinite(out[i]):
            finite = False
    if n_comp:
        out[k] = _compression(z, z0, int(compression[0]), compression[1], compression[2],
                              int(compression[3]), compression[4], compression[5],
                              compression[6], compression[7])
        finite = finite and math.isfinite(out[k])
    else:
        out[k] = math.nan
    k += 1
    stress_ratios(out[k:k + nh], wrench, stress_index, stress_coefficients)
    return finite  # NaN stress ratios and a NaN compression mark "none", not failures


# ``_compression`` compiles compression.py's function here: this module owns its stamp.
kernel_cache.revalidate([*kernel_cache.dispatchers_of(globals()), _compression], __file__)


@dataclass(frozen=True)
class ReportView:
    """
    A tick report shaped as a ``Snapshot`` (`TickReport.view`).

    Poses (n_bodies, 3), deflections and wrenches (n_hinges, 3), the first drive's force, the
    stress ratios (one per hinge, NaN without a yield strength).
    """

    poses: np.ndarray
    deflections: np.ndarray
    wrenches: np.ndarray
    drive_force: float
    stress_ratios: np.ndarray

    @classmethod
    def from_snapshot(cls, snap: Snapshot, mechanism) -> "ReportView":
        """Return the view of a ``Snapshot`` of ``mechanism`` (its stress ratios computed)."""
        names, index, coefficients = ratio_map(mechanism)
        ratios = np.empty(len(mechanism.hinges))
        stress_ratios(ratios, np.ascontiguousarray(snap.wrenches, dtype=float),
                      np.asarray(index, dtype=np.int64),
                      np.ascontiguousarray(coefficients, dtype=float))
        return cls(snap.poses, snap.deflections, snap.wrenches, float(snap.drive_force), ratios)


class TickReport:
    """
    The reported numbers of a ``Model`` at a ``State`` in one flat array (module docstring).

    ``index`` maps each part to its slice of `values`: ``poses`` (3 per body: x, y, theta),
    ``deflections`` and ``wrenches`` (3 per hinge: (alpha, p_x, p_y) and (moment, f_x, f_y),
    as ``Snapshot``), ``drive_inputs``, ``drive_forces``, ``drive_positions`` (one per drive,
    ``DriveTable.names`` order), ``drive_wrenches`` (3 per drive: (moment, f_x, f_y), as
    ``Snapshot.drive_wrenches``), ``outputs`` (``Model.output_names`` order), ``compression``
    (one entry, NaN without a compression hinge) and ``stress_ratios`` (one per hinge, NaN
    where the hinge has no yield strength).
    """

    def __init__(self, model: Model) -> None:
        self.model = model
        mech = model.mechanism
        nb, nh = len(mech.bodies), len(mech.hinges)
        nd, no = len(model.drives), len(model.output_names)
        sizes = (("poses", 3 * nb), ("deflections", 3 * nh), ("wrenches", 3 * nh),
                 ("drive_inputs", nd), ("drive_forces", nd), ("drive_positions", nd),
                 ("drive_wrenches", 3 * nd), ("outputs", no), ("compression", 1),
                 ("stress_ratios", nh))
        self.index: dict[str, slice] = {}
        start = 0
        for name, size in sizes:
            self.index[name] = slice(start, start + size)
            start += size
        #: The report of the last `fill`.
        self.values = np.zeros(start)
        #: Whether every number of the last `fill` was finite (NaN "none" entries aside).
        self.finite = True
        names, index, coefficients = ratio_map(mech)
        self._stress = (np.asarray(index, dtype=np.int64),
                        np.ascontiguousarray(coefficients, dtype=float))
        #: False: the mechanism is reported through ``snapshot`` (module docstring).
        self.compiled = bool(model.compiled and not model.drives.actuation)
        if self.compiled:
            self._constants = self._pack()

    def _pack(self) -> tuple[np.ndarray, np.ndarray]:
        """Pack the model's constants for `report_kernel`: (ints, floats), in its order."""
        model = self.model
        part, drives = model.part, model.drives
        hinge = model.assembly.kernel_arrays()  # ia, ib, ca, cb, phia, phib, kind, W, C
        damping = model.damping if model.damping is not None else np.zeros((0, 0))
        tau, zP0, D, sine_index, sine_amp, sine_w, sine_phase, Dp, first_program = model.motion
        points = model.compression
        compression = np.zeros(0)
        if points is not None:
            (i_drive, c_drive), (i_far, c_far), axis = points
            compression = np.array([i_drive, *c_drive, i_far, *c_far, *axis], dtype=float)
        stress_index, coefficients = self._stress
        nq, nh = len(model.z0), len(hinge[0])
        held = drives.holds  # per drive, the (coordinate, prescribed index) pairs it holds
        ints = [np.array([nq, nh, len(tau), len(part.prescribed), len(sine_index), len(drives),
                          len(model.output_names), len(drives.displacement), len(drives.force),
                          len(stress_index), damping.shape[0], len(compression),
                          len(drives.prescribed), first_program, sum(map(len, held))]),
                hinge[0], hinge[1], hinge[6], sine_index, part.prescribed, drives.lagged,
                drives.prescribed, drives.displacement, drives.force, stress_index,
                drives.bodies, [len(pairs) for pairs in held],
                [c for pairs in held for pair in pairs for c in pair]]
        floats = [hinge[2], hinge[3], hinge[4], hinge[5], hinge[7], hinge[8], damping, tau, zP0,
                  D, Dp, part.D, sine_amp, sine_w, sine_phase, model.mass, model.z0,
                  drives.directions, model.output_matrix, compression, coefficients]
        return (np.concatenate([np.asarray(a, dtype=np.int64).ravel() for a in ints]),
                np.concatenate([np.asarray(a, dtype=float).ravel() for a in floats]))

    def fill_data(self, data: Data) -> np.ndarray:
        """
        `fill` at ``data``'s state, with the command vector the integrator held last.

        After a step the integrator keeps the kernel's command vector of the new state
        (``integrator.step``'s cache): reusing it, while the state's commands and programs are
        those it was made from, spares ``DriveTable.kernel_command``.
        """
        s = data.state
        held = data.held_command(s) if self.compiled else None
        return self.fill(s, held[0] if held is not None else None)

    def fill(self, s: State, command: Optional[np.ndarray] = None) -> np.ndarray:
        """
        Report at state ``s`` into `values` (returned) and set `finite`.

        ``command``: the kernel's command vector of ``s`` if the caller has it (the one its last
        step held: ``DriveTable.kernel_command`` at the step's midpoint, as ``snapshot``).
        """
        if not self.compiled:
            return self._from_snapshot(s)
        if command is None:
            command = self.model.drives.kernel_command(s.command, s.programs,
                                                       s.t - 0.5 * self.model.dt)
        self.finite = report_kernel(self.values, s.z, s.v, s.t, s.u, command, *self._constants)
        prescribed = self.model.drives.prescribed
        if s.programs and len(prescribed):
            # A program's value at t (``DriveTable.state_inputs``, as the Snapshot): where t
            # ends a piece the piece the last step held can differ from it by a rounding.
            exact = self.model.drives.state_inputs(s.u, s.command, s.programs, s.t)
            self.values[self.index["drive_inputs"].start + prescribed] = exact[prescribed]
        return self.values

    def view(self) -> "ReportView":
        """Return the last `fill` as arrays shaped like a ``Snapshot``'s (views, not copies)."""
        values, ix = self.values, self.index
        forces = values[ix["drive_forces"]]
        return ReportView(values[ix["poses"]].reshape(-1, 3),
                          values[ix["deflections"]].reshape(-1, 3),
                          values[ix["wrenches"]].reshape(-1, 3),
                          float(forces[0]) if len(forces) else 0.0,
                          values[ix["stress_ratios"]])

    def _from_snapshot(self, s: State) -> np.ndarray:
        snap = snapshot(self.model, s)
        values, ix = self.values, self.index
        values[ix["poses"]] = snap.poses.ravel()
        values[ix["deflections"]] = snap.deflections.ravel()
        values[ix["wrenches"]] = snap.wrenches.ravel()
        values[ix["drive_inputs"]] = snap.drive_inputs
        values[ix["drive_forces"]] = snap.drive_forces
        values[ix["drive_positions"]] = snap.drive_positions
        values[ix["drive_wrenches"]] = snap.drive_wrenches.ravel()
        values[ix["outputs"]] = [snap.outputs[n] for n in self.model.output_names]
        values[ix["compression"]] = math.nan if snap.compression is None else snap.compression
        stress_ratios(values[ix["stress_ratios"]], np.ascontiguousarray(snap.wrenches),
                      *self._stress)
        self.finite = bool(np.isfinite(values[:ix["compression"].start]).all()
                           and (snap.compression is None or math.isfinite(snap.compression)))
        return values
