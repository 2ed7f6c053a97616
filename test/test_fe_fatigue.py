"""
Fatigue of ``model: fe`` hinges: the signed stress at the surface points of the FE solve.

Expected values come from elsewhere: the peak von Mises stress of the same solve's stress
field (another path through its results), beam statics for the signs, the notch's K_t from the
independent Q9 model of test/notch_fe.py, the Goodman line by hand with the strengths read
from materials.yaml itself, and the engine's static solves for the stage.
"""
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

import notch_fe
from flexure_sim.cli import main
from flexure_sim.engine.hinges import fatigue
from flexure_sim.engine.hinges.fe import fe_model as model, solves
from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation

ROOT = Path(__file__).resolve().parent.parent
STAGE = ROOT / "config" / "examples" / "microstage_fe.yaml"
GEO = {"D": 3e-3, "h": 0.25e-3, "t": 0.02}
MATERIALS = ROOT / "flexure_sim" / "engine" / "hinges" / "materials.yaml"


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path_factory, monkeypatch):
    """Give the module a cache directory of its own (each geometry solved once, then read)."""
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(tmp_path_factory.getbasetemp() / "fe_fatigue"))


@pytest.mark.parametrize("name, values, plane", [
    ("circular", GEO, "stress"), ("circular", GEO, "strain"),
    ("elliptical", {"a": 1.5e-3, "b": 0.75e-3, "h": 0.25e-3, "t": 0.02}, "stress"),
    ("leaf", {"length": 0.02, "thickness": 0.5e-3, "width": 0.01, "fillet": 1e-3}, "stress"),
])
def test_each_unit_wrench_peaks_at_a_fibre_as_its_von_mises_peak(name, values, plane):
    """
    max_p |a_p,j| is the peak von Mises stress under unit wrench j, to 0.3 %.

    The peak is the largest element-vertex von Mises value of the stress field; the fibres are
    the element-averaged in-plane trace at surface vertices, times sqrt(1 - nu + nu^2) in plane
    strain: two paths that agree only where the surface is traction-free and uniaxial.
    """
    peak = model.stress_coefficients(name, values, 0.33, plane)
    rows = model.fibre_coefficients(name, values, 0.33, plane)
    assert rows.shape[1] == 3 and 2 <= rows.shape[0] <= 12
    np.testing.assert_allclose(np.abs(rows).max(axis=0), peak, rtol=3e-3)


def test_notch_fibre_signs_follow_beam_statics_and_the_root_stress_its_kt():
    """
    Circular notch D/h = 12, plane stress, lengths in h (t = 1).

    A positive moment on body B (at x = +R) bends the neck concave up: sigma_xx = -m y / I,
    tension at the lower root. Tension f_x > 0 pulls both roots. A force f_y > 0 at the centre
    puts the moment -x f_y on the section at x > 0: tension on top there. The lower root's
    stress per unit moment is K_t 6 / (t h^2) with K_t of the independent Q9 model.
    """
    res = solves.solve(solves.Case("circular", (12.0,), 0.33, "stress"))
    at, rows = res.fibres_at, res.fibres
    roots = np.flatnonzero(np.abs(at[:, 0]) < 1e-9)
    assert sorted(at[roots, 1]) == pytest.approx([-0.5, 0.5])
    lower = roots[at[roots, 1] < 0][0]
    upper = roots[at[roots, 1] > 0][0]
    kt = notch_fe.concentration(1.0, 6.0, n=40)
    assert rows[lower, 0] == pytest.approx(6 * kt, rel=3e-3)
    assert rows[upper, 0] == pytest.approx(-6 * kt, rel=3e-3)
    assert rows[lower, 1] > 0 and rows[upper, 1] > 0
    shear = np.flatnonzero(np.abs(at[:, 0]) > 0.1)
    assert len(shear) == 4
    top_right = shear[(at[shear, 0] > 0) & (at[shear, 1] > 0)][0]
    assert rows[top_right, 2] == pytest.approx(res.peak[2], rel=3e-3)
    for p in shear:  # the mirror images: the sign of -x y
        assert np.sign(rows[p, 2]) == np.sign(at[p, 0] * at[p, 1])


def test_leaf_fibres_are_in_the_cantilever_convention():
    """The leaf runs along y: f_y is its tension (every fibre pulled), f_x its shear."""
    values = {"length": 0.02, "thickness": 0.5e-3, "width": 0.01, "fillet": 1e-3}
    rows = model.fibre_coefficients("leaf", values, 0.33, "stress")
    nominal = 1.0 / (values["width"] * values["thickness"])  # f_y / (w T)
    assert np.all(rows[:, 2] > nominal)  # tension everywhere, concentrated by the fillets
    assert np.all(rows[:, 2] < 1.3 * nominal)
    # The shear's end moments f_x L/2 with opposite signs at the two ends (beam statics).
    assert rows[:, 1].min() < 0 < rows[:, 1].max()
    bending = 6 * values["length"] / 2 / (values["width"] * values["thickness"] ** 2)
    assert np.abs(rows[:, 1]).max() == pytest.approx(bending, rel=0.1)


def test_fibre_derivatives_follow_one_material_point():
    """
    The derivative da/dh through the moved meshes against differences of fresh meshes.

    Compared at the notch roots (the moment column's extremes, the axial column's largest),
    where every mesh has a node: a fresh mesh lists its points in an order of its own.
    """
    h0 = GEO["h"]
    seeded = model.fibre_coefficients("circular", dict(GEO, h=hd.HyperDual(h0, 1.0, 1.0)),
                                      0.33, "stress", n=8)
    assert seeded.dtype == object
    real = np.array([[float(hd.real(x)) for x in row] for row in seeded])
    exact = np.array([[float(x.b) for x in row] for row in seeded])
    np.testing.assert_allclose(real, model.fibre_coefficients("circular", GEO, 0.33, "stress",
                                                              n=8), rtol=1e-12)
    step = 0.02 * h0
    plus = model.fibre_coefficients("circular", dict(GEO, h=h0 + step), 0.33, "stress", n=8)
    minus = model.fibre_coefficients("circular", dict(GEO, h=h0 - step), 0.33, "stress", n=8)
    for j, pick in ((0, np.argmax), (0, np.argmin), (1, np.argmax)):
        k, kp, km = pick(real[:, j]), pick(plus[:, j]), pick(minus[:, j])
        fd = (plus[kp, j] - minus[km, j]) / (2 * step)
        assert exact[k, j] == pytest.approx(fd, rel=5e-3), (j, pick)


def _strength(key):
    entry = yaml.safe_load(MATERIALS.read_text())["materials"]["6061-T6"][key]
    return float(entry["value"])


def test_goodman_of_an_fe_hinge_by_hand():
    """
    Hinge a of the FE stage (6061-T6, plane strain): three cycles, 1/n by hand.

    c_m, c_x: peak von Mises per unit moment and axial force (the stress field's own peak).
    (1) 0 -> m: the lower root from 0 to c_m m: 1/n = (c_m m / 2) (1/S_e + 1/S_u).
    (2) -m -> m with a steady tension F: each root c_x F +- c_m m: 1/n = c_m m / S_e
        + c_x F / S_u.
    (3) 0 -> (m, -F) with c_x F > c_m m: both roots in compression, the upper one from 0 to
        -(c_m m + c_x F): a compressive mean, 1/n = (c_m m + c_x F) / 2 / S_e (Shigley 6-12).
    """
    mech = load_mechanism(STAGE)
    g = mech.hinges[mech.hinge_index("a")].stress
    assert g.has_fatigue and g.material == "6061-T6"
    s_e, s_u, s_y = _strength("sigma_e"), _strength("sigma_u"), _strength("sigma_y")
    c_m, c_x, _ = model.stress_coefficients("circular", GEO, 0.33, "strain")
    m, F = 2e-3, 100.0  # 8.7 MPa of bending, 18.6 MPa of tension
    assert c_x * F > c_m * m  # case 3 is compressive at both roots

    def factors(w1, w2):
        row = fatigue.table([("a", g, fatigue.cycle(g, np.array(w1), np.array(w2)))])["a"]
        return row["goodman"], row["soderberg"]

    good, soder = factors([0, 0, 0], [m, 0, 0])
    assert good == pytest.approx(1 / (c_m * m / 2 * (1 / s_e + 1 / s_u)), rel=3e-3)
    assert soder == pytest.approx(1 / (c_m * m / 2 * (1 / s_e + 1 / s_y)), rel=3e-3)
    good, _ = factors([-m, F, 0], [m, F, 0])
    assert good == pytest.approx(1 / (c_m * m / s_e + c_x * F / s_u), rel=3e-3)
    good, soder = factors([0, 0, 0], [m, -F, 0])
    assert good == soder == pytest.approx(2 * s_e / (c_m * m + c_x * F), rel=3e-3)


def test_a_recorded_fe_hinge_cycles_each_point_between_its_extremes():
    """
    ``analyse``'s envelope: each point between its smallest and largest stress of the record.

    By hand: sigma_p(t) = a_p . w(t) summed term by term, for a record of 50 wrenches.
    """
    mech = load_mechanism(STAGE)
    g = mech.hinges[mech.hinge_index("c")].stress
    rows = model.fibre_coefficients("circular", GEO, 0.33, "strain")
    w = np.random.default_rng(5).normal(size=(50, 3)) * [2e-3, 50.0, 50.0]
    sigma = np.array([[sum(a[j] * wt[j] for j in range(3)) for a in rows] for wt in w])
    amplitude, mean = fatigue.envelope(g, w)
    np.testing.assert_allclose(amplitude, (sigma.max(0) - sigma.min(0)) / 2, rtol=1e-12)
    np.testing.assert_allclose(mean, (sigma.max(0) + sigma.min(0)) / 2, rtol=1e-12, atol=1e-3)


@pytest.mark.slow
def test_simulate_static_and_stroke_limit_report_fe_fatigue(capsys):
    """The FE stage gets its fatigue; the infinite-life input, solved again, has n = 1."""
    assert main(["simulate", str(STAGE), "--drive", "step:2e-6", "--static", "--json"]) == 0
    f = json.loads(capsys.readouterr().out)["fatigue"]
    assert f["note"] is None and set(f["hinges"]) == set("abcdefg")
    crit = f["critical"]["goodman"]
    hinges = f["hinges"]
    assert crit["hinge"] == min(hinges, key=lambda h: hinges[h]["goodman"])
    assert hinges[crit["hinge"]]["material"] == "6061-T6"
    mech = load_mechanism(STAGE)
    rest = Simulation(mech).static(0.0).snapshot.wrenches
    life = f["infinite_life"]["goodman"]
    at = Simulation(mech).static(life["input"]).snapshot.wrenches
    assert fatigue.critical(fatigue.between(mech, rest, at)) == (
        life["hinge"], pytest.approx(1.0, abs=1e-8))
    # Cycling from rest, amplitude = mean at every point: n = 1 / (s (1/S_e + 1/S_u)).
    h = hinges[crit["hinge"]]
    assert h["amplitude"] == pytest.approx(h["mean"], rel=1e-8)  # rest is 1e-11 from zero
    assert crit["safety"] == pytest.approx(
        1 / (h["amplitude"] * (1 / _strength("sigma_e") + 1 / _strength("sigma_u"))), rel=1e-8)
    assert main(["simulate", str(STAGE), "--stroke-limit", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["infinite_life"]["goodman"]["input"] == pytest.approx(life["input"], rel=1e-8)
    assert out["fatigue_note"] is None
