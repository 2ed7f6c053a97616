"""
Benchmarks.

``python -m flexure_sim.tools.bench`` (or ``flexure-sim bench``) prints a table and writes JSON.
Every figure is measured in the same run as its baseline.

Wall times are medians of several runs (7 for flexure_sim, 3 for the baseline).

- stage_step: the stage's response to a 1.35 um step over 0.05 s with the shipped
  integrator and step, against a converged reference (the same equations at steps of
  5 and 2.5 us, Richardson-extrapolated), next to scipy's solve_ivp Radau (rtol 1e-8,
  exact Jacobian, atol 1e-8 of each component's scale of motion) on the same equations.
- steps_per_s at the node's default step, and the cost of a step's parts.
- static_sweep: 1000 drive levels from 0 to the stroke.
- analyses: the stage's exact linearisation + modes + FRF at 1000 frequencies (goal < 0.1 s),
  and hyper-dual sensitivities of 4 outputs to 20 parameters (goal < 1 s).
- sweep (with --sweep): flexure-sim sweep's scaling on the stage tolerance study: designs
  per second in this process without Dask, on a LocalCluster of 1 and of 2 worker processes,
  the parallel efficiency and the overhead of a batch (a task).
- node (with --node): stage_node in fast mode (real-time factor) and real-time mode
  (missed ticks, tick jitter) at 1 kHz with all topics and recording on; the closed loop with
  pi_controller in a second process (missed ticks, jitter, command-to-applied latency:
  tools/closed_loop.py).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from .. import topics
from ..engine.config import load_mechanism
from ..engine import dynamics
from ..engine.solver import DEFAULT_STEP, Simulation

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

    walls = []
    for _ in range(REPEATS):  # the median of several runs, each from a fresh Simulation
        sim = Simulation(mech, dt=dt)
        sim.set_command(U_STEP)
        start = time.perf_counter()
        sim.step(n)
        walls.append(time.perf_counter() - start)
    wall = float(np.median(walls))
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
        "max_rel_error": float(np.max(np.abs(traj - ref)) / scale),
        "reference_rel_error_estimate": ref_err,
        "linearizations": sim.stats.linearizations,
        "iterations_per_step": sim.stats.iterations / sim.stats.steps,
        "output_final": float(traj[-1]),
    }
    if radau:
        result.update(_radau_baseline(mech, dt, n, ref))
        result["speedup"] = result["baseline_wall_s"] / wall
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

    def fun(t, y):
        return model.rhs(y, t, U_STEP)[0]

    def jac(t, y):
        return model.jacobian(y, t, U_STEP)

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
        [model.output_displacement(model.unpack(y, t, U_STEP)[0]) for y, t in zip(sol.y.T, sol.t)]
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
    sim = Simulation(mech, dt=dt)
    sim.set_command(U_STEP)
    sim.step(10)
    n = int(round(sim_seconds / dt))
    start = time.perf_counter()
    sim.step(n)
    wall = time.perf_counter() - start
    stats = sim.stats
    sim.stats = type(stats)()  # the timings below must not count as the run's work
    model = sim.model
    y = model.pack(sim.state)
    t, cmd = sim.state.t, sim.state.command
    reps = 2000
    force = timeit.timeit(lambda: model.rhs(y, t, cmd), number=reps) / reps
    jac = timeit.timeit(lambda: model.jacobian(y, t, cmd, load_gradient=True), number=50) / 50
    lin = timeit.timeit(lambda: dynamics.linearize(model, sim.data, y, t, cmd), number=20) / 20
    return {
        "steps_per_s": n / wall,
        "dt": dt,
        "rtf": sim_seconds / wall,
        "step_us": wall / n * 1e6,
        "force_evaluation_us": force * 1e6,
        "jacobian_us": jac * 1e6,
        "matrix_exponential_us": (lin - jac)
        * 1e6,  # both exponentials (phi-functions, drive work)
        "iterations_per_step": stats.iterations / stats.steps,
        "linearizations": stats.linearizations,
        "note": "a step is one force evaluation per remainder iteration plus 3 small "
        "matrix-vector products; the "
        "Jacobian and the matrix exponential (phi-functions) are paid per linearization "
        "(once per run for the stage), there is no linear solve",
    }


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


#: The 20 design parameters of the sensitivity benchmark (each hinge's h and D, four masses,
#: the notch material's E and the plate thickness t).
SENSITIVITY_PARAMETERS = (
    [f"hinges.{h}.stiffness.h" for h in "abcdefg"]
    + [f"hinges.{h}.stiffness.D" for h in "abcdefg"]
    + [f"bodies.body{i}.mass" for i in (2, 3, 4, 5)]
    + ["stiffness_models.notch.E", "stiffness_models.notch.t"]
)


def bench_analyses(frequencies: int = 1000) -> dict:
    """Modes + FRF of the stage at full stroke, and sensitivities of 4 outputs to 20 parameters."""
    from ..engine import linear
    from ..engine.design import Parameters
    from ..engine.sensitivity import OUTPUTS, sensitivities

    mech = load_mechanism("microstage")
    u = mech.drive.stroke[1]
    sim = Simulation(mech)
    sim.static(u)  # warm-up (compiled kernels)
    f = np.logspace(0, 5, frequencies)
    walls = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        model = linear.linearize(sim, u, wrenches=False)
        md = linear.modes(model)
        linear.frf(model, f, ["output"])
        walls.append(time.perf_counter() - start)
    params = Parameters("microstage")
    sens_walls = []
    for _ in range(BASELINE_REPEATS):
        start = time.perf_counter()
        sensitivities(params, SENSITIVITY_PARAMETERS, OUTPUTS, u)
        sens_walls.append(time.perf_counter() - start)
    return {
        "frequencies": frequencies,
        "modes_frf_wall_s": float(np.median(walls)),
        "first_mode_hz": float(md.frequencies[0]),
        "sensitivity_parameters": len(SENSITIVITY_PARAMETERS),
        "sensitivity_outputs": len(OUTPUTS),
        "sensitivity_wall_s": float(np.median(sens_walls)),
    }


def _stage_tolerance_study(designs: int, batch_size: int):
    """
    Return the shipped stage tolerance study with ``designs`` designs.

    The study is config/studies/stage_tolerance.yaml: the seven hinges' h with a normal error
    of 5 um each.
    """
    from ..engine.study import study_from_dict
    from .sweep_outputs import OUTPUTS

    data = {"mechanism": "microstage", "samples": designs, "seed": 20261124,
            "batch_size": batch_size, "input": 2.0e-6,
            "outputs": ["gain", "compression", "drive_force"],
            "parameters": [{"name": f"h_{c}", "path": f"hinges.{c}.stiffness.h",
                            "normal": {"std": 5e-6}} for c in "abcdefg"]}
    return study_from_dict(data, "stage_tolerance (bench)", OUTPUTS)


def bench_sweep(designs: int = 1000, batch_size: int = 50, overhead_tasks: int = 100) -> dict:
    """
    Designs per second of the stage tolerance study.

    In this process without Dask (``evaluate_batch``), and through ``run_study`` (tasks, Parquet
    parts, merge) on a LocalCluster of 1 and of 2 single-threaded worker processes, each started
    and warmed up (kernels loaded) outside the timing. Parallel efficiency: rate(2) / (2 rate(1)).
    Batch overhead: wall time per task of ``overhead_tasks`` one-design batches on the 1-worker
    cluster, minus the in-process time per design.
    """
    import logging
    import tempfile

    from distributed import Client, LocalCluster

    from .sweep_outputs import evaluate_batch
    from .sweep_run import run_study

    study = _stage_tolerance_study(designs, batch_size)
    evaluate_batch(study, 0, 5)  # warm-up
    start = time.perf_counter()
    evaluate_batch(study, 0, designs)
    serial = time.perf_counter() - start
    res: dict = {"designs": designs, "batch_size": batch_size,
                 "in_process_designs_per_s": designs / serial}
    with tempfile.TemporaryDirectory() as tmp:
        for n in (1, 2):
            start = time.perf_counter()
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
            with cluster, Client(cluster) as client:
                client.wait_for_workers(n)
                res[f"cluster_start_s_{n}"] = time.perf_counter() - start
                client.run(evaluate_batch, study, 0, 2)  # every worker loads its kernels
                start = time.perf_counter()
                run_study(study, Path(tmp) / f"w{n}.parquet", client=client)
                res[f"designs_per_s_{n}_workers"] = designs / (time.perf_counter() - start)
                if n == 1:
                    one = _stage_tolerance_study(overhead_tasks, 1)
                    start = time.perf_counter()
                    run_study(one, Path(tmp) / "overhead.parquet", client=client)
                    per_task = (time.perf_counter() - start) / overhead_tasks
                    res["batch_overhead_s"] = per_task - serial / designs
    res["parallel_efficiency_2_workers"] = (res["designs_per_s_2_workers"]
                                            / (2 * res["designs_per_s_1_workers"]))
    return res


#: wake_spin of the second real-time run: the CPU / punctuality trade-off of a short spin.
LOW_WAKE_SPIN_S = 2e-4
#: Rate of the drive-command flood of the last real-time run (another process, tools/flood.py).
FLOOD_HZ = 10000.0
#: monitor_rate of the second closed-loop run (Hz).
MONITOR_RATE = 100.0
#: Topics a controller would subscribe to, for the real-time runs next to a subscriber.
CONTROLLER_TOPICS = (topics.OUTPUT, topics.DRIVE_FORCE, topics.hinge_compression("a"))


def bench_node(duration: float = 30.0) -> dict:
    """
    stage_node on the stage at 1 kHz, all topics, recording on (tools/measure.py).

    Fast mode; real-time mode with the defaults; with a short wake_spin; and next to a controller
    process (an rclpy node subscribed to three topics at 1 kHz each), with the default
    stepping-thread niceness and with none.
    """
    from . import closed_loop, measure  # needs ROS 2

    def realtime(subscribe=False, flood_hz=0.0, **params) -> dict:
        return measure.run_node("realtime", duration, 1000.0, DEFAULT_STEP, True, subscribe,
                                params={k: repr(v) for k, v in params.items()},
                                flood_hz=flood_hz)

    fast = measure.run_node("fast", min(duration, 10.0), 1000.0, DEFAULT_STEP, True, False)
    default = realtime()
    runs = {
        "realtime": default,
        "realtime_low_spin": realtime(wake_spin=LOW_WAKE_SPIN_S),
        "realtime_controller": realtime(list(CONTROLLER_TOPICS)),
        "realtime_controller_nice0": realtime(list(CONTROLLER_TOPICS), stepping_nice=0),
        "realtime_flood": realtime(flood_hz=FLOOD_HZ),
        # pi_controller in a second process closing the loop on output/measured (issue 12).
        "realtime_closed_loop": closed_loop.run(duration),
        # The same with the monitoring topics at 100 Hz (control topics still every tick).
        "realtime_closed_loop_monitor100": closed_loop.run(
            duration, params={"monitor_rate": repr(MONITOR_RATE)}),
    }
    return {
        "fast_rtf": fast["real_time_factor"],
        "missed_tick_fraction": default["missed_fraction"],
        "jitter_p50_s": default["jitter_p50_s"],
        "jitter_p99_s": default["jitter_p99_s"],
        "max_late_s": 1e-6 * default["max_late_us"],
        "realtime_rtf": default["real_time_factor"],
        "flood_missed_tick_fraction": runs["realtime_flood"]["missed_fraction"],
        "flood_command_time_us": runs["realtime_flood"]["command_time_mean_us"],
        "closed_loop_missed_tick_fraction": runs["realtime_closed_loop"]["missed_fraction"],
        "closed_loop_applied_next_tick_fraction":
            runs["realtime_closed_loop"]["applied_next_tick_fraction"],
        "closed_loop_monitor100_missed_tick_fraction":
            runs["realtime_closed_loop_monitor100"]["missed_fraction"],
        "fast": fast,
        **runs,
    }


def machine() -> dict:
    import numba
    import scipy

    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "load_average": list(os.getloadavg()),
    }


def print_table(res: dict) -> None:
    s = res["stage_step"]
    print(f"machine: {res['machine']['processor']}, {res['machine']['cpus']} cpus, "
          f"load {', '.join(f'{x:.2f}' for x in res['machine']['load_average'])}")
    print("\nstage step response, 1.35 um, 0.05 s simulated")
    print(f"  flexure_sim (exp. trapezoidal, dt {s['dt']:g} s): wall {s['wall_s'] * 1e3:8.2f} ms  "
          f"RTF {s['rtf']:7.1f}  max rel error {s['max_rel_error']:.2e}")
    if "baseline_wall_s" in s:
        print(
            "  scipy Radau (rtol 1e-8, exact J):           wall "
            f"{s['baseline_wall_s'] * 1e3:8.2f} ms  "
            f"RTF {DURATION / s['baseline_wall_s']:7.2f}  max rel error "
            f"{s['baseline_max_rel_error']:.2e}"
        )
        print(
            f"  speedup: {s['speedup']:.1f}x   (reference error estimate "
            f"{s['reference_rel_error_estimate']:.1e})"
        )
    c = res["step_cost"]
    print(f"\nsteps per second at dt {c['dt']:g} s: {c['steps_per_s']:,.0f}  (RTF {c['rtf']:.1f})")
    print(
        f"  per step {c['step_us']:.2f} us ({c['iterations_per_step']:.2f} iterations); force "
        "evaluation "
        f"{c['force_evaluation_us']:.2f} us; per linearization: Jacobian {c['jacobian_us']:.0f} "
        "us, "
        f"matrix exponential {c['matrix_exponential_us']:.0f} us"
    )
    w = res["static_sweep"]
    print(f"\nstatic sweep, {w['levels']} levels over the stroke: {w['wall_s'] * 1e3:.1f} ms "
          f"({w['newton_iterations']} Newton iterations)")
    a = res.get("analyses")
    if a:
        print(f"\nanalyses: linearisation + modes + FRF at {a['frequencies']} frequencies "
              f"{a['modes_frf_wall_s'] * 1e3:.1f} ms (goal < 100 ms); sensitivities of "
              f"{a['sensitivity_outputs']} outputs to {a['sensitivity_parameters']} parameters "
              f"{a['sensitivity_wall_s'] * 1e3:.0f} ms (goal < 1000 ms)")
    if "sweep" in res:
        sw = res["sweep"]
        print(f"\nsweep, stage tolerance study, {sw['designs']} designs in batches of "
              f"{sw['batch_size']}: in-process {sw['in_process_designs_per_s']:.0f} designs/s")
        print(f"  LocalCluster, 1 worker {sw['designs_per_s_1_workers']:.0f} designs/s, 2 workers "
              f"{sw['designs_per_s_2_workers']:.0f} designs/s (parallel efficiency "
              f"{sw['parallel_efficiency_2_workers']:.2f})")
        print(f"  batch overhead {sw['batch_overhead_s'] * 1e3:.1f} ms per task; cluster start "
              f"{sw['cluster_start_s_2']:.1f} s (2 workers)")
    if "node" in res:
        nd = res["node"]
        print(
            "\nstage_node at 1 kHz, all topics, recording on: fast-mode RTF "
            f"{nd.get('fast_rtf', float('nan')):.2f}; "
            f"real-time missed ticks {nd.get('missed_tick_fraction', float('nan')):.4%}, "
            f"jitter p50 {nd.get('jitter_p50_s', float('nan')) * 1e6:.0f} us, "
            f"p99 {nd.get('jitter_p99_s', float('nan')) * 1e6:.0f} us"
        )
        for key in (
            "realtime",
            "realtime_low_spin",
            "realtime_controller",
            "realtime_controller_nice0",
            "realtime_flood",
        ):
            r = nd.get(key)
            if r:
                print(
                    f"  real-time, wake_spin {r['wake_spin_s'] * 1e3:.2f} ms, "
                    f"stepping nice {r['stepping_nice']}"
                    + (f", subscriber on {r['subscribed']}" if r["subscribed"] else "")
                    + (
                        f", {r['flood_sent_per_s']:.0f} commands/s from another process "
                        f"({r['command_time_mean_us'] or float('nan'):.1f} us each)"
                        if r.get("flood_hz")
                        else ""
                    )
                    + f": missed {r['missed_ticks']} of {r['paced_ticks']} ticks "
                    f"({r['missed_fraction']:.3%}), "
                    f"node CPU {r['node_cpu_cores'] or float('nan'):.2f} cores, "
                    f"worst lateness {r['max_late_us'] / 1e3:.1f} ms"
                )
        from .closed_loop import summary

        for key, label in (("realtime_closed_loop", ""),
                           ("realtime_closed_loop_monitor100",
                            f" [monitor_rate {MONITOR_RATE:g} Hz]")):
            if nd.get(key):
                print("  " + summary(nd[key]) + label)


def run(args: argparse.Namespace) -> dict:
    res: dict = {
        "machine": machine(),
        "command": " ".join(["python -m flexure_sim.tools.bench", *sys.argv[1:]]),
    }
    res["stage_step"] = bench_stage_step(args.dt, radau=not args.no_baseline)
    res["step_cost"] = bench_step_cost(args.dt)
    res["steps_per_s"] = res["step_cost"]["steps_per_s"]
    res["static_sweep"] = bench_static_sweep()
    res["analyses"] = bench_analyses()
    if args.sweep:
        res["sweep"] = bench_sweep(args.sweep_designs)
    if args.node:
        res["node"] = bench_node(args.node_seconds)
    return res


def build_parser(parser: Optional[argparse.ArgumentParser] = None) -> argparse.ArgumentParser:
    parser = parser or argparse.ArgumentParser(
        prog="python -m flexure_sim.tools.bench", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument(
        "--dt", type=float, default=DEFAULT_STEP, help=f"step (s), default {DEFAULT_STEP:g}"
    )
    parser.add_argument(
        "--json",
        type=Path,
        default=Path("bench.json"),
        help="where to write the JSON (default bench.json)",
    )
    parser.add_argument("--no-baseline", action="store_true", help="skip the scipy Radau baseline")
    parser.add_argument("--sweep", action="store_true",
                        help="also measure flexure-sim sweep on LocalClusters of 1 and 2 workers")
    parser.add_argument("--sweep-designs", type=int, default=1000,
                        help="designs of the sweep measurement (default 1000)")
    parser.add_argument(
        "--node", action="store_true", help="also measure stage_node (needs ROS 2)"
    )
    parser.add_argument(
        "--node-seconds", type=float, default=30.0, help="real-time node measurement length (s)"
    )
    return parser


def handle(args: argparse.Namespace) -> int:
    res = run(args)
    print_table(res)
    args.json.write_text(json.dumps(res, indent=2))
    print(f"\nJSON written to {args.json}")
    return 0


def register(subparsers) -> None:
    """``flexure-sim bench``."""
    p = subparsers.add_parser(
        "bench", help="benchmarks (speed against scipy Radau, steps/s, static sweep)"
    )
    build_parser(p)
    p.set_defaults(handler=handle)


def main(argv: Optional[Sequence[str]] = None) -> int:
    return handle(build_parser().parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
