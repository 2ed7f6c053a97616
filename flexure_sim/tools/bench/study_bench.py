"""
Analysis and sweep benchmarks of ``flexure-sim bench``: linearisation, sensitivities, Dask sweep.

- analyses: the stage's exact linearisation + modes + FRF at 1000 frequencies, and hyper-dual
  sensitivities of 4 outputs to 20 parameters.
- sweep: flexure-sim sweep's scaling on the stage tolerance study, without Dask and on a
  LocalCluster of 1 and 2 worker processes, and the overhead of a batch.
- optimize: flexure-sim optimize on the stage over its 7 hinge thicknesses
  (config/studies/stage_first_mode.yaml; goal: converged in < 10 s), and the share of the time
  spent in exact gradients.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.tools.bench.engine_bench import BASELINE_REPEATS, REPEATS

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
    from flexure_sim.engine.analysis import linear
    from flexure_sim.engine.mechanism.parameters import Parameters
    from flexure_sim.engine.analysis.sensitivity import OUTPUTS, sensitivities

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
    from flexure_sim.engine.analysis.study import study_from_dict
    from flexure_sim.tools.design.sweep_outputs import OUTPUTS

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

    from flexure_sim.tools.design.sweep_outputs import evaluate_batch
    from flexure_sim.tools.design.sweep_run import run_study

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


def bench_optimize(repeats: int = 3) -> dict:
    """
    Optimise the stage's first mode over its 7 necks (config/studies/stage_first_mode.yaml).

    Median wall time of ``repeats`` solves from the study's start (each from scratch, after one
    warm-up), its iterations, evaluations with and without gradients and the time in each.
    """
    from flexure_sim.engine.analysis.optimize import solve
    from flexure_sim.engine.analysis.optimize_study import load_optimize_study
    from flexure_sim.engine.mechanism.builtins import builtin_dir

    study = load_optimize_study(Path(builtin_dir()) / "studies" / "stage_first_mode.yaml")
    solve(study)  # warm-up (compiled kernels)
    runs = sorted((solve(study) for _ in range(repeats)), key=lambda r: r.wall_s)
    r = runs[len(runs) // 2]
    return {"study": study.source, "variables": len(study.variables), "status": r.status,
            "wall_s": r.wall_s, "iterations": r.iterations, "evaluations": r.evaluations,
            "gradient_evaluations": r.gradients, "gradient_s": r.extra["seconds"]["gradients"],
            "values_s": r.extra["seconds"]["values"], "objective": r.objective,
            "start_objective": r.history[0]["objective"],
            "stationarity": r.kkt.get("stationarity_relative")}
