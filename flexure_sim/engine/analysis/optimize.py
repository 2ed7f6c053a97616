"""
Design optimisation with exact gradients: one objective, constraints, bounds (scipy.optimize).

The problem of an optimisation study (analysis/optimize_study.py) in scaled form:

    minimise    f(x) = s F(p) / F0                       (s = -1 to maximise)
    subject to  c_i(x) = (F_i(p) - min_i) / C_i >= 0,  (max_i - F_i(p)) / C_i >= 0,
                0 <= x <= 1,    p = lower + x (upper - lower),

with F0 = |F(start)| and C_i = |limit_i| (else |F_i(start)|, else 1), so that objective,
constraints and variables are all of order one. Values and gradients come from
analysis/design_outputs.py: exact (hyper-dual) gradients, no differences. A constraint on an
extreme over hinges in its natural direction (the largest stress ratio at most, the smallest
safety factor at least) becomes one smooth constraint per hinge.

scipy.optimize.minimize solves it, with SLSQP (sequential quadratic programming; D. Kraft,
"A software package for sequential quadratic programming", DFVLR-FB 88-28, 1988) or
trust-constr (a trust-region interior point / SQP method; Byrd, Hribar and Nocedal, SIAM J.
Optim. 9 (1999) 877), each with the exact gradients and its own quasi-Newton Hessian.

At the result the first-order (KKT) conditions are checked independently of the method
(Nocedal and Wright, "Numerical Optimization", 2nd ed., Theorem 12.1): the active set is the
constraints and bounds within ``ACTIVE`` of their limit, the multipliers lambda >= 0 the
non-negative least-squares solution of grad f = sum lambda_i grad c_i (scipy.optimize.nnls),
and the report gives the stationarity residual |grad f - A^T lambda| / |grad f|, the largest
violation and the complementarity max lambda_i |c_i|. A multiplier in the study's units,
mu_i = lambda_i F0 / C_i, is how much the objective improves per unit the limit is relaxed.

A problem without a feasible design ends with the least-violating one: a second solve
minimises t subject to c_i(x) + t >= 0 (the largest scaled violation), and the result names
each constraint still violated and by how much.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np
import scipy.optimize

from flexure_sim.engine.analysis.design_outputs import EXTREMES
from flexure_sim.engine.analysis.optimize_study import OptimizeStudy
from flexure_sim.errors import FlexureSimError

#: A constraint or bound within this (scaled) distance of its limit counts as active.
ACTIVE = 1e-6
#: The largest scaled violation of a design that counts as feasible.
FEASIBLE = 1e-6
#: The relative stationarity (and complementarity) the result must reach to count as optimal.
KKT_TOLERANCE = 1e-6


class OptimizeError(FlexureSimError, RuntimeError):
    """A design of the optimisation could not be evaluated (names the design and the cause)."""


@dataclass(frozen=True)
class Component:
    """One smooth scaled constraint: its text, column, hinge (or None), side and limit."""

    text: str
    column: str
    hinge: Optional[str]
    side: str          # "min" (value >= limit) or "max" (value <= limit)
    limit: float
    scale: float

    def scaled(self, value: float) -> float:
        return ((value - self.limit) if self.side == "min" else (self.limit - value)) / self.scale


@dataclass
class Result:
    """What an optimisation found (``solve``); JSON-ready through ``as_dict``."""

    status: str                     # optimal | infeasible | not_converged
    message: str
    x: np.ndarray
    start: np.ndarray
    objective: float
    values: dict
    parts: dict
    constraints: list
    bounds: list
    kkt: dict
    sensitivities: dict
    history: list
    evaluations: int = 0
    gradients: int = 0
    wall_s: float = 0.0
    method: str = ""
    iterations: int = 0
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        out = dict(self.__dict__)
        out["x"], out["start"] = self.x.tolist(), self.start.tolist()
        return out


class Problem:
    """The scaled problem of a study (module docstring), with a cache of evaluated designs."""

    def __init__(self, study: OptimizeStudy):
        self.study = study
        self.lo, self.span = study.lower, study.upper - study.lower
        self.sign = -1.0 if study.sense == "maximize" else 1.0
        self._cache: dict = {}
        self.evaluations = self.gradients = 0
        #: Wall time in evaluations with gradients (exact sensitivities) and values only.
        self.seconds = {"gradients": 0.0, "values": 0.0}
        start = (study.start - self.lo) / self.span
        first = self.evaluate(start, gradients=False)
        self.f0 = abs(first[study.objective].value) or 1.0
        self.components = self._components(first)

    def physical(self, xs) -> np.ndarray:
        """Return the design of scaled ``xs`` (clipped to the bounds; exact at both bounds)."""
        xs = np.clip(np.asarray(xs, dtype=float), 0.0, 1.0)
        return (1.0 - xs) * self.lo + xs * (self.lo + self.span)

    def evaluate(self, xs, gradients: bool) -> dict:
        """Return the design's design_outputs.Value per column (cached; gradients on demand)."""
        key = np.asarray(xs, dtype=float).tobytes()
        hit = self._cache.get(key)
        if hit is not None and (hit[1] or not gradients):
            return hit[0]
        p = self.physical(xs)
        start = time.perf_counter()
        try:
            values = self.study.evaluate(p, gradients)
        except FlexureSimError as exc:
            shown = ", ".join(f"{v.name} = {x:.6g}" for v, x in zip(self.study.variables, p))
            raise OptimizeError(f"the design {shown} could not be evaluated: {exc}") from None
        self.seconds["gradients" if gradients else "values"] += time.perf_counter() - start
        self.evaluations += 1
        self.gradients += int(gradients)
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[key] = (values, gradients)
        return values

    def _components(self, first: dict) -> list[Component]:
        out = []
        for c in self.study.constraints:
            value = first[c.output]
            for side, limit in (("min", c.min), ("max", c.max)):
                if limit is None:
                    continue
                scale = abs(limit) or abs(value.value) or 1.0
                text = f"{c.output} {'>=' if side == 'min' else '<='} {limit:g}"
                natural = EXTREMES.get(c.output) is (max if side == "max" else min)
                if natural and value.parts:
                    out += [Component(f"{text} [hinge {h}]", c.output, h, side, limit, scale)
                            for h in value.parts]
                else:
                    out.append(Component(text, c.output, None, side, limit, scale))
        return out

    # ------------------------------------------------------------- scipy's functions
    def _raw(self, value, hinge: Optional[str]):
        return value.parts[hinge] if hinge is not None else (value.value, value.gradient)

    def f(self, xs) -> float:
        return self.sign * self.evaluate(xs, False)[self.study.objective].value / self.f0

    def grad(self, xs) -> np.ndarray:
        g = self.evaluate(xs, True)[self.study.objective].gradient
        return self.sign * g * self.span / self.f0

    def c(self, xs) -> np.ndarray:
        values = self.evaluate(xs, False)
        return np.array([k.scaled(self._raw(values[k.column], k.hinge)[0])
                         for k in self.components])

    def c_jac(self, xs) -> np.ndarray:
        values = self.evaluate(xs, True)
        rows = [(1.0 if k.side == "min" else -1.0) / k.scale
                * self._raw(values[k.column], k.hinge)[1] * self.span for k in self.components]
        return np.array(rows).reshape(len(self.components), len(self.span))

    def violation(self, xs) -> float:
        c = self.c(xs)
        return float(max(0.0, -c.min())) if len(c) else 0.0


def _stationary(problem: Problem, xs: np.ndarray) -> bool:
    """Tell whether the KKT conditions hold at ``xs`` to KKT_TOLERANCE (``kkt``)."""
    k = kkt(problem, xs)
    return (k["stationarity_relative"] <= KKT_TOLERANCE and k["violation"] <= FEASIBLE
            and k["complementarity"] <= KKT_TOLERANCE)


def _minimize(problem: Problem, x0: np.ndarray, history: list, fun, jac, cons, cons_jac,
              bounds, polish: bool = False) -> Any:
    """
    scipy.optimize.minimize with the study's method and options; records each iterate.

    ``polish``: a second run from a converged point, with a 1000 times tighter tolerance.
    """
    st = problem.study
    tol = st.tolerance * (1e-3 if polish else 1.0)
    if st.method == "SLSQP" or polish:
        constraints = ([{"type": "ineq", "fun": cons, "jac": cons_jac}]
                       if problem.components else [])
        return scipy.optimize.minimize(
            fun, x0, jac=jac, method="SLSQP", bounds=bounds, constraints=constraints,
            callback=lambda xk: history.append(np.array(xk)),
            options={"maxiter": st.max_iterations, "ftol": tol})
    nonlinear = ([scipy.optimize.NonlinearConstraint(cons, 0.0, np.inf, jac=cons_jac)]
                 if problem.components else [])

    def record(xk, state) -> bool:
        history.append(np.array(xk))
        return False  # True would stop trust-constr
    return scipy.optimize.minimize(
        fun, x0, jac=jac, method="trust-constr", bounds=bounds, constraints=nonlinear,
        hess=scipy.optimize.BFGS(),
        callback=record,
        options={"maxiter": st.max_iterations, "gtol": tol, "xtol": tol})


def kkt(problem: Problem, xs: np.ndarray) -> dict:
    """
    Return the first-order conditions at ``xs`` (module docstring).

    {"active": [(kind, index)], "multipliers": lambda per active entry, "stationarity",
    "stationarity_relative", "violation", "complementarity"}.
    """
    g = problem.grad(xs)
    c, J = problem.c(xs), problem.c_jac(xs)
    rows, active = [], []
    for i, ci in enumerate(c):
        if abs(ci) <= ACTIVE:
            rows.append(J[i])
            active.append(("constraint", i))
    for j, xj in enumerate(xs):
        for side, at, normal in (("lower", 0.0, 1.0), ("upper", 1.0, -1.0)):
            if abs(xj - at) <= ACTIVE:
                e = np.zeros(len(xs))
                e[j] = normal
                rows.append(e)
                active.append((side, j))
    if rows:
        A = np.array(rows)
        lam, _ = scipy.optimize.nnls(A.T, g)
        residual = g - A.T @ lam
    else:
        lam, residual = np.zeros(0), g
    comp = max([lam[k] * abs(c[i]) for k, (kind, i) in enumerate(active) if kind == "constraint"],
               default=0.0)
    norm = float(np.linalg.norm(g))
    return {"active": active, "multipliers": lam, "stationarity": float(np.linalg.norm(residual)),
            "stationarity_relative": float(np.linalg.norm(residual)) / norm if norm else 0.0,
            "violation": problem.violation(xs), "complementarity": float(comp)}


def solve(study: OptimizeStudy, start: Optional[np.ndarray] = None) -> Result:
    """Optimise a study from ``start`` (physical; default the study's) and report."""
    t0 = time.perf_counter()
    problem = Problem(study)
    x0 = (np.asarray(study.start if start is None else start, dtype=float) - problem.lo) / \
        problem.span
    history = [x0.copy()]
    bounds = scipy.optimize.Bounds(np.zeros(len(x0)), np.ones(len(x0)))
    res = _minimize(problem, x0, history, problem.f, problem.grad, problem.c, problem.c_jac,
                    bounds)
    xs = np.clip(res.x, 0.0, 1.0)
    extra = {"method_message": str(res.message)}
    if problem.violation(xs) <= FEASIBLE and not _stationary(problem, xs) and (
            res.success or study.method != "SLSQP"):
        # Stopped by the method's own test short of the KKT tolerance (trust-constr's interior
        # iterates reach an active bound only asymptotically): SLSQP from here, tighter.
        res = _minimize(problem, xs, history, problem.f, problem.grad, problem.c,
                        problem.c_jac, bounds, polish=True)
        xs = np.clip(res.x, 0.0, 1.0)
        extra["polish"] = f"SLSQP from the {study.method} result"
    if problem.violation(xs) > FEASIBLE:
        xs, found = _least_violating(problem, xs, history)
        extra.update(found)
        status, message = "infeasible", infeasible_message(problem, xs)
    elif _stationary(problem, xs):
        status, message = "optimal", ("the first-order (KKT) conditions hold to "
                                      f"{KKT_TOLERANCE:g} ({extra.get('polish', study.method)}"
                                      f": {res.message})")
    else:
        status = "not_converged"
        message = (f"{study.method} stopped ({res.message}) where the KKT conditions do not hold "
                   f"to {KKT_TOLERANCE:g}: raise max_iterations or check the scaling")
    result = report(problem, xs, status, message, history)
    result.start = problem.physical(x0)
    result.wall_s = time.perf_counter() - t0
    result.iterations = int(getattr(res, "nit", len(history) - 1))
    result.extra = {**extra, "seconds": dict(problem.seconds)}
    return result


def _least_violating(problem: Problem, xs: np.ndarray, history: list) -> tuple:
    """Return (the design minimising the largest scaled violation, what the solve said)."""
    n = len(xs)

    def fun(y):
        return y[n]

    def jac(y):
        e = np.zeros(n + 1)
        e[n] = 1.0
        return e

    def cons(y):
        return problem.c(y[:n]) + y[n]

    def cons_jac(y):
        J = problem.c_jac(y[:n])
        return np.hstack([J, np.ones((len(J), 1))])

    y0 = np.append(xs, problem.violation(xs))
    bounds = scipy.optimize.Bounds(np.append(np.zeros(n), 0.0), np.append(np.ones(n), np.inf))
    trail: list = []
    res = scipy.optimize.minimize(fun, y0, jac=jac, method="SLSQP", bounds=bounds,
                                  constraints=[{"type": "ineq", "fun": cons, "jac": cons_jac}],
                                  callback=lambda yk: trail.append(np.array(yk[:n])),
                                  options={"maxiter": problem.study.max_iterations,
                                           "ftol": problem.study.tolerance})
    history += trail
    best = np.clip(res.x[:n], 0.0, 1.0)
    if problem.violation(best) > problem.violation(xs):
        best = xs
    return best, {"least_violating": {"message": str(res.message),
                                      "violation": problem.violation(best)}}


def infeasible_message(problem: Problem, xs: np.ndarray) -> str:
    """Return the message of a problem without a feasible design: what is violated, by how much."""
    values = problem.evaluate(xs, False)
    missed = []
    for k in problem.components:
        v = problem._raw(values[k.column], k.hinge)[0]
        if k.scaled(v) < -FEASIBLE:
            short = abs(v - k.limit)
            rel = f", {short / abs(k.limit):.1%}" if k.limit else ""
            side = "short" if k.side == "min" else "over"
            missed.append(f"{k.text}: {v:.6g} ({short:.3g} {side}{rel})")
    return ("no design within the bounds meets every constraint; the least-violating design "
            "has " + "; ".join(missed))


def report(problem: Problem, xs: np.ndarray, status: str, message: str, history: list) -> Result:
    """Return the Result at ``xs``: values, constraints with multipliers, KKT, sensitivities."""
    st = problem.study
    values = problem.evaluate(xs, True)
    conditions = kkt(problem, xs)
    if status == "infeasible":  # no multipliers: the objective's conditions do not apply
        conditions = {"active": [], "multipliers": [], "violation": conditions["violation"]}
    lam = dict(zip(conditions["active"], conditions["multipliers"]))
    constraints = []
    for i, k in enumerate(problem.components):
        v = problem._raw(values[k.column], k.hinge)[0]
        mult = lam.get(("constraint", i), 0.0)
        constraints.append({"text": k.text, "output": k.column, "hinge": k.hinge, "side": k.side,
                            "limit": k.limit, "value": v, "margin": k.scaled(v),
                            "active": ("constraint", i) in lam,
                            "multiplier": float(mult) * problem.f0 / k.scale})
    bounds = []
    for j, var in enumerate(st.variables):
        at = ("lower" if xs[j] <= ACTIVE else "upper" if xs[j] >= 1.0 - ACTIVE else None)
        mult = lam.get((at, j), 0.0) if at else 0.0
        bounds.append({"variable": var.name, "at": at,
                       "multiplier": float(mult) * problem.f0 / problem.span[j]})
    names = [v.name for v in st.variables]
    sens = {col: dict(zip(names, map(float, v.gradient))) for col, v in values.items()}
    trail = []
    for iteration, x in enumerate(history):
        vals = problem.evaluate(x, False)
        trail.append({"iteration": iteration, "x": problem.physical(x).tolist(),
                      "objective": vals[st.objective].value,
                      "violation": problem.violation(x),
                      "values": {c: vals[c].value for c in vals}})
    kkt_out = {k: v for k, v in conditions.items() if k not in ("active", "multipliers")}
    return Result(status=status, message=message, x=problem.physical(xs), start=np.zeros(0),
                  objective=values[st.objective].value,
                  values={c: v.value for c, v in values.items()},
                  parts={c: {h: p[0] for h, p in v.parts.items()} for c, v in values.items()
                         if v.parts},
                  constraints=constraints, bounds=bounds, kkt=kkt_out, sensitivities=sens,
                  history=trail, evaluations=problem.evaluations,
                  gradients=problem.gradients, method=st.method)
