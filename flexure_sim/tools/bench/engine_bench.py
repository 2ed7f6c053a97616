"""
Engine benchmarks of ``flexure-sim bench``: the stage's step response, step cost, static sweep.

- stage_step: the stage's response to a 1.35 um step over 0.05 s with the shipped integrator
  and step, against a converged reference (Richardson-extrapolated), next to scipy's solve_ivp
  Radau on the same equations.
- step_cost: steps per second at the node's default step, and the cost of a step's parts.
- static_sweep: 1000 drive levels from 0 to the stroke.
"""
from __future__ import annotations

import time

import numpy as np

from flexure_sim.engine.solver import integrator as dynamics
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import DEFAULT_STEP, Simulation

U_STEP = 1.35e-6
DURATION = 0.05
#: Timed runs whose median is reported (shared, noisy machines).
REPEATS = 7
BASELINE_REPEATS = 3


def _output_trajectory(sim: Simulation, every: int, n_samples: int) -> np.ndarray:
    """Output displacement after every ``every`` steps, n_samples times."""
    out = np.empty(n_samples)
    for k in range(n_samples):
        sim.step(every)
        out[k] = sim.model.output_displacement(sim.state.z)
    return out


def reference_trajectory(mech, dt: float, duration: float) -> tuple[np.ndarray, float]:
    """
    Converged output on the grid k*dt.

    Steps dt/20 and dt/40, Richardson-extrapolated for the method's second order. Returns the
    trajectory and its estimated error (the extrapolation's correction, relative to the largest
    output).
    """
    n = int(round(duration / dt))
    runs = []
    for sub in (20, 40):
        sim = Simulation(mech, dt=dt / sub)
        sim.set_command(U_STEP)
        runs.append(_output_trajectory(sim, sub, n))
    coarse, fine = runs
    ref = fine + (fine - coarse) / 3.0
    return ref, float(np.max(np.abs(fine - ref)) / np.max(np.abs(ref)))


def bench_stage_step(dt: float = DEFAULT_STEP, radau: bool = True) -> dict:
    mech = load_mechanism("microstage")
    n = int(round(DURATION / dt))
    warm = Simulation(mech, dt=dt)  # compile / load the kernels outside the timing
    warm.set_command(U_STEP)
    warm.step(2)
    ref, ref_err = reference_trajectory(mech, dt, DURATION)

    def timed(energy: bool) -> tuple[float, Simulation]:
        walls = []
        for _ in range(REPEATS):  # the median of several runs, each from a fresh Simulation
            sim = Simulation(mech, dt=dt, energy=energy)
            sim.set_command(U_STEP)
            start = time.perf_counter()
            sim.step(n)
            walls.append(time.perf_counter() - start)
        return float(np.median(walls)), sim

    # Without the energy integrals (what stage_node runs, and what Radau computes), then with.
    wall_no_energy, _ = timed(False)
    wall, sim = timed(True)
    # Same run again, sampled, for the error (sampling costs time, so not timed).
    sampled = Simulation(mech, dt=dt)
    sampled.set_command(U_STEP)
    traj = _output_trajectory(sampled, 1, n)
    scale = np.max(np.abs(ref))
    result = {
        "dt": dt,
        "duration": DURATION,
        "steps": n,
        "wall_s": wall,
        "rtf": DURATION / wall,
        "wall_no_energy_s": wall_no_energy,
        # the energy integrals' cost: the run with them over the motion-only run (goal <= 1.5)
        "energy_factor": wall / wall_no_energy,
        "max_rel_error": float(np.max(np.abs(traj - ref)) / scale),
        "reference_rel_error_estimate": ref_err,
        "linearizations": sim.stats.linearizations,
        "iterations_per_step": sim.stats.iterations / sim.stats.steps,
        "output_final": float(traj[-1]),
    }
    if radau:
        result.update(_radau_baseline(mech, dt, n, ref))
        result["speedup"] = result["baseline_wall_s"] / wall
        result["speedup_no_energy"] = result["baseline_wall_s"] / wall_no_energy
    return result


def _radau_baseline(mech, dt: float, n: int, ref: np.ndarray) -> dict:
    from scipy.integrate import solve_ivp

    sim = Simulation(mech, dt=dt)
    sim.set_command(U_STEP)
    model = sim.model
    y0 = model.pack(sim.state)
    # atol: 1e-8 of each component's scale of motion in this run.
    scale = np.concatenate(
        [np.where(sim.part.free % 3 == 2, 1e-3, 1e-5), np.where(sim.part.free % 3 == 2, 1.0, 1e-2)]
    )
    if sim.drive is not None:
        scale = np.append(scale, U_STEP)
    atol = 1e-8 * scale

    command = model.drives.kernel_command(sim.state.command)

    def fun(t, y):
        return model.rhs(y, t, command)[0]

    def jac(t, y):
        return model.jacobian(y, t, command)

    grid = dt * np.arange(1, n + 1)
    walls = []
    for _ in range(BASELINE_REPEATS):
        start = time.perf_counter()
        sol = solve_ivp(
            fun, (0.0, DURATION), y0, method="Radau", jac=jac, rtol=1e-8, atol=atol, t_eval=grid
        )
        walls.append(time.perf_counter() - start)
    wall = float(np.median(walls))
    out = np.array(
        [model.output_displacement(model.unpack(y, t, command)[0]) for y, t in zip(sol.y.T, sol.t)]
    )
    return {
        "baseline": "scipy solve_ivp Radau, rtol 1e-8, exact Jacobian",
        "baseline_wall_s": wall,
        "baseline_max_rel_error": float(np.max(np.abs(out - ref)) / np.max(np.abs(ref))),
        "baseline_nfev": int(sol.nfev),
        "baseline_njev": int(sol.njev),
    }


def bench_step_cost(dt: float = DEFAULT_STEP, sim_seconds: float = 1.0) -> dict:
    import timeit

    mech = load_mechanism("microstage")
    n = int(round(sim_seconds / dt))
    walls = {}
    for energy in (False, True):    # the one with the energies last: its parts are timed below
        sim = Simulation(mech, dt=dt, energy=energy)
        sim.set_command(U_STEP)
        sim.step(10)
        start = time.perf_counter()
        sim.step(n)
        walls[energy] = time.perf_counter() - start
    wall = walls[True]
    stats = sim.stats
    sim.stats = type(stats)()  # the timings below must not count as the run's work
    model = sim.model
    y = model.pack(sim.state)
    t, cmd = sim.state.t, model.drives.kernel_command(sim.state.command)
    reps = 2000
    force = timeit.timeit(lambda: model.rhs(y, t, cmd), number=reps) / reps
    jac = timeit.timeit(lambda: model.tangent(y, t, cmd), number=50) / 50
    lin = timeit.timeit(lambda: dynamics.linearize(model, sim.data, y, t, cmd), number=20) / 20
    bare = Simulation(mech, dt=dt, energy=False)
    lin_bare = timeit.timeit(lambda: dynamics.linearize(bare.model, bare.data, y, t, cmd),
                             number=20) / 20
    piezo_us, piezo_plain_us = _piezo_step_cost()
    return {
        "piezo_step_us": piezo_us,
        "piezo_plain_step_us": piezo_plain_us,
        "steps_per_s": n / wall,
        "dt": dt,
        "rtf": sim_seconds / wall,
        "step_us": wall / n * 1e6,
        "step_no_energy_us": walls[False] / n * 1e6,
        "energy_step_factor": walls[True] / walls[False],
        "linearization_us": lin * 1e6,
        "linearization_no_energy_us": lin_bare * 1e6,
        "force_evaluation_us": force * 1e6,
        "jacobian_us": jac * 1e6,
        # the phi-functions' exponential and the energy integrals' matrices
        "matrix_exponential_us": (lin - jac) * 1e6,
        "iterations_per_step": stats.iterations / stats.steps,
        "linearizations": stats.linearizations,
        "note": "a step is one force evaluation per remainder iteration plus 3 small "
        "matrix-vector products; the "
        "Jacobian and the matrix exponential (phi-functions) are paid per linearization "
        "(once per run for the stage), there is no linear solve",
    }


def _piezo_step_cost(n: int = 10000) -> tuple[float, float]:
    """
    Wall time per step (us) of config/examples/piezo_stage.yaml, with and without its actuator.

    The same drive with ``actuator`` removed and the command scaled by the nominal gain is the
    plain displacement drive; both are stepped n steps after a warm-up.
    """
    import dataclasses

    from flexure_sim.engine.mechanism.builtins import builtin_dir
    from flexure_sim.engine.mechanism.parts import Drive

    mech = load_mechanism(builtin_dir() / "examples" / "piezo_stage.yaml")
    drive = mech.drives[0]
    plain = dataclasses.replace(mech, constraints=tuple(
        dataclasses.replace(c, actuator=None) if isinstance(c, Drive) else c
        for c in mech.constraints))
    out = []
    for m, command in ((mech, 60.0), (plain, 60.0 * drive.actuator.gain)):
        sim = Simulation(m)
        sim.set_command(command)
        sim.step(100)
        start = time.perf_counter()
        sim.step(n)
        out.append((time.perf_counter() - start) / n * 1e6)
    return out[0], out[1]


def bench_static_sweep(levels: int = 1000) -> dict:
    mech = load_mechanism("microstage")
    sim = Simulation(mech)
    inputs = np.linspace(mech.drive.stroke[0], mech.drive.stroke[1], levels)
    sim.static_sweep(inputs[:3])  # warm-up
    start = time.perf_counter()
    sweep = sim.static_sweep(inputs)
    wall = time.perf_counter() - start
    return {
        "levels": levels,
        "wall_s": wall,
        "newton_iterations": sweep.iterations,
        "gain_at_full_stroke": float(sweep.outputs[-1] / inputs[-1]),
    }
