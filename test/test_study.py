"""Study files (engine/analysis/study.py): validation, parameter paths, grids, samples. No Dask."""
import math

import numpy as np
import pytest
import yaml

from flexure_sim.engine.hinges.stiffness import notch_stiffness
from flexure_sim.engine.analysis.study import StudyError, load_study, study_from_dict

OUTPUTS = ("gain", "compression", "drive_force")
NOTCH = dict(D=0.003, h=0.00025, t=0.02, E=69.0e9, nu=0.33)  # config/microstage.yaml


def _study(**over):
    data = {"mechanism": "microstage", "outputs": ["gain"],
            "parameters": [{"path": "stiffness_models.notch.h", "values": [2.4e-4, 2.5e-4]}]}
    data.update(over)
    return study_from_dict(data, "s.yaml", OUTPUTS)


def _hinge_K(mech, name):
    return mech.hinges[mech.hinge_index(name)].law.K


@pytest.mark.parametrize("change, key", [
    ({"batchsize": 10}, "s.yaml: batchsize: unknown key"),
    ({"mechanism": "nosuch"}, "s.yaml: mechanism: nosuch: no such built-in mechanism"),
    ({"outputs": ["gain", "gian"]}, "s.yaml: outputs[1]: unknown output 'gian'"),
    ({"parameters": [{"path": "hinges.z.stiffness.h", "values": [1e-4]}]},
     "s.yaml: parameters[0].path: hinges has no element named 'z'"),
    ({"parameters": [{"path": "stiffness_models.notch.model", "values": [1]}]},
     "s.yaml: parameters[0].path: stiffness_models.notch.model is 'notch', not a finite number"),
    ({"parameters": [{"path": "stiffness_models.notch.h", "normal": {"sd": 1e-6}}],
      "samples": 5, "seed": 1}, "s.yaml: parameters[0].normal.sd: unknown key"),
    ({"parameters": [{"path": "stiffness_models.notch.h", "normal": {"std": 1e-6}}], "seed": 1},
     "s.yaml: samples: missing required key"),
    ({"parameters": [{"path": "stiffness_models.notch.h", "normal": {"std": 1e-6}}], "samples": 5},
     "s.yaml: seed: a Monte Carlo study needs a non-negative integer seed"),
    ({"parameters": [{"path": "stiffness_models.notch.h", "values": [1e-4]},
                     {"path": "stiffness_models.notch.D", "normal": {"std": 1e-6}}]},
     "s.yaml: parameters: mixes grid values/range with distributions"),
    ({"parameters": [{"path": "stiffness_models.notch.h", "values": [1e-4]},
                     {"path": "stiffness_models.notch.h", "values": [2e-4]}]},
     "s.yaml: parameters[1]: sets stiffness_models.notch.h, which parameters[0] sets already"),
    ({"parameters": [{"path": "stiffness_models.notch.h", "name": "gain", "values": [1e-4]}]},
     "s.yaml: parameters[0].name: column 'gain' is already an output"),
    ({"parameters": [{"path": "stiffness_models.notch.h", "uniform": {"low": 2, "high": 1}}],
      "samples": 5, "seed": 1}, "s.yaml: parameters[0].uniform.high: must be above low"),
    ({"batch_size": 0}, "s.yaml: batch_size: expected a positive integer, got 0"),
    ({"input": 3e-6}, "s.yaml: input: 3e-06 m is outside the drive's stroke [0.0, 2e-06] m"),
    ({"mechanism": "fourbar_mixed", "parameters": [{"path": "bodies.link2.mass", "values": [1]}]},
     "s.yaml: mechanism: 'fourbar_mixed' has no drive constraint"),
    ({"step": {"dt": 0.1, "duration": 0.01}},
     "s.yaml: step.dt: 0.1 s is longer than the duration"),
])
def test_a_bad_study_is_refused_with_a_message_naming_the_key(change, key):
    with pytest.raises(StudyError) as err:
        _study(**change)
    assert str(err.value).startswith(key), str(err.value)
    assert "\n" not in str(err.value)


def test_a_broken_study_file_names_the_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("mechanism: [unclosed\n")
    with pytest.raises(StudyError, match=r"bad\.yaml: not valid YAML"):
        load_study(bad, OUTPUTS)
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(bytes(range(256)))
    with pytest.raises(StudyError, match=r"binary\.yaml"):
        load_study(binary, OUTPUTS)


def test_a_hinge_path_changes_that_hinge_only_and_keeps_the_shared_model_changes():
    """
    Path hinges.a.stiffness.h gives hinge a its own notch; the other six keep the shared model.

    Hinge a's notch has E as the shared model has it in this design. Expected K from the notch
    formula.
    """
    study = _study(parameters=[{"path": "stiffness_models.notch.E", "values": [70e9]},
                               {"path": "hinges.a.stiffness.h", "values": [2.6e-4]}])
    mech = study.mechanism(study.sample(0))
    shared = notch_stiffness(**{**NOTCH, "E": 70e9})
    own = notch_stiffness(**{**NOTCH, "E": 70e9, "h": 2.6e-4})
    np.testing.assert_allclose(_hinge_K(mech, "a"), own, rtol=1e-14)
    for name in "bcdefg":
        np.testing.assert_allclose(_hinge_K(mech, name), shared, rtol=1e-14)
    assert study.base["hinges"][0]["stiffness"] == "notch"  # the base document is not changed


def test_offset_parameters_move_both_frames_of_a_hinge():
    study = _study(parameters=[{"name": "a_x", "paths": ["hinges.a.a.at.0", "hinges.a.b.at.0"],
                                "offset": True, "values": [1e-5]}])
    doc = study.design(study.sample(0))
    assert doc["hinges"][0]["a"]["at"] == [0.007 + 1e-5, 0.012]
    assert doc["hinges"][0]["b"]["at"] == [-0.007 + 1e-5, 0.0]
    study.mechanism(study.sample(0))  # the frames still coincide


def test_grid_is_the_cartesian_product_with_the_last_parameter_fastest():
    study = _study(parameters=[{"path": "stiffness_models.notch.h", "values": [1e-4, 2e-4]},
                               {"path": "stiffness_models.notch.D",
                                "range": {"start": 2e-3, "stop": 4e-3, "num": 3}}])
    assert study.samples == 6 and not study.monte_carlo
    got = [tuple(study.sample(i)) for i in range(6)]
    assert got == [(h, d) for h in (1e-4, 2e-4) for d in (2e-3, 3e-3, 4e-3)]


def test_samples_follow_the_distributions_and_depend_on_seed_and_index_only():
    study = _study(samples=4000, seed=7, batch_size=3, parameters=[
        {"path": "stiffness_models.notch.h", "normal": {"std": 5e-6}},
        {"path": "stiffness_models.notch.D", "uniform": {"half_width": 1e-4}}])
    x = np.array([study.sample(i) for i in range(study.samples)])
    n = len(x)
    # Normal(mean = base 2.5e-4, std 5e-6): mean within 4 standard errors, std within 4 of its own.
    assert abs(x[:, 0].mean() - 2.5e-4) < 4 * 5e-6 / math.sqrt(n)
    assert abs(x[:, 0].std(ddof=1) / 5e-6 - 1) < 4 / math.sqrt(2 * n)
    # Uniform(3e-3 +- 1e-4): inside the interval, variance w^2/12 with w = 2e-4.
    assert x[:, 1].min() >= 2.9e-3 and x[:, 1].max() < 3.1e-3
    assert abs(x[:, 1].var(ddof=1) / (2e-4 ** 2 / 12) - 1) < 4 * math.sqrt(0.8 / n)
    # The same index gives the same values whatever the batching or the study size.
    other = _study(samples=10, seed=7, batch_size=100, parameters=study_spec(study))
    np.testing.assert_array_equal(other.sample(9), x[9])
    reseeded = _study(samples=10, seed=8, parameters=study_spec(study))
    assert not np.array_equal(reseeded.sample(9), x[9])


def study_spec(study):
    return [{"path": "stiffness_models.notch.h", "normal": {"std": 5e-6}},
            {"path": "stiffness_models.notch.D", "uniform": {"half_width": 1e-4}}]


def test_batches_cover_every_sample_once():
    study = _study(samples=1001, seed=1, batch_size=100,
                   parameters=[{"path": "stiffness_models.notch.h", "normal": {"std": 1e-6}}])
    covered = [i for a, b in study.batches() for i in range(a, b)]
    assert covered == list(range(1001)) and len(study.batches()) == 11


def test_the_shipped_studies_load(tmp_path):
    from pathlib import Path

    from flexure_sim.tools.design.sweep_outputs import OUTPUTS as REGISTERED

    path = Path(__file__).resolve().parent.parent / "config" / "studies" / "stage_tolerance.yaml"
    study = load_study(path, REGISTERED)  # the shipped files name the runner's outputs
    assert study.samples == 10000 and study.monte_carlo
    assert [p.name for p in study.parameters] == [f"h_{c}" for c in "abcdefg"]
    assert all(p.kind == "normal" and p.scale == 5e-6 and p.loc == 2.5e-4
               for p in study.parameters)
    grid = load_study(path.with_name("stage_notch_grid.yaml"),
                      OUTPUTS + ("settling_time", "overshoot"))
    assert grid.samples == 20 and not grid.monte_carlo
    # a relative mechanism path is taken relative to the study file
    mech_file = tmp_path / "my_stage.yaml"
    mech_file.write_text((path.parents[1] / "microstage.yaml").read_text())
    (tmp_path / "sub").mkdir()
    study_file = tmp_path / "sub" / "s.yaml"
    study_file.write_text(yaml.safe_dump({"mechanism": "../my_stage.yaml", "outputs": ["gain"],
                                          "parameters": [{"path": "hinges.b.stiffness.h",
                                                          "values": [2e-4]}]}))
    expected = str(tmp_path / "sub" / "../my_stage.yaml")
    assert load_study(study_file, OUTPUTS).mechanism_source == expected
