"""
Fitting polynomial hinges (Ch. 7, Appendix B).

Exact recovery, Chapter 7.1, held-out error against order and data size, bad input, the command,
and fitted hinges in mechanisms.
"""
import dataclasses
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import yaml

from conftest import ROOT
from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism
from flexure_sim.engine.fitting.datasets import (
    NOTCH_K,
    Leaf,
    cantilever_data,
    error_table,
    law_data,
    leaf_tip,
    sample_box,
)
from flexure_sim.engine.fitting.least_squares import (
    FitError, fit_polynomial, number_of_unknowns, predict_wrench,
)
from flexure_sim.engine.laws.quadratic import QuadraticLaw, evaluate, wrench_on_element
from flexure_sim.engine.kinematics.planar import rot
from flexure_sim.engine.laws.monomials import monomial_exponents
from flexure_sim.engine.laws.polynomial import PolynomialLaw
from flexure_sim.engine.mechanism.polynomial_files import load_law
from flexure_sim.engine.fitting.randomtest import randomtest_report
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.fitting.wrench_data import (
    DataError, WrenchData, read_wrench_csv, write_wrench_csv,
)

EXAMPLES = ROOT / "config" / "examples"
K_LEAF = Leaf().small_displacement_stiffness()


def quad(coords, K=NOTCH_K):
    return QuadraticLaw(coords, K, 0 * K)


# ------------------------------------------------------------ basics and exactness

def test_predict_wrench_is_the_engine_wrench():
    """predict_wrench (vectorised) equals hinge_laws.evaluate + wrench_on_element."""
    rng = np.random.default_rng(0)
    law = quad(
        "twistor", np.array([[2.0, 30.0, -12.0], [30.0, 4.0e4, 5.0e3], [-12.0, 5.0e3, 2.0e4]])
    )
    alpha, p = sample_box(7, 2.0, (0.05, 0.05), rng)
    ev = evaluate([law] * 7, alpha, p, np.zeros((7, 3)))
    assert predict_wrench(law, alpha, p) == pytest.approx(
        wrench_on_element(alpha, ev.grad), rel=1e-13
    )


def test_unknown_counts():
    # twistor, sigma_degree 0: C(N+3,3) - 4; with sigma: C(N+3,3) + C(N+2,3) - 4;
    # twist: C(N+3,3) - 4
    for N in range(2, 9):
        assert number_of_unknowns("twistor", N) == math.comb(N + 3, 3) - 4
        assert number_of_unknowns("twistor", N, 1) == math.comb(N + 3, 3) + math.comb(N + 2, 3) - 4
        assert number_of_unknowns("twist", N) == math.comb(N + 3, 3) - 4


def _random_poly(coords, order, rng, sigma_degree=0):
    k = 4 if coords == "twistor" else 3
    exps = monomial_exponents(k, order)
    deg = exps.sum(axis=1)
    keep = deg >= 2
    if coords == "twistor":
        keep = (keep & (exps[:, 0] <= sigma_degree)) | (
            (deg == 1) & (exps[:, 0] == 1) & (sigma_degree == 1)
        )
    exps = exps[keep]
    scale = (
        np.array([0.1, 0.5, 1e-3, 1e-3]) if coords == "twistor" else np.array([1.0, 2e-3, 2e-3])
    )
    return PolynomialLaw(coords, order, exps, rng.normal(size=len(exps)), scale, 0.2)


@pytest.mark.parametrize(
    "coords,sigma_degree,alpha_max", [("twistor", 0, 1.0), ("twistor", 1, 2.8), ("twist", 0, 2.0)]
)
@pytest.mark.parametrize("order", [2, 4, 6])
def test_fit_recovers_a_polynomial_of_the_same_order(coords, sigma_degree, alpha_max, order):
    rng = np.random.default_rng(order)
    truth = _random_poly(coords, order, rng, sigma_degree)
    train = law_data(truth, *sample_box(400, alpha_max, (2e-3, 2e-3), rng))
    test = law_data(truth, *sample_box(300, alpha_max, (2e-3, 2e-3), rng))
    res = fit_polynomial(train, order, coords, sigma_degree=sigma_degree, test=test)
    assert res.report["test_max_rel"] < 1e-8, res.report["test"]
    assert res.report["rank"] == res.report["unknowns"]
    # the same function: energy and stiffness at rest
    c = train.alpha[:5], train.p[:5]
    e_fit = evaluate([res.law] * 5, *c, np.zeros((5, 3))).energy
    e_true = evaluate([truth] * 5, *c, np.zeros((5, 3))).energy
    assert e_fit == pytest.approx(e_true, rel=1e-7, abs=1e-9 * np.abs(e_true).max())


@pytest.mark.parametrize("coords", ["twistor", "twist"])
def test_fit_of_a_quadratic_law_gives_its_stiffness_and_damping(coords):
    rng = np.random.default_rng(3)
    law = QuadraticLaw(coords, NOTCH_K, 1e-3 * NOTCH_K)
    data = law_data(law, *sample_box(200, 0.3, (2e-5, 2e-5), rng))
    res = fit_polynomial(data, 2, coords)
    assert res.report["train_max_rel"] < 1e-10
    K = res.law.stiffness_at_rest()
    assert np.diag(K) == pytest.approx(np.diag(NOTCH_K), rel=1e-9)
    assert abs(K[0, 1]) < 1e-9 * math.sqrt(K[0, 0] * K[1, 1])
    # B = t_char K mapped as the quadratic laws map it: the same dissipation at any pose
    fitted = res.law.with_damping(1e-3 * K)
    r = np.array([[0.25, 1e-5, -2e-5]])
    rdot = np.array([[3.0, 1e-3, 2e-3]])
    a = evaluate([fitted], r[:, 0], r[:, 1:], rdot)
    b = evaluate([law], r[:, 0], r[:, 1:], rdot)
    assert a.damping_force == pytest.approx(b.damping_force, rel=1e-8)


def test_regularization_shrinks_and_still_fits():
    rng = np.random.default_rng(4)
    data = law_data(quad("twist"), *sample_box(100, 0.5, (2e-5, 2e-5), rng))
    plain = fit_polynomial(data, 4, "twist")
    ridge = fit_polynomial(data, 4, "twist", regularization=1e-6)
    assert np.linalg.norm(ridge.law.coefficients) < np.linalg.norm(plain.law.coefficients)
    assert ridge.report["train_max_rel"] < 1e-2


# ------------------------------------------------------------------ Chapter 7.1

@pytest.mark.parametrize("alpha_dist", [math.pi / 4, 5 * math.pi / 4])
def test_chapter_7_1_fits_the_training_rows_and_predicts_nothing(alpha_dist):
    """
    randomtest.sce: 17 random configurations, random wrenches, order 4.

    The makeAB_Q system has 68 equations for 70 coefficients, so it interpolates (the dissertation
    reports 2.6e-5 against 0.944): the training error measures the conditioning, not a model. On 17
    fresh configurations the same polynomial is off by more than the wrenches themselves.
    """
    rep = randomtest_report(seed=22, alpha_dist=alpha_dist)
    diss = rep["dissertation_method"]
    assert diss["equations"] == 68 and diss["unknowns"] == 70
    assert max(diss["train"]["max_rel"]) < 1e-2
    assert max(diss["train"]["max_measured"]) <= 1.0
    assert min(diss["fresh"]["max_rel"]) > 1.0
    # flexure_sim's fit has 3 equations per row; without sigma terms (31 unknowns for 51
    # equations) it cannot follow random wrenches at all.
    ours = rep["flexure_sim_sigma_degree_0"]
    assert ours["equations"] == 51 and ours["unknowns"] == 31
    assert max(ours["train"]["max_rel"]) > 0.1


# ------------------------------------------------ held-out error vs order and size

def test_held_out_error_falls_with_order_and_data_twistor_law_in_twist_coordinates():
    """
    Twistor quadratic law data at large deflections, fitted in twist coordinates.

    Data from the twistor quadratic law at large deflections (|alpha| <= 1.5 rad) fitted
    in twist coordinates: not a polynomial there, so the held-out error measures the
    approximation and must fall with the order (the law is even, so even orders are the
    steps) and with the data size.
    """
    t = error_table("twistor-quadratic", "twist", [2, 4, 6, 8], [60, 500], test_rows=500, seed=2)
    err = np.array([[np.inf if v is None else v for v in row] for row in t["test_max_rel"]])
    big = err[:, 1]
    assert big[0] > 0.1
    assert np.all(big[1:] < big[:-1] / 5), big
    assert big[-1] < 1e-4
    assert err[-1, 0] > 5 * err[-1, 1]  # order 8 on 60 rows: 2 equations per unknown, worse


def test_held_out_error_falls_with_order_cantilever():
    """Large-deflection leaf (rotations to 0.5 rad): the case with no closed form."""
    t = error_table("cantilever", "twistor", [2, 4, 6, 8], [400], test_rows=400, seed=3)
    err = np.array([row[0] for row in t["test_max_rel"]])
    assert err[0] > 0.3
    assert np.all(err[1:] < err[:-1] / 3), err
    assert err[-1] < 3e-3


def test_cantilever_model_small_displacement_stiffness_and_conservative():
    """
    The leaf model reduces to the linear Timoshenko cantilever at small loads.

    Its tangent stiffness d(dU/dr)/dr is symmetric at large deflection (a potential exists).
    """
    leaf = Leaf()

    def grad_r(q):
        r, w = leaf_tip(leaf, q[None, 1:], np.array([q[0]]))
        return r[0], np.r_[w[0, 0], rot(r[0, 0]) @ w[0, 1:]]

    EI, L = leaf.EI, leaf.length
    h = np.array([EI / L, EI / L**2, EI / L**2]) * 1e-6
    for load in (1e-6, 0.3):
        q0 = load * np.array([0.7 * EI / L, 0.5 * EI / L**2, -0.8 * EI / L**2])
        dr, dg = np.zeros((3, 3)), np.zeros((3, 3))
        for i in range(3):
            e = np.zeros(3)
            e[i] = h[i]
            (rp, gp), (rm, gm) = grad_r(q0 + e), grad_r(q0 - e)
            dr[:, i], dg[:, i] = (rp - rm) / (2 * h[i]), (gp - gm) / (2 * h[i])
        K = dg @ np.linalg.inv(dr)
        assert np.abs(K - K.T).max() < 1e-6 * np.abs(K).max()
        if load < 1e-3:
            assert np.diag(K) == pytest.approx(
                np.diag(leaf.small_displacement_stiffness()), rel=1e-5
            )
    data = cantilever_data(500, np.random.default_rng(0))
    assert 0.4 < np.abs(data.alpha).max() < 0.6


# ------------------------------------------------------------------ bad input

def _csv(tmp_path, text, name="data.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


GOOD_HEADER = "alpha,px,py,m,fx,fy\n"


@pytest.mark.parametrize("text,fragments", [
    ("alpha,px,py,m,fx\n0,0,0,0,0\n", ["missing column fy", "alpha, px, py, m, fx, fy"]),
    ("alpha,px,m\n0,0,0\n", ["missing columns py, fx, fy"]),
    (GOOD_HEADER + "0.1,1e-6,0,1e-3,1,2\n0.2,nan,0,1e-3,1,2\n", ["line 3", "'px'", "finite"]),
    (GOOD_HEADER + "0.1,1e-6,0,1e-3,1,inf\n", ["line 2", "'fy'", "finite"]),
    (GOOD_HEADER + "0.1,1e-6,0,1e-3,one,2\n", ["line 2", "'fx'", "'one' is not a number"]),
    (GOOD_HEADER + "0.1,1e-6,0,1e-3,1\n", ["line 2", "expected 6 fields, got 5"]),
    (GOOD_HEADER + "0.1,1e-6,0,1e-3,1,\n", ["line 2", "'fy'", "'' is not a number"]),
    (GOOD_HEADER + "3.5,1e-6,0,1e-3,1,2\n", ["line 2", "'alpha': 3.5 rad", "outside (-pi, pi)"]),
    (GOOD_HEADER, ["no data rows"]),
    ("# only a comment\n", ["no header"]),
    ("alpha,px,py,m,fx,fy,m\n", ["'m' appears more than once"]),
])
def test_bad_csv_messages(tmp_path, text, fragments):
    path = _csv(tmp_path, text)
    with pytest.raises(DataError) as err:
        read_wrench_csv(path)
    msg = str(err.value)
    assert msg.startswith(str(path)), msg
    for f in fragments:
        assert f in msg, msg


def test_csv_round_trip_with_extra_columns_and_comments(tmp_path):
    rng = np.random.default_rng(1)
    data = law_data(quad("twistor"), *sample_box(5, 1e-3, (1e-6, 1e-6), rng))
    p = tmp_path / "d.csv"
    write_wrench_csv(p, data, "two\ncomment lines")
    back = read_wrench_csv(p)
    assert np.array_equal(back.wrench, data.wrench) and np.array_equal(back.p, data.p)
    # reordered columns plus an extra one
    lines = p.read_text().splitlines()
    rows = [line.split(",") for line in lines[3:]]
    reordered = "fy,trial,m,alpha,fx,py,px\n" + "\n".join(
        ",".join([r[5], str(i), r[3], r[0], r[4], r[2], r[1]]) for i, r in enumerate(rows))
    back2 = read_wrench_csv(_csv(tmp_path, reordered, "r.csv"))
    assert np.array_equal(back2.wrench, data.wrench) and np.array_equal(back2.alpha, data.alpha)


def test_too_few_rows_for_the_order():
    rng = np.random.default_rng(2)
    data = law_data(quad("twistor"), *sample_box(17, 0.1, (1e-6, 1e-6), rng))
    with pytest.raises(FitError) as err:
        fit_polynomial(data, 5, "twistor")
    msg = str(err.value)
    assert "too few rows for order 5" in msg and "17 rows give 51 equations" in msg
    assert "52 unknown coefficients" in msg and "at least 18 rows" in msg


def test_rank_deficient_design_names_the_terms():
    """Pure translations (alpha = 0 in every row) cannot determine the rotation terms."""
    rng = np.random.default_rng(5)
    _, p = sample_box(100, 0.0, (1e-6, 1e-6), rng)
    data = law_data(quad("twistor"), np.zeros(100), p)
    with pytest.raises(FitError) as err:
        fit_polynomial(data, 3, "twistor")
    msg = str(err.value)
    assert "rank-deficient design" in msg and "xi^2" in msg and "never move xi" in msg
    assert "--regularization" in msg
    # A ridge makes the problem well posed (the rotation terms come out zero).
    res = fit_polynomial(data, 3, "twistor", regularization=1e-10)
    assert res.report["rank"] < res.report["unknowns"]
    assert res.report["train_max_rel"] < 1e-6


def test_numerically_rank_deficient_design_names_the_collinear_terms():
    """
    Check sigma - 1 = -xi^2/2 + O(xi^4).

    At milliradian rotations the sigma terms cannot be told from the xi terms (why sigma_degree
    defaults to 0).
    """
    rng = np.random.default_rng(6)
    data = law_data(quad("twistor"), *sample_box(200, 1e-3, (1e-6, 1e-6), rng))
    with pytest.raises(FitError) as err:
        fit_polynomial(data, 4, "twistor", sigma_degree=1)
    msg = str(err.value)
    assert "rank-deficient design: numerical rank" in msg and "sigma" in msg
    assert fit_polynomial(data, 4, "twistor").report["condition_number"] < 1e3


def test_other_bad_arguments():
    rng = np.random.default_rng(7)
    data = law_data(quad("twist"), *sample_box(50, 0.1, (1e-6, 1e-6), rng))
    with pytest.raises(FitError, match="order must be an integer from 2"):
        fit_polynomial(data, 1, "twist")
    with pytest.raises(FitError, match="coordinates must be twistor or twist"):
        fit_polynomial(data, 2, "quaternion")
    with pytest.raises(FitError, match="regularization must be a non-negative"):
        fit_polynomial(data, 2, "twist", regularization=-1.0)
    zero = WrenchData(data.alpha, data.p, np.zeros_like(data.wrench))
    with pytest.raises(FitError, match="every wrench is zero"):
        fit_polynomial(zero, 2, "twist")


# -------------------------------------------------------------------- command

def run(*args, cwd=ROOT):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "flexure_sim.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )


def test_cli_fit_json_and_output_file(tmp_path):
    rng = np.random.default_rng(8)
    law = quad("twistor")
    train, test = tmp_path / "train.csv", tmp_path / "test.csv"
    write_wrench_csv(train, law_data(law, *sample_box(300, 1.0, (2e-5, 2e-5), rng)))
    write_wrench_csv(test, law_data(law, *sample_box(100, 1.0, (2e-5, 2e-5), rng)))
    out = tmp_path / "hinge.yaml"
    p = run(
        "fit",
        str(train),
        "--order",
        "4",
        "--coords",
        "twist",
        "--test",
        str(test),
        "-o",
        str(out),
        "--json",
    )
    assert p.returncode == 0, p.stderr
    rep = json.loads(p.stdout)
    assert len(rep["train_rms"]) == 3 and len(rep["test_max_abs"]) == 3
    assert 1e-6 < rep["test_max_rel"] < 0.1  # twist polynomial of a twistor law: close, not exact
    assert rep["report"]["unknowns"] == 31 and rep["report"]["rows"] == 300
    doc = yaml.safe_load(out.read_text())
    assert doc["fit"]["test_max_rel"] == pytest.approx(rep["test_max_rel"])
    assert doc["provenance"]["data"] == str(train) and len(doc["provenance"]["data_sha256"]) == 64
    assert load_law(out).order == 4
    # human-readable form
    p = run("fit", str(train), "--order", "2", "--coords", "twistor")
    assert (
        p.returncode == 0
        and "worst relative error" in p.stdout
        and "stiffness at rest" in p.stdout
    )


def test_cli_fit_errors_are_messages_not_tracebacks(tmp_path):
    bad = _csv(tmp_path, "alpha,px,py,m,fx\n0,0,0,0,0\n")
    p = run("fit", str(bad), "--order", "3")
    assert p.returncode == 2 and "missing column fy" in p.stderr and "Traceback" not in p.stderr
    few = tmp_path / "few.csv"
    write_wrench_csv(
        few, law_data(quad("twistor"), *sample_box(5, 0.1, (1e-6, 1e-6), np.random.default_rng(0)))
    )
    p = run("fit", str(few), "--order", "4")
    assert (
        p.returncode == 2
        and "too few rows for order 4" in p.stderr
        and "Traceback" not in p.stderr
    )
    p = run("fit", str(tmp_path / "absent.csv"), "--order", "2")
    assert p.returncode == 2 and "absent.csv" in p.stderr and "cannot read" in p.stderr
    p = run("fit", str(few), "--order", "2", "--regularization", "-1")
    assert p.returncode == 2 and "--regularization" in p.stderr


# ------------------------------------------------ fitted hinges in mechanisms

def test_example_stage_matches_the_notch_stage_within_the_fit_error():
    """
    config/examples.

    Hinge a of the stage fitted (order 4 twistor) to noisy notch-law data; the static answer agrees
    with the built-in stage within the fit's reported held-out error, and the damping is the notch
    hinge's B = t_char K.
    """
    fitted = load_mechanism(EXAMPLES / "microstage_polynomial_a.yaml")
    builtin = load_mechanism("microstage")
    report = yaml.safe_load((EXAMPLES / "notch_hinge_order4.yaml").read_text())["fit"]
    tol = report["test_max_rel"]
    assert 1e-4 < tol < 1e-2
    a = Simulation(fitted).static(1.35e-6).snapshot
    b = Simulation(builtin).static(1.35e-6).snapshot
    assert abs(a.output - b.output) <= tol * abs(b.output)
    assert abs(a.compression - b.compression) <= tol * abs(b.compression)
    # ... and the step response too (damping B = t_char K of the fitted K): 2 ms of a 1.35 um step
    outs = []
    for mech in (fitted, builtin):
        sim = Simulation(mech)
        sim.set_command(1.35e-6)
        sim.step(20)
        outs.append(sim.snapshot().output)
    assert outs[1] > 0.5 * b.output
    assert abs(outs[0] - outs[1]) <= tol * abs(outs[1])
    h_fit, h_ref = fitted.hinges[0], builtin.hinges[0]
    assert isinstance(h_fit.law, PolynomialLaw)
    assert np.diag(h_fit.law.B) == pytest.approx(np.diag(h_ref.law.B), rel=tol)
    assert h_fit.stiffness_source.startswith("polynomial:")


def test_example_hinge_file_is_what_the_command_writes(tmp_path):
    """The shipped fit is reproducible from the shipped CSVs."""
    out = tmp_path / "again.yaml"
    p = run(
        "fit",
        "notch_hinge_train.csv",
        "--order",
        "4",
        "--coords",
        "twistor",
        "--test",
        "notch_hinge_test.csv",
        "-o",
        str(out),
        cwd=EXAMPLES,
    )
    assert p.returncode == 0, p.stderr
    shipped, again = load_law(EXAMPLES / "notch_hinge_order4.yaml"), load_law(out)
    assert np.array_equal(shipped.exponents, again.exponents)
    tol = 1e-9 * np.abs(shipped.coefficients).max()
    assert again.coefficients == pytest.approx(shipped.coefficients, rel=1e-6, abs=tol)


def test_fourbar_with_fitted_hinges_matches_at_large_deflection():
    """
    Four-bar with order-6 twist polynomial hinges: the static pose agrees.

    All four leaf hinges of the four-bar replaced by an order-6 twist polynomial fitted to
    their twistor quadratic law (not a polynomial in twist coordinates); the static pose at a
    0.157 rad driver rotation agrees within the fit's held-out error.
    """
    mech = load_mechanism("fourbar_cantilever")
    K = mech.hinges[0].law.K
    rng = np.random.default_rng(9)
    law = QuadraticLaw("twistor", K, 0 * K)
    train = law_data(law, *sample_box(400, 0.25, (1e-4, 1e-4), rng))
    test = law_data(law, *sample_box(400, 0.25, (1e-4, 1e-4), rng))
    res = fit_polynomial(train, 6, "twist", test=test)
    tol = res.report["test_max_rel"]
    assert tol < 1e-7
    hinges = tuple(dataclasses.replace(h, law=res.law.with_damping(h.law.B)) for h in mech.hinges)
    poly = dataclasses.replace(mech, hinges=hinges)
    a = Simulation(poly).static(0.0, t=0.05)
    b = Simulation(mech).static(0.0, t=0.05)
    moved = b.z - Simulation(mech).z0
    assert np.abs(b.snapshot.deflections[:, 0]).max() > 0.15
    assert np.abs(a.z - b.z).max() <= tol * np.abs(moved).max()


def _stage_doc():
    return yaml.safe_load((EXAMPLES / "microstage_polynomial_a.yaml").read_text())


def _expect(tmp_path, doc, *fragments):
    path = tmp_path / "mech.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError) as err:
        load_mechanism(path)
    msg = str(err.value)
    assert msg.startswith(str(path)), msg
    for f in fragments:
        assert f in msg, msg


def test_mechanism_errors_for_polynomial_laws(tmp_path):
    doc = _stage_doc()
    # the path is relative to the mechanism file: from tmp_path the example file is absent
    _expect(tmp_path, doc, "hinges[0].law.polynomial", "notch_hinge_order4.yaml", "cannot read")
    doc["hinges"][0]["law"]["polynomial"] = str(EXAMPLES / "notch_hinge_order4.yaml")
    doc["hinges"][0]["stiffness"] = "notch"
    _expect(tmp_path, doc, "hinges[0].stiffness", "polynomial law defines the stiffness")
    del doc["hinges"][0]["stiffness"]
    doc["hinges"][0]["law"]["order"] = 3
    _expect(tmp_path, doc, "hinges[0].law.order", "unknown key")
    del doc["hinges"][0]["law"]["order"]
    doc["hinges"][1]["law"] = "quadratic"
    _expect(tmp_path, doc, "hinges[1].law", "unknown law 'quadratic'")
    doc["hinges"][1].pop("law")
    # an unstable fitted law (negative stiffness at rest) is refused
    bad = yaml.safe_load((EXAMPLES / "notch_hinge_order4.yaml").read_text())
    bad["terms"][0]["coefficient"] *= -1
    (tmp_path / "unstable.yaml").write_text(yaml.safe_dump(bad))
    doc["hinges"][0]["law"]["polynomial"] = "unstable.yaml"
    _expect(tmp_path, doc, "hinges[0].law", "not positive definite")
    # a broken polynomial file: the message names both files and the key inside
    bad["terms"][0]["exponents"] = [0, 1, 0, 0]
    (tmp_path / "broken.yaml").write_text(yaml.safe_dump(bad))
    doc["hinges"][0]["law"]["polynomial"] = "broken.yaml"
    _expect(
        tmp_path, doc, "hinges[0].law.polynomial", "broken.yaml: terms:", "unstressed equilibrium"
    )


def test_builtins_are_unchanged_and_examples_are_not_builtins():
    from flexure_sim.engine.mechanism.loader import builtin_names

    assert "microstage_polynomial_a" not in builtin_names()
    stage = load_mechanism("microstage")
    assert all(isinstance(h.law, QuadraticLaw) for h in stage.hinges)
