"""
Benchmarks.

``python -m flexure_sim.tools.bench.benchmarks`` (or ``flexure-sim bench``) prints a table and
writes JSON. Every figure is measured in the same run as its baseline.

Wall times are medians of several runs (7 for flexure_sim, 3 for the baseline).

- stage_step: the stage's response to a 1.35 um step over 0.05 s with the shipped
  integrator and step, against a converged reference (the same equations at steps of
  5 and 2.5 us, Richardson-extrapolated), next to scipy's solve_ivp Radau (rtol 1e-8,
  exact Jacobian, atol 1e-8 of each component's scale of motion) on the same equations.
- steps_per_s at the node's default step, and the cost of a step's parts.
- static_sweep: 1000 drive levels from 0 to the stroke.
- spatial: the stage opened in 3-D and the tip-tilt stage stepped by the spatial engine (wall
  time, real-time factor, error against a converged reference, next to the planar engine on
  the same run; tools/bench/spatial_bench.py).
- analyses: the stage's exact linearisation + modes + FRF at 1000 frequencies (goal < 0.1 s),
  and hyper-dual sensitivities of 4 outputs to 20 parameters (goal < 1 s).
- fe_hinge: one finite-element hinge's solve (goal < 5 s) and its cached load, alone and in
  the stage with model: fe hinges (goal < 10 ms; tools/bench/fe_bench.py).
- optimize: flexure-sim optimize on the stage over its 7 hinge thicknesses (goal: converged
  in < 10 s), and its time in exact gradients.
- recorder: the CPU time a message of the recording's MCAP writer against the mcap library's
  ``Writer.add_message`` (tools/bench/recorder_bench.py).
- sweep (with --sweep): flexure-sim sweep's scaling on the stage tolerance study: designs
  per second in this process without Dask, on a LocalCluster of 1 and of 2 worker processes,
  the parallel efficiency and the overhead of a batch (a task).
- node (with --node): stage_node's tick and its overhead factor, real time alone and the
  closed loop with pi_controller in a second process at 1, 2 and 4 kHz, the floor of an rclpy
  ping-pong, fast mode, a command flood (tools/bench/node_bench.py).

The engine benchmarks live in ``bench_engine``, the analyses and the sweep in
``bench_studies``; this module holds the node benchmark, the table and the command.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from flexure_sim.engine.solver.simulation import DEFAULT_STEP
from flexure_sim.tools.bench.spatial_bench import bench_spatial, print_spatial
from flexure_sim.tools.bench.engine_bench import (
    bench_static_sweep, bench_stage_step, bench_step_cost,
)
from flexure_sim.tools.bench.fe_bench import bench_fe_hinge
from flexure_sim.tools.bench.recorder_bench import bench_recorder, print_recorder
from flexure_sim.tools.bench.study_bench import bench_analyses, bench_optimize, bench_sweep


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
    print(f"  flexure_sim (exp. trapezoidal, dt {s['dt']:g} s), motion only (as Radau): wall "
          f"{s['wall_no_energy_s'] * 1e3:8.2f} ms  max rel error {s['max_rel_error']:.2e}")
    print(f"  flexure_sim with the energy integrals (the default):  wall "
          f"{s['wall_s'] * 1e3:8.2f} ms  ({s['wall_s'] / s['wall_no_energy_s']:.2f}x the "
          "motion alone)")
    if "baseline_wall_s" in s:
        print(f"  scipy Radau (rtol 1e-8, exact J), motion only:      wall "
              f"{s['baseline_wall_s'] * 1e3:8.2f} ms  max rel error "
              f"{s['baseline_max_rel_error']:.2e}")
        print(f"  speedup over Radau, like for like (motion only): {s['speedup_no_energy']:.1f}x;"
              f" with the energy integrals, which Radau does not compute: {s['speedup']:.1f}x "
              f"(reference error estimate {s['reference_rel_error_estimate']:.1e})")
    c = res["step_cost"]
    print(f"\nsteps per second at dt {c['dt']:g} s: {c['steps_per_s']:,.0f}  (RTF {c['rtf']:.1f})")
    print(
        f"  per step {c['step_us']:.2f} us ({c['iterations_per_step']:.2f} iterations); force "
        "evaluation "
        f"{c['force_evaluation_us']:.2f} us; per linearization: Jacobian {c['jacobian_us']:.0f} "
        "us, "
        f"matrix exponential {c['matrix_exponential_us']:.0f} us"
    )
    print(f"  piezo actuator (config/examples/piezo_stage.yaml): per step "
          f"{c['piezo_step_us']:.2f} us, the same drive without it "
          f"{c['piezo_plain_step_us']:.2f} us")
    print(f"  without the energy integrals: per step {c['step_no_energy_us']:.2f} us, per "
          f"linearization {c['linearization_no_energy_us']:.0f} us (with: "
          f"{c['linearization_us']:.0f} us)")
    print_spatial(res["spatial"])
    w = res["static_sweep"]
    print(f"\nstatic sweep, {w['levels']} levels over the stroke: {w['wall_s'] * 1e3:.1f} ms "
          f"({w['newton_iterations']} Newton iterations)")
    a = res.get("analyses")
    if a:
        print(f"\nanalyses: linearisation + modes + FRF at {a['frequencies']} frequencies "
              f"{a['modes_frf_wall_s'] * 1e3:.1f} ms (goal < 100 ms); sensitivities of "
              f"{a['sensitivity_outputs']} outputs to {a['sensitivity_parameters']} parameters "
              f"{a['sensitivity_wall_s'] * 1e3:.0f} ms (goal < 1000 ms)")
    fe = res.get("fe_hinge")
    if fe:
        print(f"\nfinite-element hinge (stage notch, resolution {fe['resolution']}): solve "
              f"{fe['solve_s']:.2f} s (goal < 5 s); cached stiffness "
              f"{fe['cached_stiffness_s'] * 1e3:.2f} ms, stage with 7 such hinges loaded "
              f"{fe['cached_stage_load_s'] * 1e3:.1f} ms (goal < 10 ms)")
    o = res.get("optimize")
    if o:
        print(f"\noptimize, the stage's first mode over its {o['variables']} hinge thicknesses: "
              f"{o['status']} in {o['wall_s']:.2f} s (goal < 10 s), {o['iterations']} "
              f"iterations, {o['evaluations']} evaluations of which {o['gradient_evaluations']} "
              f"with exact gradients ({o['gradient_s']:.2f} s; values only {o['values_s']:.2f} "
              f"s); first mode {o['start_objective']:.2f} -> {o['objective']:.2f} Hz, KKT "
              f"stationarity {o['stationarity']:.1g}")
    if "recorder" in res:
        print_recorder(res["recorder"])
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
        from flexure_sim.tools.bench.node_bench import print_node

        print_node(res["node"])


def run(args: argparse.Namespace) -> dict:
    res: dict = {
        "machine": machine(),
        "command": " ".join(["python -m flexure_sim.tools.bench.benchmarks", *sys.argv[1:]]),
    }
    res["stage_step"] = bench_stage_step(args.dt, radau=not args.no_baseline)
    res["step_cost"] = bench_step_cost(args.dt)
    res["steps_per_s"] = res["step_cost"]["steps_per_s"]
    res["static_sweep"] = bench_static_sweep()
    res["spatial"] = bench_spatial(args.dt)
    res["analyses"] = bench_analyses()
    res["fe_hinge"] = bench_fe_hinge()
    res["optimize"] = bench_optimize()
    res["recorder"] = bench_recorder()
    if args.sweep:
        res["sweep"] = bench_sweep(args.sweep_designs)
    if args.node:
        from flexure_sim.tools.bench.node_bench import bench_node  # needs ROS 2

        res["node"] = bench_node(args.node_seconds, res["step_cost"]["step_no_energy_us"])
    return res


def build_parser(parser: Optional[argparse.ArgumentParser] = None) -> argparse.ArgumentParser:
    parser = parser or argparse.ArgumentParser(
        prog="python -m flexure_sim.tools.bench.benchmarks", description=__doc__.split("\n\n")[0]
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
