"""
The figures docs/analyses.md quotes, recomputed and compared with the numbers parsed from it.

Each number is read from the page and must agree with the engine to half a unit of its last
printed digit (the page rounds; it does not truncate), so an edit of the page or a change of
the code that moves a figure fails here. Covered: the stage's modes, modal damping and
poles at 1.35 um; the lightly damped microstage_realistic's first mode and damping ratio;
the static gains, bandwidth and -90 deg phase of the frequency response; the hinge stress
table at full stroke and the stroke limit; the notch's K_t; the tolerance table (every row,
its nominal line and its summary).
"""

import importlib.util
import re
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
import scipy.optimize

from flexure_sim.engine.analysis import linear
from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.mechanism.parameters import Parameters
from flexure_sim.engine.analysis.sensitivity import sensitivities
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.hinges.stress import notch_concentration, stress_table, stroke_limit

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "analyses.md"
U_MODES, U_FULL = 1.35e-6, 2e-6


def _lines():
    """Return the page's lines, with the typographic minus and bold markers removed."""
    return DOC.read_text(encoding="utf-8").replace("\u2212", "-").replace("**", "").splitlines()


def _prose():
    """Return the page as one line of text (sentences are wrapped)."""
    return " ".join(" ".join(_lines()).split())


def _find(pattern):
    match = re.search(pattern, _prose())
    assert match, f"docs/analyses.md no longer says {pattern!r}"
    return match.groups()


def agrees(text, value, what=""):
    """Assert that value rounds to text: within half a unit of text's last digit."""
    unit = float(Decimal(10) ** Decimal(text).as_tuple().exponent)
    assert abs(value - float(text)) <= 0.5 * unit * (1 + 1e-9), (
        f"{what}: docs/analyses.md says {text}, the engine gives {value!r}"
    )


def _table_rows(first_cell):
    """Return the cells of the table rows whose first cell matches first_cell (a regex)."""
    rows = []
    for line in _lines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and re.fullmatch(first_cell, cells[0]):
            rows.append(cells)
    return rows


# ------------------------------------------------------------------- modes, damping


@pytest.fixture(scope="module")
def stage_modes():
    model = linear.linearize(Simulation(load_mechanism("microstage")), U_MODES)
    return model, linear.modes(model)


def test_mode_table_frequencies_and_modal_damping(stage_modes):
    _, md = stage_modes
    rows = {int(r[0]): r for r in _table_rows(r"\d+")}
    assert sorted(rows) == [1, 2, 3, 4]
    for k, (_, f, zeta) in rows.items():
        agrees(f, md.frequencies[k - 1], f"mode {k} frequency")
        agrees(zeta, md.modal_damping[k - 1], f"mode {k} modal damping")
    ((_, f_range, z_range),) = _table_rows(r"5.12")
    (f5, f12), (z5, z12) = (re.split(r"\s*…\s*", c) for c in (f_range, z_range))
    agrees(f5, md.frequencies[4], "mode 5")
    agrees(f12, md.frequencies[11], "mode 12")
    agrees(z5, md.modal_damping[4], "mode 5 damping")
    agrees(z12, md.modal_damping[11], "mode 12 damping")
    assert len(md.frequencies) == 12


def test_quoted_poles_of_the_stage(stage_modes):
    _, md = stage_modes
    re_, im = _find(r"with the pole pair (-[\d.]+) ± ([\d.]+)i 1/s")
    (pair,) = md.poles[md.poles.imag > 0]
    agrees(re_, pair.real, "first mode pole, real part")
    agrees(im, pair.imag, "first mode pole, imaginary part")
    count, lo, hi = _find(r"cluster of (\d+) real poles between (-[\d.]+) and (-[\d.]+) 1/s")
    near = md.poles[(md.poles.imag == 0) & (np.abs(md.poles.real + 1000.0) < 10.0)].real
    assert len(near) == int(count)
    agrees(lo, near.max(), "cluster's upper end")
    agrees(hi, near.min(), "cluster's lower end")


def test_realistic_stage_first_mode_and_damping_ratio():
    """The paragraph on microstage_realistic: `flexure-sim modes` at 1.35 um and at rest."""
    mech = load_mechanism("microstage_realistic")
    md = linear.modes(linear.linearize(Simulation(mech), U_MODES, wrenches=False))
    f1, zeta, re_, im = _find(
        r"modes microstage_realistic --input 1\.35e-6`: first mode ([\d.]+) Hz with damping "
        r"ratio ([\d.]+) \(pole pair (-[\d.]+) ± ([\d.]+)i 1/s"
    )
    agrees(f1, md.frequencies[0], "realistic first mode")
    agrees(zeta, md.modal_damping[0], "realistic first mode's damping ratio")
    pair = md.poles[md.poles.imag > 0][0]
    agrees(re_, pair.real, "realistic pole, real part")
    agrees(im, pair.imag, "realistic pole, imaginary part")
    assert -pair.real / abs(pair) == pytest.approx(md.modal_damping[0], rel=1e-6)
    for z in md.modal_damping[1:]:  # "every higher mode 0.0100 too"
        agrees(zeta, z, "realistic higher mode's damping ratio")
    (f_rest,) = _find(r"where the ratios are 0\.01 exactly \(first mode ([\d.]+) Hz\)")
    rest = linear.modes(linear.linearize(Simulation(mech), 0.0, wrenches=False))
    agrees(f_rest, rest.frequencies[0], "realistic first mode at rest")
    np.testing.assert_allclose(rest.modal_damping, 0.01, rtol=1e-9)


# --------------------------------------------------------------- frequency response


def test_static_gains_bandwidth_and_phase_crossing(stage_modes):
    model, _ = stage_modes
    gain, compression, force = _find(
        r"Static gain ([\d.]+) \(output / input\), joint-a compression ([\d.]+) m/m, "
        r"drive force ([\d.e]+) N/m"
    )
    g = linear.static_gain(model, ["output", "compression", "drive_force"])
    agrees(gain, g[0], "static gain")
    agrees(compression, g[1], "compression gain")
    agrees(force, g[2], "drive force gain")

    def response(f):
        return linear.frf(model, [f], ["output"])[0, 0]

    (bandwidth,) = _find(r"-3 dB bandwidth of the output is ([\d.]+) Hz")
    f3 = scipy.optimize.brentq(lambda f: abs(response(f)) - abs(g[0]) / np.sqrt(2), 10, 1e3)
    agrees(bandwidth, f3, "-3 dB bandwidth")
    (f90,) = _find(r"the phase passes -90° at the first mode, ([\d.]+) Hz")
    crossing = scipy.optimize.brentq(lambda f: np.angle(response(f)) + np.pi / 2, 10, 1e3)
    agrees(f90, crossing, "-90 deg crossing")


@pytest.mark.slow
def test_the_frf_command_the_page_names_prints_the_quoted_static_gains(tmp_path):
    """The page's `frf` command, run as a user runs it, prints the three gains it quotes."""
    import subprocess
    import sys

    gains = dict(zip(("output", "compression", "drive_force"), _find(
        r"Static gain ([\d.]+) \(output / input\), joint-a compression ([\d.]+) m/m, "
        r"drive force ([\d.e]+) N/m")))
    (command,) = _find(r"\(`(flexure-sim frf [^`]+)`\s+prints each next to \|G\| at the lowest "
                       r"frequency")
    p = subprocess.run([sys.executable, "-m", "flexure_sim.cli", *command.split()[1:], "-o",
                        str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    printed = dict(re.findall(r"^(\w+): \|G\| .*\(static gain ([-\d.e+]+)\)", p.stdout, re.M))
    assert set(printed) == set(gains), p.stdout
    for name, text in gains.items():
        agrees(text, float(printed[name]), f"{name} as frf prints it")


# ------------------------------------------------------------------------- stress


def test_hinge_stress_table_at_full_stroke_and_the_stroke_limit():
    mech = load_mechanism("microstage")
    sim = Simulation(mech)
    table = stress_table(sim.static(U_FULL).snapshot.wrenches, mech)
    # the stress table's header (the fatigue table's comes later; not the tolerance table's)
    header = [r for r in _table_rows("hinge") if r[1] == "a"][0]
    (stress,) = _table_rows(r"peak stress \[MPa\]")
    (ratio,) = _table_rows("σ / σ_y")
    assert header[1:] == sorted(table)
    for name, s, r in zip(header[1:], stress[1:], ratio[1:]):
        agrees(s, table[name]["stress"] / 1e6, f"hinge {name} stress")
        agrees(r, table[name]["ratio"], f"hinge {name} stress ratio")
    hinge, limit, times = _find(
        r"the first hinge to reach yield is (\w), at ([\d.]+) µm of drive input, ([\d.]+) times"
    )
    u, first = stroke_limit(sim)
    assert hinge == first
    agrees(limit, u * 1e6, "stroke limit")
    agrees(times, u / mech.drive.stroke[1], "stroke limit / piezo stroke")
    (kt,) = _find(r"For the stage's h/D = 1/12, K_t = ([\d.]+)")
    params = Parameters("microstage")
    h, D = (params.value(f"stiffness_models.notch.{k}") for k in ("h", "D"))
    assert h / D == pytest.approx(1 / 12, rel=1e-12)
    agrees(kt, notch_concentration(h, D), "K_t")


def test_material_table_is_the_shipped_table():
    """The page's material table quotes engine/hinges/materials.yaml (E GPa, strengths MPa)."""
    from flexure_sim.engine.hinges.materials import table

    rows = {r[0].split()[0].strip("`"): r for r in _table_rows(r"`[^`]+`.*")}
    assert set(rows) == set(table())
    for name, m in table().items():
        _, E, nu, rho, sy, su, se, _ = rows[name]
        agrees(E, m["E"] / 1e9, f"{name} E")
        agrees(nu, m["nu"], f"{name} nu")
        agrees(rho, m["density"], f"{name} density")
        agrees(sy, m["sigma_y"] / 1e6, f"{name} sigma_y")
        agrees(su, m["sigma_u"] / 1e6, f"{name} sigma_u")
        strength, _, cycles = se.split()[:3]
        agrees(strength, m["sigma_e"] / 1e6, f"{name} sigma_e")
        assert float(cycles) == m.cycles, name


def test_fatigue_table_and_the_infinite_life_input():
    from flexure_sim.engine.hinges import fatigue

    mech = load_mechanism("microstage")
    report = fatigue.static_report(Simulation(mech), 0.0, U_FULL)
    header = [r for r in _table_rows("hinge") if r[1] == "a"][1]
    rows = {name: _table_rows(name)[0] for name in (r"amplitude \[MPa\]", "Goodman n",
                                                    "Soderberg n")}
    assert header[1:] == sorted(report["hinges"])
    for k, name in enumerate(header[1:], start=1):
        h = report["hinges"][name]
        agrees(rows[r"amplitude \[MPa\]"][k], h["amplitude"] / 1e6, f"hinge {name} amplitude")
        agrees(rows["Goodman n"][k], h["goodman"], f"hinge {name} Goodman")
        agrees(rows["Soderberg n"][k], h["soderberg"], f"hinge {name} Soderberg")
    hinge, goodman, soderberg = _find(r"The critical hinge is (\w); cycled from 0 it has infinite "
                                      r"life .* up to ([\d.]+) µm of drive input by Goodman "
                                      r"\(([\d.]+) µm by Soderberg\)")
    assert hinge == report["critical"]["goodman"]["hinge"]
    agrees(goodman, report["infinite_life"]["goodman"]["input"] * 1e6, "Goodman life")
    agrees(soderberg, report["infinite_life"]["soderberg"]["input"] * 1e6, "Soderberg life")
    (limit,) = _find(r"The same stage in 7075-T6 \(503 MPa\) reaches yield at ([\d.]+) µm")
    text = (ROOT / "config" / "microstage.yaml").read_text().replace("material: 6061-T6}",
                                                                     "material: 7075-T6}")
    import yaml

    from flexure_sim.engine.mechanism.loader import mechanism_from_dict

    agrees(limit, stroke_limit(Simulation(mechanism_from_dict(yaml.safe_load(text))))[0] * 1e6,
           "7075-T6 stroke limit")


# ---------------------------------------------------------------- tolerance table


def _tolerance_script():
    spec = importlib.util.spec_from_file_location(
        "tolerance_table", ROOT / "scripts" / "tolerance_table.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_tolerance_table_rows_nominal_and_summary():
    """
    Every row: the second-order prediction from the sensitivities and the re-solve.

    The re-solve is the one scripts/tolerance_table.py (the page's source for the table) does.
    """
    script = _tolerance_script()
    params = Parameters("microstage")
    outputs = ("gain", "first_mode", "peak_stress")
    scale = (1.0, 1.0, 1e-6)  # peak stress in MPa
    rows = _table_rows("[a-g]")
    assert sorted({r[0] for r in rows}) == list("abcdefg") and len(rows) == 14
    first_order_error, moved, nominal = 0.0, {}, None
    for hinge in "abcdefg":
        path = f"hinges.{hinge}.stiffness.h"
        res = sensitivities(params, [path], list(outputs), U_FULL)
        nominal = [res["values"][o] * c for o, c in zip(outputs, scale)]
        for row in (r for r in rows if r[0] == hinge):
            dh = float(row[1].split()[0]) * 1e-6
            resolved = script.resolve(params, hinge, params.value(path) + dh, U_FULL)
            for k, (o, c) in enumerate(zip(outputs, scale)):
                v, g = res["values"][o], res["gradient"][o][path]
                d2 = res["second"][o][f"{path}|{path}"]
                predicted, again = (t.strip() for t in row[2 + k].split("/"))
                agrees(predicted, (v + g * dh + 0.5 * d2 * dh * dh) * c, f"{row[:2]} {o}")
                agrees(again, resolved[k] * c, f"{row[:2]} {o} re-solved")
                change = abs(resolved[k] / v - 1.0)
                if change > moved.get(o, (0.0, ""))[0]:
                    moved[o] = (change, hinge)
                if o == "first_mode":
                    first_order_error = max(first_order_error, abs(v + g * dh - resolved[k]))
    gain, f1, peak = _find(
        r"Nominal: gain ([\d.]+), first mode ([\d.]+) Hz, peak stress ([\d.]+) MPa \(hinge c\)"
    )
    for text, value, o in zip((gain, f1, peak), nominal, outputs):
        agrees(text, value, f"nominal {o}")
    g_pct, g_hinge, f_pct, f_hinge, s_pct, s_hinge = _find(
        r"moves the gain by up to ([\d.]+) % \(hinge (\w)\), the first mode by ([\d.]+) % "
        r"\(hinge (\w)\), and the peak stress by ([\d.]+) % \(hinge (\w),"
    )
    agrees(g_pct, 100 * moved["gain"][0], "largest gain change")
    agrees(f_pct, 100 * moved["first_mode"][0], "largest first-mode change")
    agrees(s_pct, 100 * moved["peak_stress"][0], "largest peak-stress change")
    assert (g_hinge, f_hinge, s_hinge) == tuple(moved[o][1] for o in outputs)
    (off,) = _find(r"to first order it was off by up to ([\d.]+) Hz")
    agrees(off, first_order_error, "first-order error of the first mode")


def test_agrees_is_strict_about_the_last_digit():
    """The comparison itself: 300.62 stands for [300.615, 300.625]; 2.261e7 for +-5e3."""
    agrees("300.62", 300.6249)
    agrees("2.261e7", 2.2614e7)
    with pytest.raises(AssertionError):
        agrees("300.62", 300.6251)
    with pytest.raises(AssertionError):
        agrees("2.261e7", 2.2604e7)
