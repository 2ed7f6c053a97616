"""3-D mechanism files and planar files opened in 3-D: bad input is refused by key, by name."""
import copy
from pathlib import Path

import numpy as np
import pytest

from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.engine.mechanism.spatial_loader import load_spatial, spatial_from_dict
from flexure_sim.engine.mechanism.values import ConfigError
from flexure_sim.engine.mechanism.yaml_files import read_yaml

ROOT = Path(__file__).resolve().parents[1]


def tiptilt():
    return copy.deepcopy(read_yaml(resolve_mechanism_path("tiptilt_stage"), ConfigError))


def planar(name="microstage"):
    return copy.deepcopy(read_yaml(resolve_mechanism_path(name), ConfigError))


def test_shipped_files_load():
    tt = load_spatial("tiptilt_stage")
    assert [b.name for b in tt.bodies] == ["base", "platform", "cap1", "cap2", "cap3"]
    assert [d.name for d in tt.drives] == ["p1", "p2", "p3"]
    stage = load_spatial("microstage")
    assert stage.planar is not None and len(stage.hinges) == 7
    # the plate of 20 mm: I_xx = I_zz / 2 + m t^2 / 12
    body = stage.bodies[3]
    # I_zz of body4 as microstage.sci's formula gives it (config/microstage.yaml's header)
    i_zz = 0.01568 * (0.028**2 + 0.010**2) / 12
    assert body.inertia[0][0] == pytest.approx(i_zz / 2 + 0.01568 * 0.02**2 / 12)


def edit(doc, path, value):
    node = doc
    for key in path[:-1]:
        node = node[key]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return doc


@pytest.mark.parametrize("path, value, message", [
    (["space"], "2d", r"space: expected 3d, got '2d'"),
    (["colour"], "red", r"colour: unknown key"),
    (["bodies", 1, "mass"], float("nan"), r"bodies\[1\]\.mass: must be finite"),
    (["bodies", 1, "inertia"], [1e-6, -1e-6, 1e-6],
     r"bodies\[1\]\.inertia: inertia matrix is not positive definite"),
    (["hinges", 0, "b", "at"], [0.0, 0.0101, -0.004],
     r"hinges\[0\]: frames a and b do not coincide"),
    (["hinges", 3, "b", "rpy"], [0.6, -1.5707963267948966, 0.0],
     r"hinges\[3\]: frames a and b do not coincide"),
    (["stiffness_models", "wire"], {"model": "matrix", "K": np.eye(3).tolist()},
     r"stiffness_models\.wire\.K: expected a 6x6 matrix"),
    (["stiffness_models", "wire"], {"model": "matrix", "K": (-np.eye(6)).tolist()},
     r"stiffness_models\.wire: stiffness matrix is not positive definite"),
    (["stiffness_models", "wire", "model"], "fe",
     r"stiffness_models\.wire\.shape: missing required key"),
    (["stiffness_models", "wire", "model"], "notchy",
     r"stiffness_models\.wire\.model: unknown stiffness model 'notchy' \(notch, .*fe, matrix\)"),
    (["constraints", 1, "axis"], "rx",
     r"constraints\[1\]\.axis: .* \(a displacement drive on a rotation coordinate"),
    (["defaults", "damping"], {"B": np.eye(3).tolist()},
     r"defaults\.damping\.B: a 3-D hinge's damping is \{t_char"),
    (["defaults", "law"], {"polynomial": "x.yaml"}, r"defaults\.law: expected twistor or twist"),
    (["outputs", 0, "coordinate"], "theta",
     r"outputs\[0\]\.coordinate: expected one of x, y, z, rx, ry, rz"),
])
def test_a_bad_3d_file_names_the_key(path, value, message):
    with pytest.raises(ConfigError, match=message):
        spatial_from_dict(edit(tiptilt(), path, value), "tiptilt.yaml")


@pytest.mark.parametrize("name, path, value, message", [
    ("microstage", ["stiffness_models", "notch"],
     {"model": "matrix", "Ko": 2.5, "Kt": [1.6e8, 1.7e7]},
     r"stiffness_models\.notch\.model: a matrix stiffness \(3x3\) has no out-of-plane"),
    ("microstage", ["constraints", 1],
     {"type": "drive", "body": "body6", "axis": "theta", "response_time": 1e-3,
      "stroke": [0, 1e-3], "slew_rate": 1},
     r"constraints\[1\]\.axis: a displacement drive on theta"),
    ("fourbar_cantilever", [], None, r"constraints\[1\]: a sine_rate constraint"),
    ("microstage_realistic", [], None, r"damping: the mechanism damping block is not supported"),
    ("microstage", ["hinges", 2, "damping"], {"B": np.eye(3).tolist()},
     r"hinges\[2\]\.damping\.B: a 3-D hinge's damping"),
])
def test_a_planar_file_opened_in_3d_refuses_what_has_no_out_of_plane_meaning(
        name, path, value, message):
    doc = planar(name)
    if path:
        edit(doc, path, value)
    with pytest.raises(ConfigError, match=message):
        spatial_from_dict(doc, f"{name}.yaml")


def test_a_planar_file_with_a_polynomial_law_is_refused_in_3d():
    with pytest.raises(ConfigError, match=r"hinges\[0\]\.law: a polynomial law has no "
                                          "out-of-plane terms"):
        load_spatial(ROOT / "config" / "examples" / "microstage_polynomial_a.yaml")


def test_a_planar_file_with_a_bad_value_gets_the_planar_message():
    doc = edit(planar(), ["bodies", 2, "mass"], -1.0)
    with pytest.raises(ConfigError, match=r"microstage\.yaml: bodies\[2\]\.mass: must be "
                                          "positive"):
        spatial_from_dict(doc, "microstage.yaml")
