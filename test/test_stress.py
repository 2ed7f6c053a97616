"""Hinge stress: the notch and leaf formulas, the stage's stress ratios, the stroke limit."""

import json

import notch_fe
import numpy as np
import pytest

from flexure_sim.cli import main
from flexure_sim.engine.hinges import stress
from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.engine.mechanism.parameters import Parameters
from flexure_sim.engine.solver.simulation import Simulation


def test_notch_concentration_factor_is_roarks_semicircular_u_notch_in_bending():
    # Young & Budynas, "Roark's Formulas for Stress and Strain", 7th ed., Table 17.1, two
    # U-notches in a member of rectangular section, in-plane bending, 0.25 <= h/r <= 2.0:
    # C1 = 0.723 + 2.845 sqrt(h/r) - 0.504 h/r, C2 = -1.836 - 5.746 sqrt(h/r) + 1.314 h/r,
    # C3 = 7.254 - 1.885 sqrt(h/r) + 1.646 h/r, C4 = -5.140 + 4.785 sqrt(h/r) - 2.456 h/r
    # (as printed at eng-calculations.com, "two U-notches ... in-plane bending"). Semicircular
    # notches h/r = 1: C = (3.064, -6.268, 7.015, -2.811), evaluated here by hand.
    def published(x):
        return 3.064 - 6.268 * x + 7.015 * x**2 - 2.811 * x**3

    # Neck as thick as the holes (h = D): 2a/W = D / (2 D) = 0.5 -> 1.332375.
    assert stress.notch_concentration(3e-3, 3e-3) == pytest.approx(1.332375, abs=1e-12)
    # The stage's hinge, h = 0.25 mm, D = 3 mm: 2a/W = 3 / 3.25.
    assert stress.notch_concentration(0.25e-3, 3e-3) == pytest.approx(
        published(3 / 3.25), abs=1e-12
    )
    assert published(3 / 3.25) == pytest.approx(1.04450, abs=1e-5)
    # A thin neck between large holes concentrates no stress (the coefficients sum to 1).
    assert stress.notch_concentration(1e-12, 3e-3) == pytest.approx(1.0, abs=1e-6)
    # Deep notches (h/r > 2) use the second row: h/r = 4, 2h/D = 0.5 gives
    # C1 = 0.833 + 4.138 - 0.036, C2 = 0.024 - 10.766 + 0.504, C3 = -0.856 + 12.92 - 0.796,
    # C4 = 0.999 - 6.292 + 0.328.
    want = 4.935 + (-10.238) * 0.5 + 11.268 * 0.25 + (-4.965) * 0.125
    assert stress.u_notch_bending_factor(4.0, 1.0, 16.0) == pytest.approx(want, abs=1e-12)
    with pytest.raises(ValueError, match="outside Roark's range"):
        stress.u_notch_bending_factor(0.1, 1.0, 4.0)


def test_notch_stress_is_beam_bending_plus_axial_times_kt():
    # 1 N m on a 0.25 mm x 20 mm neck: 6 M / (t h^2) = 6 / (0.02 * 6.25e-8) = 4.8 GPa nominal;
    # 10 N axial: 10 / (0.02 * 2.5e-4) = 2 MPa. Shear force has no lever arm at the centre.
    kt = stress.notch_concentration(0.25e-3, 3e-3)
    s = stress.notch_stress(np.array([1.0, -10.0, 1e3]), 3e-3, 0.25e-3, 0.02)
    assert s == pytest.approx(kt * (4.8e9 + 2e6), rel=1e-12)


def test_leaf_stress_adds_the_shear_force_lever_arm():
    # Leaf 10 mm x 1 mm x 5 mm: end moment |m| + |f_x| L/2 = 0.01 + 2 * 0.005 = 0.02 N m;
    # 6 * 0.02 / (5e-3 * 1e-6) = 24 MPa; axial 5 N / 5e-6 m^2 = 1 MPa.
    s = stress.leaf_stress(np.array([-0.01, 2.0, 5.0]), 0.010, 0.001, 0.005)
    assert s == pytest.approx(25e6, rel=1e-12)


def test_stage_stroke_limit_reaches_yield_exactly():
    mech = load_mechanism("microstage")
    sim = Simulation(mech)
    u, hinge = stress.stroke_limit(sim)
    table = stress.stress_table(sim.static(u).snapshot.wrenches, mech)
    assert stress.peak_ratio(table) == (hinge, pytest.approx(1.0, abs=1e-8))
    assert u > sim.drive.stroke[1]  # the piezo's 2 um stroke is far from yield
    # Stress grows nearly linearly with the input: the ratio at full stroke times the limit.
    full = stress.peak_ratio(
        stress.stress_table(sim.static(2e-6).snapshot.wrenches, mech)
    )[1]
    assert u == pytest.approx(2e-6 / full, rel=1e-2)


def test_simulate_static_shows_stress_and_stroke_limit_command(capsys):
    import json

    assert main(["simulate", "microstage", "--drive", "step:2e-6", "--static", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["hinge_stress"]) == set("abcdefg")
    assert out["hinge_stress"]["c"]["sigma_y"] == 276e6
    assert main(["simulate", "microstage", "--stroke-limit"]) == 0
    assert "stroke limit (first hinge at yield)" in capsys.readouterr().out
    assert main(["simulate", "fourbar_mixed", "--stroke-limit"]) == 2
    assert "has no drive" in capsys.readouterr().err


def test_analyse_reports_the_peak_stress_ratio_of_each_step(tmp_path, capsys):
    """
    A recorded stage run analysed from the file agrees with the engine stepped here.

    The run (tools_fixtures: the engine stepped as the node steps it, written as the node
    writes it) is analysed from the file, against the same schedule stepped here with the
    engine and the stress of every tick's snapshot. The damping wrenches of the transient
    make the peaks exceed the static ratio of the level (which they must reach).
    """
    from tools_fixtures import DEMO_LEVELS, record_stage_run

    path = tmp_path / "stage.mcap"
    record_stage_run(path)  # rest 10 ms, then each level for 20 ms, 1 kHz ticks of 10 steps
    assert main(["analyse", str(path), "--json"]) == 0
    steps = json.loads(capsys.readouterr().out)

    mech = load_mechanism("microstage")
    sim = Simulation(mech, dt=1e-4, relinearize_tol=1e-4)
    expected = [(0.0, None)] * len(DEMO_LEVELS)
    for tick in range(110):
        if tick >= 10 and (tick - 10) % 20 == 0:
            sim.set_command(DEMO_LEVELS[(tick - 10) // 20])
        sim.step(10)
        if tick >= 10:
            k = (tick - 10) // 20
            table = stress.stress_table(sim.snapshot().wrenches, mech)
            hinge, ratio = stress.peak_ratio(table)
            if ratio > expected[k][0]:
                expected[k] = (ratio, hinge)
    for s, (ratio, hinge), level in zip(steps, expected, DEMO_LEVELS):
        assert s["peak_stress"]["hinge"] == hinge
        assert s["peak_stress"]["ratio"] == pytest.approx(ratio, rel=1e-9)
        static = stress.peak_ratio(
            stress.stress_table(sim.static(level).snapshot.wrenches, mech)
        )[1]
        assert s["peak_stress"]["ratio"] >= static * (1 - 1e-6)
    assert main(["analyse", str(path)]) == 0
    assert "peak stress/yield" in capsys.readouterr().out


def test_static_stress_with_a_polynomial_hinge_covers_the_notch_hinges(capsys):
    """
    A fitted polynomial hinge has no geometry.

    No stress for it, the others as usual; the analyses that need the generic force chain say why
    they cannot run.
    """
    from flexure_sim.engine.mechanism.loader import resolve_mechanism_path

    path = str(
        resolve_mechanism_path("microstage").parent / "examples" / "microstage_polynomial_a.yaml"
    )
    assert main(["simulate", path, "--drive", "step:1e-6", "--static", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["hinge_stress"]) == set("bcdefg")
    assert main(["linearize", path, "-o", "model.npz"]) == 2
    assert "not fitted polynomial laws" in capsys.readouterr().err


def _two_hinge_doc(sigma_y="250.0e6"):
    """
    Return a mechanism document with one body on a notch hinge, a leaf hinge and a matrix hinge.

    The notch uses a named model with sigma_y as PyYAML reads 250.0e6 (a string), the leaf is
    inline without sigma_y; no file behind it.
    """
    return {
        "name": "two_hinges",
        "defaults": {"law": "twistor", "damping": {"t_char": 1e-4}},
        "stiffness_models": {"n": {"model": "notch", "D": 0.002, "h": 3.0e-4, "t": 0.01,
                                   "E": "69.0e9", "nu": 0.33, "sigma_y": sigma_y}},
        "bodies": [{"name": "ground", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
                   {"name": "m", "mass": 0.01, "inertia": 1e-6, "pose": [0.0, 0.0, 0.0]}],
        "hinges": [
            {"name": "n", "a": {"body": "ground", "at": [0.01, 0.0]},
             "b": {"body": "m", "at": [0.01, 0.0]}, "stiffness": "n"},
            {"name": "leaf", "a": {"body": "ground", "at": [-0.01, 0.0]},
             "b": {"body": "m", "at": [-0.01, 0.0]},
             "stiffness": {"model": "cantilever", "length": 0.01, "thickness": 0.001,
                           "width": 0.005, "E": "69.0e9", "nu": 0.33}},
            {"name": "k", "a": {"body": "ground", "at": [0.0, 0.01]},
             "b": {"body": "m", "at": [0.0, 0.01]},
             "stiffness": {"model": "matrix", "Ko": 1.0, "Kt": [1e5, 1e5]}},
        ],
        "constraints": [{"type": "fixed", "body": "ground"}],
    }


def test_stress_geometry_is_part_of_the_loaded_mechanism_with_the_stiffness_numbers():
    """
    Each hinge's stress geometry comes with the mechanism (no file to re-read).

    The numbers its stiffness formula used, sigma_y as a number; none for a matrix hinge.
    """
    from flexure_sim.engine.hinges.stiffness import cantilever_stiffness, notch_stiffness

    mech = mechanism_from_dict(_two_hinge_doc(), source="<no file>")
    n, leaf, k = mech.hinges
    assert n.stress == stress.StressGeometry("notch", (0.002, 3.0e-4, 0.01), 250e6)
    assert leaf.stress == stress.StressGeometry("cantilever", (0.01, 0.001, 0.005), None)
    assert k.stress is None
    np.testing.assert_array_equal(notch_stiffness(*n.stress.dimensions, 69e9, 0.33), n.law.K)
    np.testing.assert_array_equal(cantilever_stiffness(*leaf.stress.dimensions, 69e9, 0.33),
                                  leaf.law.K)
    # The stress table from the mechanism alone, against the formulas by hand: leaf
    # 6 (|m| + |f_x| L / 2) / (w T^2) + |f_y| / (w T); notch K_t (6 |m| / (t h^2) + |f_x| / (t h)).
    w = np.array([[0.02, -3.0, 40.0], [-0.01, 2.0, 5.0], [1.0, 1.0, 1.0]])
    table = stress.stress_table(w, mech)
    assert set(table) == {"n", "leaf"}
    assert table["leaf"] == {"stress": pytest.approx(25e6, rel=1e-12), "sigma_y": None,
                             "ratio": None, "material": None}
    kt = stress.notch_concentration(3.0e-4, 0.002)
    s_n = kt * (6 * 0.02 / (0.01 * 9e-8) + 3.0 / (0.01 * 3e-4))
    assert table["n"]["stress"] == pytest.approx(s_n, rel=1e-12)
    assert table["n"]["ratio"] == pytest.approx(s_n / 250e6, rel=1e-12)
    # The per-tick form of the ratios (node diagnostics) is the same formula.
    names, idx, C = stress.ratio_map(mech)
    assert names == ["n"] and idx.tolist() == [0]
    assert (C * np.abs(w[idx])).sum(1)[0] == pytest.approx(table["n"]["ratio"], rel=1e-12)


def test_design_geometry_is_the_mechanisms_stress_geometry():
    """design.py (the sensitivities) and the loaded mechanism share one stress geometry."""
    params = Parameters("microstage")
    assert params.design().geometry == [h.stress for h in params.mechanism.hinges]
    assert all(h.stress.sigma_y == 276e6 for h in params.mechanism.hinges)


# Pilkey and Pilkey, "Peterson's Stress Concentration Factors", 3rd ed. (Wiley, 2008), Chart
# 2.24: bending of a flat beam with opposite semicircular notches (from Isida's solutions),
# K_tn = 3.065 - 6.637 (2r/H) + 8.229 (2r/H)^2 - 3.636 (2r/H)^3 with the nominal stress
# 6 M / (t d^2) on the net width d = H - 2r -- the same definition as Roark's Table 17.1.
# Coefficients as quoted in the public R function stress.concentration.factor (Reuel Smith,
# 2022-2024; geometry "rect_2semicirc_edge", load type 2, "Chart 2.3, 2.24 in Peterson's
# Stress Concentration Factors"); that function's tension row for the same notches (Chart 2.3,
# 3.065 - 3.472 x + 1.009 x^2 + 0.405 x^3) is also what eng-calculations.com prints for
# Peterson's "tension strip with opposite semicircular edge notches".
def _peterson_chart_2_24(x):
    return 3.065 - 6.637 * x + 8.229 * x**2 - 3.636 * x**3


def test_notch_stress_against_petersons_published_semicircular_notch_factor():
    """
    Worked example: Peterson's Chart 2.24 (above) for a stated geometry and moment.

    A bar H = 10 mm wide, t = 5 mm thick, two semicircular notches r = 2.5 mm (2r/H = 0.5,
    neck d = 5 mm), M = 1 N m: sigma_nom = 6 M / (t d^2) = 48 MPa, K_tn = 3.065 - 3.3185 +
    2.05725 - 0.4545 = 1.34925, sigma_max = 64.764 MPa. Our notch hinge of neck h = 5 mm
    between holes D = 5 mm is that geometry. Precision: the two handbook fits of the same
    elasticity solutions, Roark's Table 17.1 and Peterson's Chart 2.24, differ by up to 1.6 %
    for 2r/H <= 0.5, so 2 % is what the published numbers allow; at 2r/H -> 0 both give the
    semicircular edge notch's 3.065 (Peterson's constant term, 4 digits).
    """
    assert 6.0 * 1.0 / (5e-3 * 5e-3**2) == pytest.approx(48e6, rel=1e-12)
    assert _peterson_chart_2_24(0.5) == pytest.approx(1.34925, abs=1e-12)
    s = stress.notch_stress(np.array([1.0, 0.0, 0.0]), 5e-3, 5e-3, 5e-3)
    assert s == pytest.approx(64.764e6, rel=0.02)
    assert stress.notch_concentration(5e-3, 5e-3) == pytest.approx(1.34925, rel=0.02)
    for x in (0.1, 0.2, 0.3, 0.4, 0.5):  # 2r/H = D / (h + D)
        D = 1e-3
        kt = stress.notch_concentration(D * (1 - x) / x, D)
        assert kt == pytest.approx(_peterson_chart_2_24(x), rel=0.02), x
    # 2r/H -> 0 (h = 1e4 D): the semicircular edge notch, 3.065.
    assert stress.notch_concentration(10.0, 1e-3) == pytest.approx(3.065, abs=2e-3)


def test_notch_concentration_of_thin_necks_against_a_finite_element_model():
    """
    The flexure regime, 2r/H -> 1, checked by a second method (test/notch_fe.py).

    There the published fits part ways: at the stage's h/D = 1/12 (2r/H = 12/13) Roark's
    Table 17.1 gives 1.0445 and Peterson's Chart 2.24 polynomial 1.0905. A plane-stress
    finite-element model of the notched strip in pure bending decides: 1.032 (it converges
    from below, about 0.2 % low at this mesh), so Roark's factor, the one the engine uses, is
    1.2 % conservative and Peterson's polynomial 5.7 % off there. The same model reproduces
    Peterson's published 1.34925 at 2r/H = 0.5 to 0.7 %.
    """
    r = 1.5e-3
    fe_half = notch_fe.concentration(2 * r, r)  # h = D: 2r/H = 0.5
    assert fe_half == pytest.approx(_peterson_chart_2_24(0.5), rel=0.01)
    assert stress.notch_concentration(2 * r, 2 * r) == pytest.approx(fe_half, rel=0.015)
    fe_stage = notch_fe.concentration(0.25e-3, r)
    kt_stage = stress.notch_concentration(0.25e-3, 2 * r)
    assert fe_stage == pytest.approx(1.032, abs=2e-3)
    assert fe_stage < kt_stage < 1.015 * fe_stage
