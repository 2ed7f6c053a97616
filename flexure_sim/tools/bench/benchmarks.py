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
- sweep (with --sweep): flexure-sim sweep's scaling on the stage tolerance study: designs
  per second in this process without Dask, on a LocalCluster of 1 and of 2 worker processes,
  the parallel efficiency and the overhead of a batch (a task).
- node (with --node): stage_node in fast mode (real-time factor) and real-time mode
  (missed ticks, tick jitter) at 1 kHz with all topics and recording on; the closed loop with
  pi_controller in a second process (missed ticks, jitter, command-to-applied latency:
  tools/bench/closed_loop.py).

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

from flexure_sim import topics
from flexure_sim.engine.solver.simulation import DEFAULT_STEP
from flexure_sim.tools.bench.spatial_bench import bench_spatial, print_spatial
from flexure_sim.tools.bench.engine_bench import (
    DURATION, bench_static_sweep, bench_stage_step, bench_step_cost,
)
from flexure_sim.tools.bench.fe_bench import bench_fe_hinge
from flexure_sim.tools.bench.study_bench import bench_analyses, bench_optimize, bench_sweep

#: wake_spin of the second real-time run: the CPU / punctuality trade-off of a short spin.
LOW_WAKE_SPIN_S = 2e-4
#: Rate of the drive-command flood of the last real-time run (another process,
# tools/bench/flood.py).
FLOOD_HZ = 10000.0
#: monitor_rate of the second closed-loop run (Hz).
MONITOR_RATE = 100.0
#: merge_late_ticks of the flood and closed-loop runs that merge late ticks.
MERGE_LATE_TICKS = 2
#: The closed loop with the stepping thread under SCHED_FIFO (`stepping_priority`), which
#: needs it to sleep between ticks (wake_spin at most half the period).
FIFO_PARAMS = {"stepping_priority": "50", "wake_spin": "0.0001"}
FIFO_LABEL = " [stepping_priority 50, wake_spin 0.1 ms]"
#: Topics a controller would subscribe to, for the real-time runs next to a subscriber.
CONTROLLER_TOPICS = (topics.OUTPUT, topics.DRIVE_FORCE, topics.hinge_compression("a"))


def bench_node(duration: float = 30.0) -> dict:
    """
    stage_node on the stage at 1 kHz, all topics, recording on (tools/bench/measure.py).

    Fast mode; real-time mode with the defaults; with a short wake_spin; and next to a controller
    process (an rclpy node subscribed to three topics at 1 kHz each), with the default
    stepping-thread niceness and with none; next to a command flood and in closed loop, each
    also with late ticks merged (``merge_late_ticks``).
    """
    from flexure_sim.tools.bench import closed_loop, measure  # needs ROS 2

    def realtime(subscribe=False, flood_hz=0.0, **params) -> dict:
        return measure.run_node("realtime", duration, 1000.0, DEFAULT_STEP, True, subscribe,
                                params={k: repr(v) for k, v in params.items()},
                                flood_hz=flood_hz)

    fast = measure.run_node("fast", min(duration, 10.0), 1000.0, DEFAULT_STEP, True, False)
    default = realtime()
    runs = {
        "realtime": default,
        # With the CPU wake-up latency request (cpu_latency_us 0: idle CPUs poll).
        "realtime_cpu_latency": realtime(cpu_latency_us=0),
        "realtime_low_spin": realtime(wake_spin=LOW_WAKE_SPIN_S),
        "realtime_controller": realtime(list(CONTROLLER_TOPICS)),
        "realtime_controller_nice0": realtime(list(CONTROLLER_TOPICS), stepping_nice=0),
        "realtime_flood": realtime(flood_hz=FLOOD_HZ),
        "realtime_flood_merge": realtime(flood_hz=FLOOD_HZ, merge_late_ticks=MERGE_LATE_TICKS),
        # pi_controller in a second process closing the loop on output/measured (issue 12).
        "realtime_closed_loop": closed_loop.run(duration),
        # The same with the monitoring topics at 100 Hz (control topics still every tick).
        "realtime_closed_loop_monitor100": closed_loop.run(
            duration, params={"monitor_rate": repr(MONITOR_RATE)}),
        # With the CPU wake-up latency request; and with it and a short wake_spin.
        "realtime_closed_loop_cpu_latency": closed_loop.run(
            duration, params={"cpu_latency_us": "0"}),
        "realtime_closed_loop_low_spin": closed_loop.run(
            duration, params={"cpu_latency_us": "0", "wake_spin": repr(LOW_WAKE_SPIN_S)}),
        # The stepping thread and the middleware's threads at the other processes' niceness.
        "realtime_closed_loop_nice0": closed_loop.run(duration, params={"stepping_nice": "0"}),
        # Under SCHED_FIFO (the thread then sleeps between ticks); and both next to a
        # CPU-bound process at niceness 19.
        "realtime_closed_loop_fifo": closed_loop.run(duration, params=FIFO_PARAMS),
        "realtime_closed_loop_hog": closed_loop.run(duration, hog=True),
        "realtime_closed_loop_fifo_hog": closed_loop.run(duration, params=FIFO_PARAMS,
                                                         hog=True),
        # Every tick, late ticks merged: simulated time stays with wall time.
        "realtime_closed_loop_merge": closed_loop.run(
            duration, params={"merge_late_ticks": repr(MERGE_LATE_TICKS)}),
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
        "flood_commands_lost": runs["realtime_flood"].get("flood_commands_lost"),
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
        print(f"  without the energy integrals (energy=False, as stage_node): wall "
              f"{s['wall_no_energy_s'] * 1e3:.2f} ms, speedup {s['speedup_no_energy']:.1f}x")
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
            "realtime_cpu_latency",
            "realtime_low_spin",
            "realtime_controller",
            "realtime_controller_nice0",
            "realtime_flood",
            "realtime_flood_merge",
        ):
            r = nd.get(key)
            if r:
                print(
                    f"  real-time, wake_spin {r['wake_spin_s'] * 1e3:.2f} ms, "
                    f"stepping nice {r['stepping_nice']}, "
                    f"cpu_latency_us {r.get('cpu_latency_us')}"
                    + (f", subscriber on {r['subscribed']}" if r["subscribed"] else "")
                    + (
                        f", {r['flood_sent_per_s']:.0f} commands/s from another process "
                        f"({r['command_time_mean_us'] or float('nan'):.1f} us each; "
                        f"{r.get('flood_sent')} sent, {r.get('flood_commands_recorded')} "
                        f"recorded, {r.get('flood_commands_lost')} lost)"
                        if r.get("flood_hz")
                        else ""
                    )
                    + (f", merge_late_ticks {r['params']['merge_late_ticks']}"
                       if "merge_late_ticks" in r["params"] else "")
                    + f": real-time factor {r['real_time_factor']:.3f}, "
                    f"missed {r['missed_ticks']} of {r['paced_ticks']} ticks "
                    f"({r['missed_fraction']:.3%}; merged {r.get('merged_ticks', 0)}), "
                    f"node CPU {r['node_cpu_cores'] or float('nan'):.2f} cores, "
                    f"worst lateness {r['max_late_us'] / 1e3:.1f} ms"
                )
        from flexure_sim.tools.bench.closed_loop import summary

        for key, label in (("realtime_closed_loop", ""),
                           ("realtime_closed_loop_cpu_latency", " [cpu_latency_us 0]"),
                           ("realtime_closed_loop_low_spin",
                            f" [cpu_latency_us 0, wake_spin {LOW_WAKE_SPIN_S * 1e3:g} ms]"),
                           ("realtime_closed_loop_monitor100",
                            f" [monitor_rate {MONITOR_RATE:g} Hz]"),
                           ("realtime_closed_loop_nice0",
                            " [stepping_nice 0: stepping and middleware threads]"),
                           ("realtime_closed_loop_fifo", FIFO_LABEL),
                           ("realtime_closed_loop_hog", " [next to a CPU hog at niceness 19]"),
                           ("realtime_closed_loop_fifo_hog",
                            FIFO_LABEL + " [next to a CPU hog at niceness 19]"),
                           ("realtime_closed_loop_merge",
                            f" [merge_late_ticks {MERGE_LATE_TICKS}]")):
            if nd.get(key):
                print("  " + summary(nd[key]) + label)


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
    if args.sweep:
        res["sweep"] = bench_sweep(args.sweep_designs)
    if args.node:
        res["node"] = bench_node(args.node_seconds)
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
