"""Mechanism YAML: built-ins load; each class of error is rejected with file, key and problem."""
import copy

import pytest
import yaml

from flexure_sim.engine.mechanism.loader import (
    ConfigError,
    builtin_names,
    load_mechanism,
    resolve_mechanism_path,
)
from reference_figures import NOTCH_KX


def test_builtins_load():
    assert {"microstage", "fourbar_cantilever", "fourbar_mixed"} <= set(builtin_names())
    stage = load_mechanism("microstage")
    assert [b.name for b in stage.bodies] == [f"body{i}" for i in range(1, 7)]
    assert [h.name for h in stage.hinges] == list("abcdefg")
    assert stage.drive.body == "body6" and stage.output.body == "body4"
    assert stage.hinges[0].law.K[1, 1] == pytest.approx(NOTCH_KX, rel=1e-3)
    assert stage.hinges[0].law.B == pytest.approx(1e-3 * stage.hinges[0].law.K)


@pytest.fixture
def stage_doc():
    return yaml.safe_load(resolve_mechanism_path("microstage").read_text())


def _load(tmp_path, doc, name="bad.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc) if not isinstance(doc, str) else doc)
    return load_mechanism(path)


def _expect(tmp_path, doc, *fragments):
    with pytest.raises(ConfigError) as err:
        _load(tmp_path, doc)
    msg = str(err.value)
    assert "bad.yaml" in msg
    for f in fragments:
        assert f in msg, msg
    return msg


def test_unknown_body(tmp_path, stage_doc):
    stage_doc["hinges"][2]["b"]["body"] = "body9"
    _expect(tmp_path, stage_doc, "hinges[2].b.body", "unknown body 'body9'")


def test_duplicate_body_name(tmp_path, stage_doc):
    stage_doc["bodies"][3]["name"] = "body2"
    _expect(tmp_path, stage_doc, "bodies[3].name", "duplicate body name 'body2'")


def test_duplicate_hinge_name(tmp_path, stage_doc):
    stage_doc["hinges"][4]["name"] = "a"
    _expect(tmp_path, stage_doc, "hinges[4].name", "duplicate hinge name 'a'")


@pytest.mark.parametrize(
    "key,value", [("mass", 0.0), ("mass", -1.0), ("inertia", 0.0), ("inertia", -2e-6)]
)
def test_non_positive_mass_or_inertia(tmp_path, stage_doc, key, value):
    stage_doc["bodies"][1][key] = value
    _expect(tmp_path, stage_doc, f"bodies[1].{key}", "must be positive")


def test_non_symmetric_stiffness(tmp_path, stage_doc):
    stage_doc["hinges"][0]["stiffness"] = {
        "model": "matrix",
        "K": [[2.5, 1.0, 0], [0, 1.6e8, 0], [0, 0, 1.7e7]],
    }
    _expect(tmp_path, stage_doc, "hinges[0].stiffness", "not symmetric")


def test_yield_strength_of_a_matrix_stiffness_is_refused_not_ignored(tmp_path, stage_doc):
    stage_doc["hinges"][0]["stiffness"] = {"model": "matrix", "Ko": 2.5, "Kt": [1.6e8, 1.7e7],
                                           "sigma_y": 276e6}
    _expect(tmp_path, stage_doc, "hinges[0].stiffness.sigma_y", "no geometry")


def test_non_positive_definite_stiffness(tmp_path, stage_doc):
    stage_doc["hinges"][0]["stiffness"] = {"model": "matrix", "Ko": 2.5, "Kt": [1.6e8, -1.0]}
    _expect(tmp_path, stage_doc, "hinges[0].stiffness", "not positive definite")


def test_frames_that_do_not_coincide(tmp_path, stage_doc):
    stage_doc["hinges"][1]["b"]["at"] = [0.007, 0.0215]
    _expect(tmp_path, stage_doc, "hinges[1]", "do not coincide")


def test_no_fixed_body(tmp_path, stage_doc):
    stage_doc["constraints"] = [c for c in stage_doc["constraints"] if c["type"] != "fixed"]
    _expect(tmp_path, stage_doc, "constraints", "no fixed body")


def test_unknown_key_is_named(tmp_path, stage_doc):
    stage_doc["bodies"][0]["masss"] = 1.0
    _expect(tmp_path, stage_doc, "bodies[0].masss", "unknown key")


def test_missing_key_is_named(tmp_path, stage_doc):
    del stage_doc["hinges"][3]["stiffness"]
    _expect(tmp_path, stage_doc, "hinges[3].stiffness", "missing required key")


def test_unknown_law_and_stiffness_model(tmp_path, stage_doc):
    doc = copy.deepcopy(stage_doc)
    doc["hinges"][0]["law"] = "spline"
    _expect(tmp_path, doc, "hinges[0].law", "unknown law 'spline'")
    stage_doc["stiffness_models"]["notch"]["model"] = "wire"
    _expect(tmp_path, stage_doc, "stiffness_models.notch.model", "unknown stiffness model 'wire'")


def test_non_numeric_and_non_finite_values(tmp_path, stage_doc):
    doc = copy.deepcopy(stage_doc)
    doc["bodies"][2]["pose"] = [0.0, "up", 0.0]
    _expect(tmp_path, doc, "bodies[2].pose[1]", "expected a number")
    stage_doc["stiffness_models"]["notch"]["E"] = float("nan")
    _expect(tmp_path, stage_doc, "stiffness_models.notch.E", "finite")


def test_constraint_errors(tmp_path, stage_doc):
    doc = copy.deepcopy(stage_doc)
    doc["constraints"].append({"type": "fixed", "body": "body6"})
    _expect(tmp_path, doc, "constraints[2]", "already constrained")
    doc = copy.deepcopy(stage_doc)
    doc["constraints"][1]["stroke"] = [2e-6, 0.0]
    _expect(tmp_path, doc, "constraints[1].stroke", "min < max")
    stage_doc["constraints"][1]["type"] = "magnet"
    _expect(tmp_path, stage_doc, "constraints[1].type", "unknown constraint type")


def test_invalid_names_for_ros(tmp_path, stage_doc):
    stage_doc["bodies"][0]["name"] = "1"
    _expect(tmp_path, stage_doc, "bodies[0].name", "not a valid name")


def test_not_yaml_and_missing_file(tmp_path):
    _expect(tmp_path, "bodies: [unclosed", "not valid YAML")
    _expect(tmp_path, "- just\n- a list\n", "must be a mapping")
    with pytest.raises(ConfigError, match="no such mechanism file"):
        load_mechanism(tmp_path / "absent.yaml")
    with pytest.raises(ConfigError, match="no such built-in mechanism"):
        load_mechanism("no_such_stage")
