"""
One path from a mechanism's YAML document to its Mechanism and to a design's numbers.

Design parameters by path (mechanism/parameters.py) are set into the parsed document as the
sweeps set theirs (doc_paths) and built by the loader that builds a mechanism from a file, with
hyper-dual values carried through it: its checks apply to a design's numbers, the design's
stiffness, damping, frames and masses are the loader's, and the analyses of a recorded run take
the run's mechanism.
"""
from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from flexure_sim.cli import main
from flexure_sim.engine.analysis.sensitivity import sensitivities
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism, mechanism_from_dict
from flexure_sim.engine.mechanism.parameters import Parameters, design_of

U = 1.35e-6


@pytest.fixture(scope="module")
def stage():
    return Parameters("microstage")


def test_a_designs_numbers_meet_the_loaders_checks(stage):
    """A neck thickness that the file would refuse is refused as a design value, by its key."""
    with pytest.raises(ConfigError, match=r"hinges\[0\]\.stiffness\.h: must be positive"):
        stage.design({"hinges.a.stiffness.h": -1e-4})
    with pytest.raises(ConfigError, match=r"bodies\[3\]\.mass: must be positive"):
        stage.design({"bodies.body4.mass": hd.HyperDual(-0.01, 1.0, 1.0, 0.0)})


def test_a_design_with_float_values_is_the_mechanism_loaded_from_the_edited_file(stage):
    """Every number of the Design equals the one of the mechanism loaded from the edited YAML."""
    changes = {"hinges.c.stiffness.h": 2.6e-4, "stiffness_models.notch.D": 3.1e-3,
               "hinges.a.a.at.0": 0.007, "bodies.body4.inertia": 1.1e-6,
               "defaults.damping.t_char": 2e-3}
    got = stage.design(changes)
    data = copy.deepcopy(stage.data)
    data["stiffness_models"]["notch"]["D"] = 3.1e-3
    hinge_c = next(h for h in data["hinges"] if h["name"] == "c")
    hinge_c["stiffness"] = dict(data["stiffness_models"]["notch"], h=2.6e-4)
    next(h for h in data["hinges"] if h["name"] == "a")["a"]["at"][0] = 0.007
    next(b for b in data["bodies"] if b["name"] == "body4")["inertia"] = 1.1e-6
    data["defaults"]["damping"]["t_char"] = 2e-3
    want = design_of(mechanism_from_dict(data))
    for field in ("K", "B", "ca", "cb", "phia", "phib", "mass"):
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)
    assert got.geometry == want.geometry


def test_hyper_dual_values_flow_through_the_loaders_formulas(stage):
    """
    d/dh of hinge c's stiffness, damping and stress geometry: the parts the loader carried.

    Ko = kappa E t h^2 with kappa = -0.035 h/D + 0.1109 sqrt(h/D) (eq. 5.28), B = t_char K.
    """
    h0 = stage.value("hinges.c.stiffness.h")
    design = stage.design({"hinges.c.stiffness.h": hd.HyperDual(h0, 1.0, 1.0, 0.0)})
    c = stage.mechanism.hinge_index("c")
    D, E, t = 3e-3, 69e9, 0.02
    dKo = E * t * (-0.035 * 3 * h0**2 / D + 0.1109 * 2.5 * h0**1.5 / np.sqrt(D))
    d2Ko = E * t * (-0.035 * 6 * h0 / D + 0.1109 * 3.75 * h0**0.5 / np.sqrt(D))
    assert design.K.b[c, 0, 0] == pytest.approx(dKo, rel=1e-13)
    assert design.K.d[c, 0, 0] == pytest.approx(d2Ko, rel=1e-13)
    assert design.B.b[c, 0, 0] == pytest.approx(1e-3 * dKo, rel=1e-13)
    others = [k for k in range(len(stage.mechanism.hinges)) if k != c]
    assert not np.any(design.K.b[others]) and not np.any(design.B.b[others])
    assert design.geometry[c].dimensions[1].b == 1.0  # the stress formula's h is the seed


def test_paths_resolve_as_in_the_sweeps(stage):
    """A hinge by its index is the hinge by its name, as in a study file."""
    by_name = sensitivities(stage, ["hinges.a.stiffness.h"], ["gain"], U)
    by_index = sensitivities(stage, ["hinges.0.stiffness.h"], ["gain"], U)
    assert (by_index["gradient"]["gain"]["hinges.0.stiffness.h"]
            == by_name["gradient"]["gain"]["hinges.a.stiffness.h"])


def test_analyse_takes_the_runs_mechanism(tmp_path, capsys):
    """
    A run whose metadata names its mechanism but holds no YAML text still gets its stresses.

    The peak stress ratio is the run's mechanism's (the same as with the YAML recorded).
    """
    from tools_fixtures import record_stage_run

    full, bare = tmp_path / "full.mcap", tmp_path / "bare.mcap"
    record_stage_run(full)
    record_stage_run(bare, mechanism_yaml=False)
    steps = {}
    for path in (full, bare):
        assert main(["analyse", str(path), "--json"]) == 0
        steps[path] = json.loads(capsys.readouterr().out)
    for a, b in zip(steps[full], steps[bare]):
        assert b["peak_stress"] is not None
        assert b["peak_stress"] == a["peak_stress"]
    assert load_mechanism("microstage").hinges[0].stress.sigma_y is not None
