"""
A piezo stack actuator: amplifier lag, Bouc-Wen hysteresis, Kelvin-Voigt creep, stack stiffness.

The chain from the command to the force on the stage (every quantity SI; V in volts):

1. command: a voltage V_c, or a nominal displacement x_c mapped through the nominal gain
   d = (s_max - s_min) / (v_max - v_min) (m/V, the drive's stroke over the voltage range):
   V_c = v_min + (x_c - s_min) / d.                                        (P1)
2. amplifier: a first-order low-pass of -3 dB bandwidth f_amp (Hz), tau_a = 1 / (2 pi f_amp):
   dV_a/dt = (V_c - V_a) / tau_a.                                          (P2)
   ``bandwidth`` 0 means unlimited: V_a = V_c, and a change of a held command is applied by
   `jump` (the hysteresis below is rate-independent, so a jump is integrated exactly in V).
3. hysteresis, the Bouc-Wen model with n = 1 as used for piezo actuators (Low and Guo,
   J. Microelectromech. Syst. 4(4) 230-237, 1995; Rakotondrabe, IEEE T-ASE 8(2) 428-431,
   2011):
   x_h = d (V_a - v_min) - h,                                              (P3)
   dh/dt = alpha d dV_a/dt - beta |dV_a/dt| h - gamma dV_a/dt |h|,          (P4)
   alpha (dimensionless) sets the loop's size, beta and gamma (1/V) its shape; h is in m.
   With hysteresis the loop is run counter-clockwise in (V, x): the ascending branch lies
   below the descending one. alpha = 0: no hysteresis (h stays 0).
4. creep, a Kelvin-Voigt chain in series with the elastic (instantaneous) part (Jung and
   Gweon, Rev. Sci. Instrum. 71(4) 2000; the linear creep operator of Croft, Shed and
   Devasia, J. Dyn. Sys. Meas. Control 123(1) 2001): element i of ratio r_i and time
   constant tau_i (a spring k_0/r_i parallel to a dashpot, k_0 the elastic part's stiffness)
   adds c_i with
   dc_i/dt = (r_i x_h - c_i) / tau_i,                                      (P5)
   so a step of x_h by D gives D (1 + sum_i r_i (1 - exp(-t / tau_i))). Elements a time
   decade apart with ratio g each approximate the logarithmic law
   D(t) = D_0.1 (1 + g log10(t / 0.1 s)) with creep factor g ~ 0.01-0.02 (Physik Instrumente,
   piezo tutorial, "Creep / Drift"): over a decade t..10t the increments
   g (exp(-t/tau_k) - exp(-10 t/tau_k)), tau_k = 10^k s, telescope to exactly g for an
   endless chain, so a finite chain creeps g per decade between its first and last tau.
5. free stroke (the displacement of the unloaded actuator) and the stack's stiffness k_s in
   series with the stage:
   x_a = s_min + x_h + sum_i c_i,                                          (P6)
   F = k_s (x_a - x_out),                                                  (P7)
   the force on the stage along the drive axis at its displacement x_out: the blocked force
   is k_s x_a (x_out = 0), the free stroke x_a (F = 0). Against a load spring k_L
   (F = k_L x_out): x_out = x_a k_s / (k_s + k_L)                           (P8)
   (`series_output`). ``stiffness`` inf: a rigid stack, x_out = x_a.

The stage does not act back on the actuator's states: hysteresis and creep are those of the
free stroke, and the load only compresses the stack (P7).

State per actuator (`PiezoSpec.state_names`): s = [V_a (V), h (m), c_1 .. c_N (m)]. `rhs` is f in
ds/dt = f(s, V_c, dV_c/dt) (the rate is used only without an amplifier lag), `jacobian` its
exact derivative; `advance` steps it under a held command (exact but for the creep's
input, linear over the step). Steady hysteresis loop in closed form: `steady_loop_half_width`.
No ROS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit

#: The command kinds of the ``actuator: {command: ...}`` key.
COMMANDS = ("displacement", "voltage")


@dataclass(frozen=True)
class CreepElement:
    """One Kelvin-Voigt element of the creep chain (P5): ``ratio`` r_i >= 0, ``tau`` s > 0."""

    ratio: float
    tau: float


@dataclass(frozen=True)
class PiezoSpec:
    """
    The actuator block of a drive (mechanism file ``actuator:``, mechanism/actuator_block.py).

    gain: nominal gain d (m/V, P1); v_min, v_max: the voltage range (V) mapped onto the
    drive's stroke [s_min, ...]; command: ``displacement`` (nominal, m) or ``voltage`` (V);
    bandwidth: amplifier -3 dB bandwidth (Hz, 0: unlimited, P2); stiffness: stack stiffness
    k_s (N/m, inf: rigid, P7); alpha, beta (1/V), gamma (1/V): Bouc-Wen (P4); creep: the
    Kelvin-Voigt chain (P5).
    """

    gain: float
    v_max: float
    v_min: float = 0.0
    s_min: float = 0.0
    command: str = "displacement"
    bandwidth: float = 0.0
    stiffness: float = math.inf
    alpha: float = 0.0
    beta: float = 0.0
    gamma: float = 0.0
    creep: tuple[CreepElement, ...] = field(default=())

    @property
    def size(self) -> int:
        """Length of the state vector: V_a, h, then one per creep element."""
        return 2 + len(self.creep)

    @property
    def state_names(self) -> list[str]:
        """Names of the state's entries, in order."""
        return ["voltage", "hysteresis"] + [f"creep{i}" for i in range(len(self.creep))]

    @property
    def lagged(self) -> bool:
        """Tell whether the amplifier has a finite bandwidth (V_a is a lagging state)."""
        return self.bandwidth > 0.0

    @property
    def tau_amplifier(self) -> float:
        """tau_a = 1 / (2 pi f_amp) (P2); 0 when the bandwidth is unlimited."""
        return 1.0 / (2.0 * math.pi * self.bandwidth) if self.lagged else 0.0


def command_voltage(spec: PiezoSpec, command):
    """Return the voltage V_c of a command (P1): itself, or the nominal map's inverse."""
    if spec.command == "voltage":
        return command
    return spec.v_min + (np.asarray(command, dtype=float) - spec.s_min) / spec.gain


def command_limits(spec: PiezoSpec, stroke, slew_rate: float) -> tuple[float, float, float]:
    """
    Return a drive's stroke and slew-rate limits in its actuator's command unit: (lo, hi, rate).

    ``stroke`` [s_min, s_max] (m) and ``slew_rate`` (m/s) are the drive's; a displacement
    command keeps them, a voltage command maps them through (P1): [v_min, v_max] (V) and
    slew_rate / d (V/s).
    """
    if spec.command == "voltage":
        return spec.v_min, spec.v_max, float(slew_rate) / spec.gain
    return float(stroke[0]), float(stroke[1]), float(slew_rate)


def nominal_displacement(spec: PiezoSpec, voltage):
    """s_min + d (V - v_min): the displacement of an ideal actuator at voltage V (P1)."""
    return spec.s_min + spec.gain * (np.asarray(voltage, dtype=float) - spec.v_min)


def initial_state(spec: PiezoSpec) -> np.ndarray:
    """Return the state at rest: V_a = v_min, no hysteresis, no creep (x_a = s_min)."""
    s = np.zeros(spec.size)
    s[0] = spec.v_min
    return s


def rhs(spec: PiezoSpec, s: np.ndarray, v_cmd: float, v_rate: float = 0.0) -> np.ndarray:
    """
    Return ds/dt = f(s, V_c, dV_c/dt) (P2, P4, P5).

    With a finite bandwidth dV_a/dt = (V_c - V_a) / tau_a and ``v_rate`` is unused; without,
    dV_a/dt = ``v_rate`` (V_a follows the command; a held command has rate 0: see `jump`).
    """
    V, h = s[0], s[1]
    dV = (v_cmd - V) / spec.tau_amplifier if spec.lagged else v_rate
    out = np.empty(spec.size)
    out[0] = dV
    out[1] = spec.alpha * spec.gain * dV - spec.beta * abs(dV) * h - spec.gamma * dV * abs(h)
    x_h = spec.gain * (V - spec.v_min) - h
    for i, el in enumerate(spec.creep):
        out[2 + i] = (el.ratio * x_h - s[2 + i]) / el.tau
    return out


def jacobian(spec: PiezoSpec, s: np.ndarray, v_cmd: float,
             v_rate: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """
    Return (df/ds, df/d(V_c, dV_c/dt)): the exact derivatives of `rhs`, shapes (n, n), (n, 2).

    From (P4) with r = dV_a/dt: dh'/dr = alpha d - beta sgn(r) h - gamma |h|,
    dh'/dh = -beta |r| - gamma r sgn(h); r = (V_c - V_a)/tau_a gives dr/dV_a = -1/tau_a,
    dr/dV_c = 1/tau_a (no lag: dr/d(dV_c/dt) = 1). From (P5): dc_i'/dV_a = r_i d / tau_i,
    dc_i'/dh = -r_i / tau_i, dc_i'/dc_i = -1 / tau_i. Exact wherever f is differentiable
    (r != 0 and h != 0, or either factor of a kink term zero, as at rest); at a kink it is
    the one-sided derivative with sgn(0) = 0.
    """
    V, h = s[0], s[1]
    n = spec.size
    A, B = np.zeros((n, n)), np.zeros((n, 2))
    if spec.lagged:
        tau = spec.tau_amplifier
        r = (v_cmd - V) / tau
        dr_dV, dr_in = -1.0 / tau, np.array([1.0 / tau, 0.0])
    else:
        r, dr_dV, dr_in = v_rate, 0.0, np.array([0.0, 1.0])
    A[0, 0], B[0] = dr_dV, dr_in
    dh_dr = spec.alpha * spec.gain - spec.beta * np.sign(r) * h - spec.gamma * abs(h)
    A[1, 0] = dh_dr * dr_dV
    A[1, 1] = -spec.beta * abs(r) - spec.gamma * r * np.sign(h)
    B[1] = dh_dr * dr_in
    for i, el in enumerate(spec.creep):
        A[2 + i, 0] = el.ratio * spec.gain / el.tau
        A[2 + i, 1] = -el.ratio / el.tau
        A[2 + i, 2 + i] = -1.0 / el.tau
    return A, B


def free_stroke(spec: PiezoSpec, s: np.ndarray):
    """x_a = s_min + d (V_a - v_min) - h + sum c_i (P3, P6); ``s`` of shape (n,) or (n, k)."""
    return stroke_values(np.asarray(s, dtype=float), spec.s_min, spec.gain, spec.v_min)


def stroke_values(s, s_min, gain, v_min):
    """`free_stroke` (P6) from the state's entries (rows of ``s``) and the spec's numbers."""
    creep = 0.0
    for i in range(2, s.shape[0]):
        creep = creep + s[i]
    return s_min + gain * (s[0] - v_min) - s[1] + creep


#: `stroke_values` compiled for one state (one source; the Python one also takes rows).
stroke_kernel = njit(cache=True)(stroke_values)


def free_stroke_gradient(spec: PiezoSpec) -> np.ndarray:
    """dx_a/ds = [d, -1, 1, ..., 1] (constant: P6 is linear in the state)."""
    return np.concatenate([[spec.gain, -1.0], np.ones(len(spec.creep))])


def stack_force(spec: PiezoSpec, x_a, x_out):
    """F = k_s (x_a - x_out) (P7): the force on the stage along the drive axis (N)."""
    return spec.stiffness * (np.asarray(x_a) - np.asarray(x_out))


def series_output(k_s: float, k_load: float, x_a):
    """
    x_out = x_a k_s / (k_s + k_L) (P8): the stack (k_s) in series with a load spring k_L.

    k_s inf: x_out = x_a (rigid stack); k_L inf: x_out = 0 (blocked); k_L 0: free stroke.
    """
    x_a = np.asarray(x_a, dtype=float)
    if math.isinf(k_load):
        return np.zeros_like(x_a)
    if math.isinf(k_s):
        return x_a.copy()
    return x_a * (k_s / (k_s + k_load))


@njit(cache=True)
def _sweep(h: float, dv: float, a: float, beta: float, gamma: float) -> float:
    """
    Return h after the voltage moves monotonically by ``dv`` from a state with hysteresis h.

    The exact solution of (P4) in its rate-independent form dh/dV = a - beta sgn(dV) h -
    gamma |h| (a = alpha d). With g = sgn(dV) h and the travel l = |dV| it reads
    dg/dl = a - beta g - gamma |g|, linear on each side of g = 0:
    g >= 0: dg/dl = a - p g, p = beta + gamma: g(l) = a/p + (g0 - a/p) exp(-p l);
    g < 0:  dg/dl = a - m g, m = beta - gamma: g(l) = a/m + (g0 - a/m) exp(-m l)
    (g0 + a l if m = 0), which reaches g = 0 after l0 = ln(1 - m g0 / a) / m (-g0/a if m = 0).
    """
    if dv == 0.0 or a == 0.0:
        return h
    sgn = 1.0 if dv > 0 else -1.0
    g, ell = sgn * h, abs(dv)
    p, m = beta + gamma, beta - gamma
    if g < 0.0:
        l0 = -g / a if m == 0.0 else math.log1p(-m * g / a) / m
        if ell <= l0:
            g = g + a * ell if m == 0.0 else a / m + (g - a / m) * math.exp(-m * ell)
            return sgn * g
        g, ell = 0.0, ell - l0
    g = a / p + (g - a / p) * math.exp(-p * ell)
    return sgn * g


def jump(spec: PiezoSpec, s: np.ndarray, v_new: float) -> np.ndarray:
    """
    Return the state after the amplifier output jumps to ``v_new`` (unlimited bandwidth).

    h follows the exact monotone sweep (`_sweep`: Bouc-Wen is rate-independent, so an
    instantaneous change is the limit of any fast monotone ramp); creep states are
    continuous (P5 has bounded rates) and keep their values.
    """
    return jump_values(np.array(s, dtype=float), float(v_new), spec.alpha * spec.gain,
                       spec.beta, spec.gamma)


@njit(cache=True)
def jump_values(s, v_new, a, beta, gamma):
    """`jump` from the state and the spec's numbers (a = alpha d)."""
    out = s.copy()
    out[1] = _sweep(out[1], v_new - out[0], a, beta, gamma)
    out[0] = v_new
    return out


def creep_arrays(spec: PiezoSpec) -> tuple[np.ndarray, np.ndarray]:
    """Return the creep chain's ratios r_i and time constants tau_i (s) as arrays (P5)."""
    return (np.array([el.ratio for el in spec.creep], dtype=float),
            np.array([el.tau for el in spec.creep], dtype=float))


def advance(spec: PiezoSpec, s: np.ndarray, v_cmd: float, dt: float) -> np.ndarray:
    """
    Return the state after ``dt`` (s) with the command held at ``v_cmd`` (V; zero-order hold).

    See `advance_values`, which it calls with the spec's numbers.
    """
    if not dt > 0:
        raise ValueError(f"dt: must be positive, got {dt!r}")
    ratios, taus = creep_arrays(spec)
    return advance_values(np.array(s, dtype=float), float(v_cmd), float(dt),
                          spec.tau_amplifier, spec.alpha * spec.gain, spec.beta, spec.gamma,
                          spec.gain, spec.v_min, ratios, taus)


@njit(cache=True)
def advance_values(s, v_cmd, dt, tau_a, a, beta, gamma, gain, v_min, ratios, taus):
    """
    Return the state after ``dt`` under the held ``v_cmd``: `advance` from the spec's numbers.

    tau_a (0: no lag), a = alpha d, beta, gamma, d, v_min, and the creep chain's ratios and
    taus (`creep_arrays`). The amplifier (P2) exactly: V_1 = V_c + (V_0 - V_c) exp(-dt / tau_a)
    (without a lag: `jump` to V_c at the step's start). V_a moves monotonically over the step,
    so h is exact too (`_sweep`: the rate-independent dh/dV). Creep (P5) by its exact solution
    for x_h linear over the step between its values x_0, x_1 at the ends (the error is second
    order in dt / tau_i):
    c_1 = E c_0 + r [x_0 (1 - E) + (x_1 - x_0) (1 - tau (1 - E) / dt)], E = exp(-dt / tau).
    """
    lagged = tau_a > 0.0
    s0 = s.copy() if lagged else jump_values(s, v_cmd, a, beta, gamma)
    out = s0.copy()
    if lagged:
        out[0] = v_cmd + (s0[0] - v_cmd) * math.exp(-dt / tau_a)
        out[1] = _sweep(s0[1], out[0] - s0[0], a, beta, gamma)
    x0 = gain * (s0[0] - v_min) - s0[1]
    x1 = gain * (out[0] - v_min) - out[1]
    for i in range(ratios.shape[0]):
        one_minus_e = -math.expm1(-dt / taus[i])
        out[2 + i] = ((1.0 - one_minus_e) * s0[2 + i] + ratios[i] * (
            x0 * one_minus_e + (x1 - x0) * (1.0 - taus[i] * one_minus_e / dt)))
    return out


def steady_loop_half_width(spec: PiezoSpec, amplitude: float) -> float:
    """
    Return the half-width (m) of the steady Bouc-Wen loop at the centre of a symmetric sweep.

    The voltage sweeps monotonically between V_0 - A and V_0 + A (``amplitude`` A, V), e.g. a
    triangle. (P4) depends on V only through dV, so the steady loop is point-symmetric about
    its centre: each sweep runs from g = -H to g = +H (g = sgn(dV) h, H the turning value).
    With a = alpha d, p = beta + gamma, m = beta - gamma, integrating `_sweep`'s pieces:
    from g = -H the branch crosses g = 0 after l0 = ln(1 + m H / a) / m, then
    g(l) = (a/p) (1 - exp(-p (l - l0))) = (a/p) (1 - (1 + m H/a)^(p/m) exp(-p l)).
    The sweep closes (g(2A) = H) when
        H = (a/p) (1 - (1 + m H / a)^(p/m) exp(-2 p A)),                    (L1)
    one equation with a unique root in (0, a/p) (the left side rises, the right falls),
    solved by bisection to machine precision. The half-width at the centre (l = A) is
        w = g(A) = (a/p) (1 - (1 + m H / a)^(p/m) exp(-p A)),                (L2)
    (from `_sweep` if the crossing lies beyond the centre). The loop's width at the centre,
    descending minus ascending branch of x_h = d V - h, is 2 w. In closed form for gamma = 0
    (p = m = beta): H = (a/beta) tanh(beta A) and w = (a/beta) (1 - sech(beta A)).
    """
    a, beta, gamma = spec.alpha * spec.gain, spec.beta, spec.gamma
    if a == 0.0 or amplitude <= 0.0:
        return 0.0

    def closing(H: float) -> float:  # (L1): end of a sweep of 2A from -H, minus H
        return _sweep(-H, 2.0 * amplitude, a, beta, gamma) - H

    lo, hi = 0.0, a / (beta + gamma)
    for _ in range(200):  # bisection: closing(lo) > 0 > closing(hi)
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        lo, hi = (mid, hi) if closing(mid) > 0.0 else (lo, mid)
    H = 0.5 * (lo + hi)
    return _sweep(-H, amplitude, a, beta, gamma)


# Numba's cache of each compiled function is keyed on its own file only (``kernel_cache``).
kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
