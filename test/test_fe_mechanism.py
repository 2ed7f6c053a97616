"""
``model: fe`` in a mechanism file: loading, messages, stress, and the design sensitivities.

The stage of config/examples/microstage_fe.yaml (the built-in stage with finite-element notch
hinges); expected values from the finite-element model's own building blocks where the test is
of plumbing, and from finite differences and a second finite-element code otherwise.
"""

import copy
from pathlib import Path

import numpy as np
import pytest

import notch_fe
from flexure_sim.engine.analysis.sensitivity import sensitivities
from flexure_sim.engine.hinges.fe import model
from flexure_sim.engine.hinges.stress import stress_table
from flexure_sim.engine.mechanism.loader import ConfigError, mechanism_from_dict
from flexure_sim.engine.mechanism.parameters import ParameterError, Parameters
from flexure_sim.engine.mechanism.yaml_files import read_yaml
from flexure_sim.engine.solver.simulation import Simulation
from reference_figures import RIGID_LEVER_GAIN, STAGE_GAIN

ROOT = Path(__file__).resolve().parent.parent
STAGE = ROOT / "config" / "examples" / "microstage_fe.yaml"
GEO = {"D": 3e-3, "h": 0.25e-3, "t": 0.02}


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path_factory, monkeypatch):
    """Give the module a cache directory of its own (solved once, then read)."""
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(tmp_path_factory.getbasetemp() / "fe_mech"))


def _data():
    return read_yaml(STAGE, ConfigError)


def _gain(data, u=1.35e-6):
    sim = Simulation(mechanism_from_dict(data, source=str(STAGE)))
    return sim.static(u).snapshot.output / u


def test_stage_hinges_take_the_finite_element_stiffness_and_stress():
    mech = mechanism_from_dict(_data(), source=str(STAGE))
    K = model.stiffness("circular", GEO, 69e9, 0.33, "strain")  # t >= D: plane strain
    for hinge in mech.hinges:
        assert np.array_equal(hinge.law.K, K)
        assert hinge.stress.model == "fe" and hinge.stress.sigma_y == 276e6
    # The peak stress per unit moment is a notch stress concentration times 6 / (t h^2); in
    # plane strain von Mises is sqrt(1 - nu + nu^2) of the root's sigma_xx (sigma_zz =
    # nu sigma_xx there). K_t from the independent Q9 model of test/notch_fe.py (whose
    # plane-stress K_t is the plane-strain one too: traction problems in 2D do not depend on
    # the elastic constants).
    kt = notch_fe.concentration(0.25e-3, 1.5e-3, n=40)
    nominal = 6 / (0.02 * 0.25e-3 ** 2)
    c_m = mech.hinges[0].stress.dimensions[0]
    assert c_m == pytest.approx(kt * nominal * np.sqrt(1 - 0.33 + 0.33 ** 2), rel=3e-3)
    table = stress_table(np.array([[1.0, 0.0, 0.0]] * 7), mech)
    assert table["a"]["stress"] == pytest.approx(c_m, rel=1e-12)


def test_stage_gain_with_fe_hinges_between_the_closed_form_and_beam_expectations():
    # The finite-element hinges are stiffer axially than eqs. 5.29-5.30 say (2.6e8 against
    # 1.59e8 N/m): joint a compresses less and the gain is higher than the built-in stage's
    # 27.63, toward the rigid-lever 36.4.
    gain = _gain(_data())
    assert STAGE_GAIN < gain < RIGID_LEVER_GAIN


def test_second_load_reads_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(tmp_path))
    mechanism_from_dict(_data(), source=str(STAGE))
    files = {p: p.stat().st_mtime_ns for p in (tmp_path / "fe").glob("*.json")}
    assert len(files) == 1  # seven hinges, one geometry, stiffness and stress in one solve
    mechanism_from_dict(_data(), source=str(STAGE))
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "fe").glob("*.json")} == files


@pytest.mark.parametrize("change, message", [
    ({"shape": "oval"}, "stiffness_models.notch.shape: unknown hinge shape 'oval'"),
    ({"D": None}, "stiffness_models.notch.D: missing required key"),
    ({"h": -1e-4}, "stiffness_models.notch.h: "),
    ({"plane": "both"}, "stiffness_models.notch.plane: expected one of auto, stress, strain"),
    ({"resolution": 2.5}, "stiffness_models.notch.resolution: expected a whole number"),
    ({"nu": 0.5}, "stiffness_models.notch.nu: Poisson's ratio must be in"),
    ({"r": 1e-3}, "stiffness_models.notch.r: unknown key"),
    ({"shape": "corner_filleted", "D": None, "length": 2e-3, "r": 1.5e-3},
     "stiffness_models.notch: r: the fillet radius"),
    ({"shape": "leaf", "D": None, "h": None, "t": None, "length": 0.01, "thickness": 1e-3,
      "width": 5e-3}, "stiffness_models.notch.sigma_y: a leaf without fillets has a stress "
                      "singularity"),
])
def test_bad_fe_specifications_are_refused_naming_the_key(change, message):
    data = copy.deepcopy(_data())
    spec = data["stiffness_models"]["notch"]
    for k, v in change.items():
        if v is None:
            spec.pop(k)
        else:
            spec[k] = v
    with pytest.raises(ConfigError) as err:
        mechanism_from_dict(data, source=str(STAGE))
    assert message in str(err.value)
    assert str(STAGE) in str(err.value)


def test_gain_sensitivity_to_the_neck_matches_differences_of_reloaded_stages():
    # d gain / d h and d2 gain / dh2 through the hyper-dual chain (the model: fe stiffness's
    # derivatives on moved meshes) against central differences of the stage reloaded with h
    # +- 2 % / 5 % (each meshed afresh).
    params = Parameters(STAGE)
    path = "stiffness_models.notch.h"
    res = sensitivities(params, [path], ["gain"], u=1.35e-6)
    h0 = 0.25e-3

    def gain(h):
        data = copy.deepcopy(_data())
        data["stiffness_models"]["notch"]["h"] = h
        return _gain(data)

    d1 = (gain(h0 * 1.02) - gain(h0 * 0.98)) / (0.04 * h0)
    d2 = (gain(h0 * 1.05) - 2 * gain(h0) + gain(h0 * 0.95)) / (0.05 * h0) ** 2
    assert res["values"]["gain"] == pytest.approx(gain(h0), rel=1e-9)
    assert res["gradient"]["gain"][path] == pytest.approx(d1, rel=2e-3)
    assert res["second"]["gain"][f"{path}|{path}"] == pytest.approx(d2, rel=3e-2)


def test_peak_stress_sensitivity_and_the_resolution_is_no_parameter():
    params = Parameters(STAGE)
    res = sensitivities(params, ["stiffness_models.notch.t"], ["peak_stress"], u=2e-6)
    # A thicker plate: stiffer hinges (E t) and lower stress per load (1 / t); the stage's
    # input is a displacement, so the hinge loads scale with t and the stress does not move
    # with t at all.
    assert abs(res["gradient"]["peak_stress"]["stiffness_models.notch.t"]) * 0.02 < (
        1e-6 * res["values"]["peak_stress"])
    data = copy.deepcopy(_data())
    data["stiffness_models"]["notch"]["resolution"] = 16
    with pytest.raises(ParameterError, match="resolution .* is not a design parameter"):
        Parameters(STAGE, data).check("stiffness_models.notch.resolution")
