"""Materials by name: the shipped table, its sources, lookup, and no hidden default material."""
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from flexure_sim.cli import main
from flexure_sim.engine.hinges import materials
from flexure_sim.engine.hinges.stiffness import cantilever_stiffness, notch_stiffness
from flexure_sim.engine.hinges.stress import stroke_limit
from flexure_sim.engine.mechanism.loader import (ConfigError, mechanism_from_dict,
                                                 resolve_mechanism_path)
from flexure_sim.engine.mechanism.parameters import Parameters
from flexure_sim.engine.solver.simulation import Simulation
from reference_figures import STROKE_LIMIT

ROOT = Path(__file__).resolve().parent.parent
TABLE = ROOT / "flexure_sim" / "engine" / "hinges" / "materials.yaml"


def test_every_value_of_the_table_has_a_source_and_a_sigma_e_its_cycles():
    """Read the file itself (not through the module): each property a value and a source."""
    data = yaml.safe_load(TABLE.read_text())["materials"]
    wanted = {"6061-T6", "7075-T6", "Ti-6Al-4V", "17-4PH-H900", "50CrV4", "C17200-TF00"}
    assert wanted <= set(data)
    for name, spec in data.items():
        for prop in ("E", "nu", "density", "sigma_y", "sigma_u", "sigma_e"):
            entry = spec[prop]
            assert float(entry["value"]) > 0, (name, prop)
            assert isinstance(entry["source"], str) and len(entry["source"]) > 20, (name, prop)
        assert float(spec["sigma_e"]["cycles"]) >= 1e6, name
    # The module reads the same numbers.
    for name, m in materials.table().items():
        assert m["sigma_y"] == float(data[name]["sigma_y"]["value"])
        assert m.cycles == float(data[name]["sigma_e"]["cycles"])


def test_table_values_are_the_datasheets():
    """
    Spot checks against the published figures the sources name.

    ASM/MatWeb 6061-T6: 276 MPa yield, 310 MPa ultimate, 96.5 MPa at 5e8 cycles, 68.9 GPa;
    7075-T6: 503 / 572 / 159 MPa, 71.7 GPa; Ti-6Al-4V annealed: 880 / 950 MPa, 510 MPa at 1e7.
    """
    t = materials.table()
    assert (t["6061-T6"]["sigma_y"], t["6061-T6"]["sigma_u"], t["6061-T6"]["sigma_e"],
            t["6061-T6"].cycles, t["6061-T6"]["E"]) == (276e6, 310e6, 96.5e6, 5e8, 68.9e9)
    assert (t["7075-T6"]["sigma_y"], t["7075-T6"]["sigma_u"], t["7075-T6"]["sigma_e"],
            t["7075-T6"]["E"]) == (503e6, 572e6, 159e6, 71.7e9)
    assert (t["Ti-6Al-4V"]["sigma_y"], t["Ti-6Al-4V"]["sigma_u"], t["Ti-6Al-4V"]["sigma_e"],
            t["Ti-6Al-4V"].cycles) == (880e6, 950e6, 510e6, 1e7)
    # Granit Engineering's 51CrV4 (1.8159) sheet: E 205000 N/mm^2, Poisson 0.29, 7.85 kg/dm^3.
    assert (t["50CrV4"]["E"], t["50CrV4"]["nu"], t["50CrV4"]["density"]) == (205e9, 0.29, 7850.0)
    # NGK Alloy 25 strip, temper OT (TF00): yield at least 960, tensile 1100-1380 N/mm^2.
    assert (t["C17200-TF00"]["sigma_y"], t["C17200-TF00"]["sigma_u"]) == (960e6, 1100e6)


def test_fatigue_estimates_are_half_the_ultimate_strength():
    """Shigley Sec. 6-7: S'e = 0.5 S_ut for steels up to about 1400 MPa, where no test exists."""
    t = materials.table()
    for name in ("17-4PH-H900", "50CrV4"):
        assert t[name]["sigma_u"] <= 1400e6
        assert t[name]["sigma_e"] == pytest.approx(0.5 * t[name]["sigma_u"], rel=1e-12), name
        assert "estimate" in t[name].sources["sigma_e"]


def test_an_unverified_value_says_so_in_its_source():
    """Values no readable source confirmed carry the marker; the checked ones name a URL."""
    unchecked = "not checked against a readable source"
    t = materials.table()
    for name, m in t.items():
        for prop, source in m.sources.items():
            assert unchecked in source or "http" in source, (name, prop)
    for prop in ("E", "nu", "density", "sigma_y", "sigma_u"):
        assert unchecked in t["17-4PH-H900"].sources[prop], prop
    assert unchecked in t["C17200-TF00"].sources["sigma_e"]


def test_a_table_value_without_a_source_is_refused():
    text, n = re.subn(r'(density: \{value: 2700\.0), source: "[^"]*"', r"\1", TABLE.read_text(),
                      count=1)
    assert n == 1
    with pytest.raises(materials.MaterialError, match=r"6061-T6\.density\.source: every value "
                       "needs its source"):
        materials._read_table(text, "t.yaml")


def test_lookup_ignores_case_spaces_and_hyphens_and_names_the_close_one():
    assert materials.lookup("7075t6").name == "7075-T6"
    assert materials.lookup("17-4 PH H900").name == "17-4PH-H900"
    with pytest.raises(materials.MaterialError, match=r"unknown material '7057-T6' \(did you "
                       r"mean 7075-T6\?\); the table has 6061-T6, 7075-T6"):
        materials.lookup("7057-T6")


def _leaf_doc(**leaf):
    spec = {"model": "cantilever", "length": 0.01, "thickness": 0.001, "width": 0.005, **leaf}
    return {"name": "leafy", "defaults": {"damping": {"t_char": 1e-4}},
            "stiffness_models": {"leaf": spec},
            "bodies": [{"name": "ground", "mass": 1.0, "inertia": 1.0},
                       {"name": "m", "mass": 0.01, "inertia": 1e-6}],
            "hinges": [{"name": "l", "a": {"body": "ground", "at": [0.0, 0.0]},
                        "b": {"body": "m", "at": [0.0, 0.0]}, "stiffness": "leaf"}],
            "constraints": [{"type": "fixed", "body": "ground"}]}


def test_a_material_gives_e_nu_and_the_strengths_and_explicit_numbers_override():
    ti = materials.lookup("Ti-6Al-4V")
    hinge = mechanism_from_dict(_leaf_doc(material="Ti-6Al-4V")).hinges[0]
    np.testing.assert_array_equal(hinge.law.K, cantilever_stiffness(0.01, 0.001, 0.005,
                                                                    113.8e9, 0.342))
    g = hinge.stress
    assert (g.sigma_y, g.sigma_u, g.sigma_e, g.cycles, g.material) == (
        880e6, 950e6, 510e6, 1e7, "Ti-6Al-4V")
    assert g.key == "stiffness_models.leaf" and ti["E"] == 113.8e9
    # The file's own numbers win: E, nu and the fatigue strength with its cycle count.
    own = mechanism_from_dict(_leaf_doc(material="ti 6al 4v", E=100e9, nu=0.3, sigma_e=300e6,
                                        fatigue_cycles=1e9)).hinges[0]
    np.testing.assert_array_equal(own.law.K, cantilever_stiffness(0.01, 0.001, 0.005, 100e9,
                                                                  0.3))
    assert (own.stress.sigma_e, own.stress.cycles, own.stress.sigma_y) == (300e6, 1e9, 880e6)
    # The design parameters (sensitivities, optimiser) see the same numbers.
    params = Parameters("leafy.yaml", data=_leaf_doc(material="Ti-6Al-4V"))
    assert params.design().geometry == [hinge.stress]
    np.testing.assert_array_equal(params.design().K[0], hinge.law.K)


@pytest.mark.parametrize("change, key, problem", [
    ({"material": "unobtainium"}, "stiffness_models.leaf.material", "unknown material"),
    ({"E": 69e9, "nu": 0.33, "sigma_e": 9e7}, "stiffness_models.leaf.sigma_e",
     "give fatigue_cycles too"),
    ({"material": "6061-T6", "sigma_u": 2e8}, "stiffness_models.leaf.sigma_u",
     "below the yield strength"),
    ({"E": 69e9, "nu": 0.33, "fatigue_cycles": 1e7}, "stiffness_models.leaf.fatigue_cycles",
     "without its fatigue strength"),
])
def test_bad_material_keys_are_refused_naming_the_key(change, key, problem):
    with pytest.raises(ConfigError, match=f"<dict>: {key}: .*{problem}"):
        mechanism_from_dict(_leaf_doc(**change))


def test_a_matrix_stiffness_with_a_material_is_refused():
    doc = _leaf_doc()
    doc["stiffness_models"]["leaf"] = {"model": "matrix", "Ko": 1.0, "Kt": [1e5, 1e5],
                                       "material": "6061-T6"}
    with pytest.raises(ConfigError, match="leaf.material: a matrix stiffness has no geometry"):
        mechanism_from_dict(doc)


def test_shipped_stages_name_their_material_and_keep_the_dissertations_e():
    for name in ("microstage", "microstage_realistic", "xy_stage"):
        mech = mechanism_from_dict(yaml.safe_load(resolve_mechanism_path(name).read_text()))
        for h in mech.hinges:
            assert h.stress.material == "6061-T6" and h.stress.sigma_y == 276e6, (name, h.name)
    mech = mechanism_from_dict(yaml.safe_load(resolve_mechanism_path("microstage").read_text()))
    np.testing.assert_array_equal(mech.hinges[0].law.K,
                                  notch_stiffness(0.003, 0.00025, 0.02, 69e9, 0.33))


def _stage_with(material_text: str, tmp_path) -> Path:
    text = resolve_mechanism_path("microstage").read_text()
    assert text.count(", material: 6061-T6}") == 1
    path = tmp_path / "stage.yaml"
    path.write_text(text.replace(", material: 6061-T6}", material_text))
    return path


def test_no_material_no_yield_strength_and_the_outputs_say_which_key_to_add(tmp_path, capsys):
    path = str(_stage_with("}", tmp_path))
    assert main(["simulate", path, "--drive", "step:2e-6", "--static", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert all(h["ratio"] is None and h["sigma_y"] is None for h in out["hinge_stress"].values())
    assert out["stress_note"].endswith("or sigma_y to stiffness_models.notch")
    assert "add material: NAME (6061-T6, 7075-T6" in out["stress_note"]
    assert out["fatigue"]["hinges"] == {} and "sigma_e, fatigue_cycles and sigma_u to " \
        "stiffness_models.notch" in out["fatigue"]["note"]
    assert main(["simulate", path, "--stroke-limit"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no yield strength: add material: NAME" in err[0]


def test_the_stage_in_7075_t6_has_the_stroke_limit_of_its_yield_strength(tmp_path):
    """503 MPa instead of 276 MPa: stress grows nearly linearly with the input (issue: ~30 um)."""
    u61, h61 = stroke_limit(Simulation(mechanism_from_dict(yaml.safe_load(
        resolve_mechanism_path("microstage").read_text()))))
    from flexure_sim.engine.mechanism.loader import load_mechanism

    u75, h75 = stroke_limit(Simulation(load_mechanism(_stage_with(", material: 7075-T6}",
                                                                  tmp_path))))
    assert h61 == h75 == "c"
    assert u61 == pytest.approx(STROKE_LIMIT, rel=1e-3)
    assert u75 == pytest.approx(30.46e-6, rel=1e-3)
    assert u75 / u61 == pytest.approx(503 / 276, rel=2e-3)


@pytest.mark.slow
def test_a_pip_install_carries_the_table_as_package_data(tmp_path):
    """A pip install (no checkout beside it): the installed module reads its own table."""
    target = tmp_path / "site"
    build = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                            "--target", str(target), str(ROOT)], capture_output=True, text=True,
                           timeout=600)
    assert build.returncode == 0, build.stderr[-2000:]
    probe = ("from flexure_sim.engine.hinges import materials; "
             "print(materials.__file__); print(materials.lookup('7075-T6')['sigma_y'])")
    p = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                       timeout=120, cwd=tmp_path, env={"PYTHONPATH": str(target),
                                                       "PATH": "/usr/bin:/bin"})
    assert p.returncode == 0, p.stderr
    where, value = p.stdout.split()
    assert Path(where).is_relative_to(target) and float(value) == 503e6


def _plate_doc(**body):
    doc = _leaf_doc(material="6061-T6")
    doc["bodies"][1] = {"name": "m", **body}
    return doc


def test_a_body_of_a_material_is_a_plate_cut_to_its_shape():
    """
    Mass rho t A and inertia rho t (b^2 + h^2) b h / 12 of a 40 x 10 mm rectangle, by hand.

    7075-T6 (2810 kg/m^3), 10 mm thick: 2810 * 0.01 * 4e-4 = 0.01124 kg;
    0.01124 * (0.04^2 + 0.01^2) / 12 = 1.59233e-6 kg m^2.
    """
    rectangle = {"rectangle": [-0.02, -0.005, 0.02, 0.005]}
    body = mechanism_from_dict(_plate_doc(material="7075-T6", thickness=0.01,
                                          shape=rectangle)).bodies[1]
    assert body.mass == pytest.approx(0.01124, rel=1e-12)
    assert body.inertia == pytest.approx(0.01124 * (0.04**2 + 0.01**2) / 12, rel=1e-12)
    # A clockwise polygon, a density instead of a material, and a given mass that wins.
    square = {"polygon": [[-0.01, -0.01], [-0.01, 0.01], [0.01, 0.01], [0.01, -0.01]]}
    body = mechanism_from_dict(_plate_doc(density=1000.0, thickness=0.002, shape=square,
                                          mass=0.5)).bodies[1]
    assert body.mass == 0.5 and body.inertia == pytest.approx(
        1000 * 0.002 * 4e-4 * (0.02**2 + 0.02**2) / 12, rel=1e-12)
    # The sensitivities and the optimiser see the loaded numbers.
    params = Parameters("p.yaml", data=_plate_doc(material="7075-T6", thickness=0.01,
                                                  shape=rectangle))
    assert params.design().mass[3:].tolist() == pytest.approx([0.01124, 0.01124, 1.592333e-6],
                                                              rel=1e-6)


@pytest.mark.parametrize("body, key, problem", [
    ({"material": "7075-T6", "thickness": 0.01,
      "shape": {"rectangle": [0.0, 0.0, 0.04, 0.01]}},
     "bodies[1].shape", r"centroid \(0.02, 0.005\) m is not at the body frame's origin"),
    ({"material": "7075-T6", "shape": {"rectangle": [-1, -1, 1, 1]}}, "bodies[1].thickness",
     "missing required key"),
    ({"thickness": 0.01, "shape": {"rectangle": [-1, -1, 1, 1]}}, "bodies[1].thickness",
     "give a material or a density"),
    ({"material": "balsa", "thickness": 0.01, "shape": {"rectangle": [-1, -1, 1, 1]}},
     "bodies[1].material", "unknown material 'balsa'"),
    ({"inertia": 1e-6}, "bodies[1].mass", "missing required key"),
])
def test_bad_plate_bodies_are_refused_naming_the_key(body, key, problem):
    with pytest.raises(ConfigError, match=f"<dict>: {re.escape(key)}: .*{problem}"):
        mechanism_from_dict(_plate_doc(**body))
