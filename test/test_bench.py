"""The accuracy claims behind the benchmark figures (speed figures are printed, not tested)."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexure_sim.tools.bench import engine_bench as bench_engine
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import DEFAULT_STEP
from reference_figures import FIRST_MODE_HZ, STAGE_GAIN, STAGE_INPUT


@pytest.fixture(scope="module")
def stage_run():
    return bench_engine.bench_stage_step(DEFAULT_STEP, radau=True)


def test_shipped_step_is_accurate_to_1e_6_against_the_reference(stage_run):
    assert stage_run["max_rel_error"] < 1e-6
    assert stage_run["reference_rel_error_estimate"] < 1e-8
    # A third of the way, then settled on the static answer (the run is a real step response).
    assert stage_run["output_final"] == pytest.approx(STAGE_GAIN * STAGE_INPUT, rel=1e-4)


def test_reference_is_confirmed_by_an_independent_integrator(stage_run):
    """Check that scipy's Radau (rtol 1e-8) on the same equations agrees with the reference."""
    assert stage_run["baseline_max_rel_error"] < 1e-6
    assert stage_run["baseline_nfev"] > 100


def test_error_grows_with_the_step_as_second_order():
    mech = load_mechanism("microstage")
    ref, _ = bench_engine.reference_trajectory(mech, 4e-4, 0.01)
    errors = []
    for dt in (4e-4, 2e-4):
        from flexure_sim.engine.solver.simulation import Simulation
        sim = Simulation(mech, dt=dt)
        sim.set_command(bench_engine.U_STEP)
        traj = bench_engine._output_trajectory(sim, int(round(4e-4 / dt)), len(ref))
        errors.append(np.max(np.abs(traj - ref)) / np.max(np.abs(ref)))
    assert errors[1] < errors[0] / 3


def test_static_sweep_figures():
    res = bench_engine.bench_static_sweep(levels=50)
    assert res["gain_at_full_stroke"] == pytest.approx(STAGE_GAIN, rel=1e-3)
    assert res["newton_iterations"] < 6 * 50


def test_analyses_benchmark_runs_modes_frf_at_1000_frequencies_and_4_outputs_to_20_parameters():
    """The issue's analysis benchmark: what it times (its wall times are printed, not tested)."""
    from flexure_sim.engine.analysis.sensitivity import OUTPUTS
    from flexure_sim.tools.bench.study_bench import SENSITIVITY_PARAMETERS, bench_analyses

    res = bench_analyses()
    assert res["frequencies"] == 1000
    assert res["first_mode_hz"] == pytest.approx(FIRST_MODE_HZ, rel=1e-3)
    assert res["sensitivity_parameters"] == len(set(SENSITIVITY_PARAMETERS)) == 20
    assert res["sensitivity_outputs"] == len(OUTPUTS) == 4
    assert res["modes_frf_wall_s"] > 0 and res["sensitivity_wall_s"] > 0


def test_spatial_accuracy_ladder_halves_the_step_until_the_target(monkeypatch):
    """``spatial_bench.at_accuracy``: stops at the first step within the target, else None."""
    from flexure_sim.engine.mechanism.spatial_loader import load_spatial
    from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
    from flexure_sim.tools.bench import spatial_bench

    monkeypatch.setattr(spatial_bench, "DURATION", 2e-3)
    monkeypatch.setattr(spatial_bench, "HALVINGS", 1)
    tip = load_spatial("tiptilt_stage")
    args = ((lambda h: SpatialSimulation(tip, dt=h)), [1e-5, 0.0, 0.0], 1e-4,
            (lambda s: s.model.output_values(s.state.z)[0]))
    none = spatial_bench.at_accuracy(*args, target=0.0)
    assert none["reached"] is None and [r["dt"] for r in none["steps"]] == [1e-4, 5e-5]
    first, second = (r["max_rel_error"] for r in none["steps"])
    assert second < first  # a smaller step is more accurate
    reached = spatial_bench.at_accuracy(*args, target=0.5 * (first + second))
    assert [r["dt"] for r in reached["steps"]] == [1e-4, 5e-5]
    assert reached["reached"] == reached["steps"][-1]


def test_the_installed_package_finds_the_fe_benchmarks_stage(tmp_path):
    # Run from elsewhere, so that the installed copy is imported: its example mechanisms are
    # under <prefix>/share/flexure_sim/config, not next to the module.
    code = ("import sys; from flexure_sim.tools.bench.fe_bench import stage_file; "
            "print(sys.prefix); print(stage_file())")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    prefix, path = p.stdout.splitlines()
    assert path == f"{prefix}/share/flexure_sim/config/examples/microstage_fe.yaml"
    assert Path(path).is_file()
