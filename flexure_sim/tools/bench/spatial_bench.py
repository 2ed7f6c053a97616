"""
Spatial engine benchmarks of ``flexure-sim bench``: 3-D stepping speed at the planar accuracy.

- stage_3d: the micropositioning stage opened in 3-D (24 free coordinates against the planar
  12), its 1.35 um step response over 0.05 s at the shipped step: wall time, real-time factor,
  the output's error against a converged reference (the 3-D engine at dt/20 and dt/40,
  Richardson-extrapolated) next to the planar engine's error and wall time on the same run,
  and the largest out-of-plane coordinate (0: nothing leaves the plane).
- tiptilt: config/tiptilt_stage.yaml, a 10 um step of stack p1, the same figures for its tip;
  and at the planar accuracy: the step halved from dt until the tip's error is no larger than
  the planar stage's at dt (at most ``HALVINGS`` times), with the error and real-time factor
  of every step tried.
- steady: steps per second over 1 s simulated once linearized (what a long run or the node
  sees), both engines.
- call costs: the wall time of one ``step(1)`` and one ``step(10)`` call once linearized (best
  of 7 x 500 calls), both engines: a call's fixed cost is what a short call adds to its steps.
- linearization: the cost of one exact Jacobian (the complex step of the compiled force
  chain) and of the phi-functions' exponentials, paid once per run here.
"""
from __future__ import annotations

import time

import numpy as np

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.mechanism.spatial_loader import load_spatial
from flexure_sim.engine.solver import spatial_integrator
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
from flexure_sim.tools.bench.engine_bench import REPEATS, U_STEP

DURATION = 0.05
#: Steps per call of the call costs: one (a controller stepping the simulation itself), ten
#: (a 1 kHz node tick at the shipped step).
CALL_STEPS = (1, 10)
#: How many times the tip-tilt stage's step is halved at most to reach the planar accuracy.
HALVINGS = 6


def _trajectory(make, command, dt: float, every: int, n: int, output) -> np.ndarray:
    sim = make(dt)
    sim.set_command(command)
    out = np.empty(n)
    for k in range(n):
        sim.step(every)
        out[k] = output(sim)
    return out


def _run(make, command, dt: float, output) -> dict:
    """Wall time (median of REPEATS fresh runs), and the error against a converged reference."""
    n = int(round(DURATION / dt))
    warm = make(dt)
    warm.set_command(command)
    warm.step(2)
    walls = []
    for _ in range(REPEATS):
        sim = make(dt)
        sim.set_command(command)
        start = time.perf_counter()
        sim.step(n)
        walls.append(time.perf_counter() - start)
    coarse = _trajectory(make, command, dt / 20, 20, n, output)
    fine = _trajectory(make, command, dt / 40, 40, n, output)
    ref = fine + (fine - coarse) / 3.0
    traj = _trajectory(make, command, dt, 1, n, output)
    wall = float(np.median(walls))
    start = time.perf_counter()
    sim.step(10 * n)
    steady = (time.perf_counter() - start) / (10 * n)
    calls = {f"call_{k}_us": 1e6 * _call(sim, k) for k in CALL_STEPS}
    return {"steps": n, "steady_step_us": steady * 1e6, "steady_rtf": dt / steady, **calls,
            "wall_s": wall, "rtf": DURATION / wall, "step_us": wall / n * 1e6,
            "max_rel_error": float(np.max(np.abs(traj - ref)) / np.max(np.abs(ref))),
            "reference_rel_error_estimate": float(np.max(np.abs(fine - ref))
                                                  / np.max(np.abs(ref))),
            "linearizations": sim.stats.linearizations,
            "iterations_per_step": sim.stats.iterations / sim.stats.steps, "final": sim}


def _call(sim, steps: int, calls: int = 500, rounds: int = 7) -> float:
    """Return the wall time (s) of one ``sim.step(steps)`` call: the best of ``rounds``."""
    best = float("inf")
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(calls):
            sim.step(steps)
        best = min(best, (time.perf_counter() - start) / calls)
    return best


def at_accuracy(make, command, dt: float, output, target: float) -> dict:
    """
    Return the steps dt, dt/2, ... tried until the error is at most ``target``, and the first.

    Each row: the step, its max rel error and real-time factors (``_run``); ``reached``: the
    first row within ``target``, or None if ``HALVINGS`` halvings did not reach it.
    """
    rows = []
    for k in range(HALVINGS + 1):
        res = _run(make, command, dt / 2**k, output)
        res.pop("final")
        rows.append({"dt": dt / 2**k, "max_rel_error": res["max_rel_error"], "rtf": res["rtf"],
                     "steady_rtf": res["steady_rtf"]})
        if res["max_rel_error"] <= target:
            return {"target": target, "steps": rows, "reached": rows[-1]}
    return {"target": target, "steps": rows, "reached": None}


def bench_spatial(dt: float) -> dict:
    """Return the figures of the module docstring."""
    stage3d = load_spatial("microstage")
    planar = load_mechanism("microstage")
    res3 = _run(lambda h: SpatialSimulation(stage3d, dt=h), U_STEP, dt,
                lambda s: s.model.output_values(s.state.z)[0])
    res2 = _run(lambda h: Simulation(planar, dt=h, energy=False), U_STEP, dt,
                lambda s: s.model.output_displacement(s.state.z))
    z = res3.pop("final").state.z.reshape(-1, 6)
    res2.pop("final")
    res3["max_out_of_plane"] = float(np.max(np.abs(z[:, 2:5])))
    res3["planar"] = res2
    tip = load_spatial("tiptilt_stage")
    tip_sim = (lambda h: SpatialSimulation(tip, dt=h))
    tip_out = (lambda s: s.model.output_values(s.state.z)[0])
    tt = _run(tip_sim, [1e-5, 0.0, 0.0], dt, tip_out)
    tt.pop("final")
    tt["at_planar_accuracy"] = at_accuracy(tip_sim, [1e-5, 0.0, 0.0], dt, tip_out,
                                           res2["max_rel_error"])
    sim = SpatialSimulation(stage3d, dt=dt)
    sim.set_command(U_STEP)
    sim.step(5)
    model, y = sim.model, sim.model.pack(sim.state)
    t, cmd = sim.state.t, model.actuator_command(sim.state.command)
    start = time.perf_counter()
    for _ in range(5):
        model.jacobian(y, t, cmd)
    jac = (time.perf_counter() - start) / 5
    start = time.perf_counter()
    for _ in range(5):
        spatial_integrator.linearize(model, sim.data, y, t, cmd)
    lin = (time.perf_counter() - start) / 5
    return {"dt": dt, "duration": DURATION, "stage_3d": res3, "tiptilt": tt,
            "jacobian_ms": jac * 1e3, "linearization_ms": lin * 1e3,
            "free_coordinates": len(model.part.free)}


def print_spatial(res: dict) -> None:
    """Print ``bench_spatial``'s figures."""
    s, p, t = res["stage_3d"], res["stage_3d"]["planar"], res["tiptilt"]
    print(f"\n3-D stepping (spatial engine), {res['duration']:g} s simulated at dt "
          f"{res['dt']:g} s")
    print(f"  stage in 3-D ({res['free_coordinates']} free coordinates): wall "
          f"{s['wall_s'] * 1e3:7.2f} ms  RTF {s['rtf']:6.1f}  per step {s['step_us']:.2f} us  "
          f"max rel error {s['max_rel_error']:.2e}  out of plane {s['max_out_of_plane']:.1g}")
    print(f"  the same stage planar (energy=False):    wall {p['wall_s'] * 1e3:7.2f} ms  "
          f"RTF {p['rtf']:6.1f}  per step {p['step_us']:.2f} us  max rel error "
          f"{p['max_rel_error']:.2e}")
    print(f"  tip-tilt stage, 10 um on p1, tip:        wall {t['wall_s'] * 1e3:7.2f} ms  "
          f"RTF {t['rtf']:6.1f}  per step {t['step_us']:.2f} us  max rel error "
          f"{t['max_rel_error']:.2e}")
    acc = t["at_planar_accuracy"]
    tried = ", ".join(f"{r['dt']:.3g} s: {r['max_rel_error']:.2e} (RTF {r['rtf']:.1f})"
                      for r in acc["steps"])
    reached = acc["reached"]
    print(f"  tip-tilt at the planar stage's accuracy ({acc['target']:.2e}): " + (
        f"dt {reached['dt']:.3g} s, RTF {reached['rtf']:.1f} (steady {reached['steady_rtf']:.1f})"
        if reached else "not reached") + f"; steps tried {tried}")
    print(f"  once linearized, {10 * s['steps']} steps: the stage in 3-D "
          f"{s['steady_step_us']:.2f} us per step (RTF {s['steady_rtf']:.1f}), planar "
          f"{p['steady_step_us']:.2f} us (RTF {p['steady_rtf']:.1f}), tip-tilt "
          f"{t['steady_step_us']:.2f} us (RTF {t['steady_rtf']:.1f})")
    print("  a call of 1 / 10 steps: the stage in 3-D " + ", planar ".join(
        f"{r['call_1_us']:.1f} / {r['call_10_us']:.1f} us" for r in (s, p))
          + f", tip-tilt {t['call_1_us']:.1f} / {t['call_10_us']:.1f} us")
    print(f"  per linearization of the 3-D stage: exact Jacobian (complex step) "
          f"{res['jacobian_ms']:.1f} ms, with the matrix exponential "
          f"{res['linearization_ms']:.1f} ms ({s['linearizations']} per run)")
