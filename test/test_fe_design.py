"""
Sweeps and optimisation of a stage with ``model: fe`` hinges.

The FE stage of config/examples/microstage_fe.yaml, mostly at a coarse resolution (8 elements
across the neck) so that every new neck is solved in about a second. Expected values come from
elsewhere: the same design written to a YAML file and loaded and solved by the engine, and
central differences of designs meshed afresh.
"""
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml

from flexure_sim.engine.analysis.optimize import solve
from flexure_sim.engine.analysis.optimize_study import load_optimize_study
from flexure_sim.engine.analysis.study import study_from_dict
from flexure_sim.engine.hinges import fatigue
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.tools.design.sweep_outputs import OUTPUTS
from flexure_sim.tools.design.sweep_run import run_study

ROOT = Path(__file__).resolve().parent.parent
STAGE = ROOT / "config" / "examples" / "microstage_fe.yaml"
U = 2e-6
H = {"lower": 1.5e-4, "upper": 4.0e-4}


def _stage(tmp_path, monkeypatch, resolution):
    """Write the FE stage at ``resolution`` to tmp_path and give it a cache of its own."""
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(tmp_path / "cache"))
    doc = yaml.safe_load(STAGE.read_text())
    doc["stiffness_models"]["notch"]["resolution"] = resolution
    path = tmp_path / "stage.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.fixture()
def stage(tmp_path, monkeypatch):
    """Return the FE stage at resolution 8 (a new neck solves in about a second)."""
    return _stage(tmp_path, monkeypatch, 8)


def _with_neck(stage: Path, h: float, name: str) -> Path:
    """Write the stage with neck h to a file of its own."""
    doc = yaml.safe_load(stage.read_text())
    doc["stiffness_models"]["notch"]["h"] = h
    path = stage.parent / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _engine(path: Path) -> dict:
    """Gain and Goodman safety factor of a mechanism file, from the engine's static solves."""
    mech = load_mechanism(path)
    sim = Simulation(mech)
    loaded = sim.static(U).snapshot
    table = fatigue.between(mech, sim.static(0.0).snapshot.wrenches, loaded.wrenches)
    return {"gain": loaded.output / U, "fatigue_safety": fatigue.critical(table)[1]}


@pytest.mark.slow
def test_a_sweep_over_the_neck_gives_the_designs_loaded_from_their_own_files(stage, tmp_path):
    necks = [2.4e-4, 2.6e-4]
    study = study_from_dict({
        "mechanism": str(stage), "input": U,
        "outputs": ["gain", "first_mode", "peak_stress_ratio", "fatigue_safety"],
        "parameters": [{"name": "h", "path": "stiffness_models.notch.h", "values": necks}]},
        "s.yaml", OUTPUTS)
    table = pq.read_table(_run(study, tmp_path)).to_pydict()
    assert table["status"] == ["ok", "ok"]
    for k, h in enumerate(necks):
        engine = _engine(_with_neck(stage, h, f"h{k}.yaml"))
        assert table["gain"][k] == pytest.approx(engine["gain"], rel=1e-12)
        assert table["fatigue_safety"][k] == pytest.approx(engine["fatigue_safety"], rel=1e-12)
    # A thicker neck: stiffer hinges, a lower gain, a higher first mode, more stress.
    assert table["gain"][1] < table["gain"][0]
    assert table["first_mode"][1] > table["first_mode"][0]
    assert table["fatigue_safety"][1] < table["fatigue_safety"][0]


def _run(study, tmp_path: Path) -> Path:
    """Run the study in this process (Dask's synchronous scheduler) and return its table."""
    out = tmp_path / "sweep.parquet"
    run_study(study, out, workers=1)
    return out


@pytest.mark.slow
def test_optimiser_gradients_against_central_differences_of_fresh_meshes(tmp_path, monkeypatch):
    """
    The derivatives in h of gain, first mode and the Goodman factor at h = 0.25 mm.

    The exact gradients differentiate through the cached FE solve (moved meshes); central
    differences with steps of +-2 % re-mesh each neck, so they carry the re-meshing noise of
    the discretisation: at the default resolution (16) all three agree to 1e-3 (measured
    1e-4, 4e-5, 4e-4); at resolution 8 the Goodman factor's root stress is 2 % apart.
    """
    stage = _stage(tmp_path, monkeypatch, 16)
    spec = {"mechanism": str(stage), "input": U,
            "variables": [{"path": "stiffness_models.notch.h", **H}],
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": "gain", "min": 0.0},
                            {"output": "fatigue_safety", "min": 0.0}]}
    path = tmp_path / "opt.yaml"
    path.write_text(yaml.safe_dump(spec))
    study = load_optimize_study(path)
    h0, step = 2.5e-4, 0.02 * 2.5e-4
    exact = study.evaluate([h0], True)
    plus, minus = study.evaluate([h0 + step], False), study.evaluate([h0 - step], False)
    for name in ("gain", "first_mode", "fatigue_safety"):
        fd = (plus[name].value - minus[name].value) / (2 * step)
        assert exact[name].gradient[0] == pytest.approx(fd, rel=1e-3), name


@pytest.mark.slow
def test_a_short_optimisation_meets_its_gain_limit_in_the_file_it_describes(stage, tmp_path):
    """
    Maximise the first mode over the shared neck subject to gain >= 30 and Goodman n >= 4.

    Thicker necks raise the first mode and lower the gain: the gain limit is active. The design
    at the optimum, written to a file and solved by the engine, has gain 30.
    """
    spec = {"mechanism": str(stage), "input": U,
            "variables": [{"path": "stiffness_models.notch.h", **H}],
            "objective": {"maximize": "first_mode"},
            "constraints": [{"output": "gain", "min": 30.0},
                            {"output": "fatigue_safety", "min": 4.0}]}
    path = tmp_path / "opt.yaml"
    path.write_text(yaml.safe_dump(spec))
    result = solve(load_optimize_study(path))
    assert result.status == "optimal" and result.kkt["stationarity_relative"] <= 1e-6
    gain = [c for c in result.constraints if c["output"] == "gain"][0]
    assert gain["active"] and gain["multiplier"] > 0
    engine = _engine(_with_neck(stage, float(result.x[0]), "optimum.yaml"))
    assert engine["gain"] == pytest.approx(30.0, rel=1e-8)
    assert engine["fatigue_safety"] >= 4.0
    assert H["lower"] < result.x[0] < H["upper"]
