"""Statics at the edges: a mechanism whose every coordinate is prescribed (issue 16 item 7)."""
import json
import subprocess
import sys

import numpy as np
import pytest
import yaml
from conftest import ROOT

from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.engine.solver.simulation import Simulation

KO, KX, KY = 2.0, 1.0e8, 1.0e7
#: A platform driven directly on fixed ground through one hinge of known stiffness: no
#: coordinate is free. Hinge frames unrotated at the hinge centre, between the two bodies.
DRIVEN_PLATFORM = {
    "name": "driven_platform",
    "defaults": {"law": "twistor", "damping": {"t_char": 1.0e-3}},
    "bodies": [
        {"name": "ground", "mass": 1.0, "inertia": 1.0e-3, "pose": [0.0, 0.0, 0.0]},
        {"name": "platform", "mass": 0.01, "inertia": 1.0e-6, "pose": [0.01, 0.0, 0.0]},
    ],
    "hinges": [{"name": "a", "a": {"body": "ground", "at": [0.005, 0.0]},
                "b": {"body": "platform", "at": [-0.005, 0.0]},
                "stiffness": {"model": "matrix", "Ko": KO, "Kt": [KX, KY]}}],
    "constraints": [
        {"type": "fixed", "body": "ground"},
        {"type": "drive", "body": "platform", "axis": [1.0, 0.0], "response_time": 1.0e-3,
         "stroke": [0.0, 2.0e-6], "slew_rate": 0.01},
    ],
    "output": {"body": "platform", "axis": [1.0, 0.0]},
    "compression_hinge": "a",
}


@pytest.mark.parametrize("u", [0.0, 1.0e-6, -3.0e-7])
def test_static_without_free_coordinates_is_the_prescribed_pose(u):
    """
    The hinge is stretched by exactly u along its axial direction.

    Alpha = 0, p = (u, 0), so U = 1/2 KX u^2 for the twistor law (x = p/2, U = 2 x^T Kt x) and the
    drive must push with KX u. Tolerance 1e-9: p comes from poses of ~1e-2 m (1e-18 m rounding on
    1e-6 m).
    """
    sim = Simulation(mechanism_from_dict(DRIVEN_PLATFORM))
    res = sim.static(u)
    snap = res.snapshot
    assert res.iterations == 0 and res.residual == 0.0
    assert snap.drive_force == pytest.approx(KX * u, rel=1e-9, abs=1e-12)
    assert snap.output == pytest.approx(u, rel=1e-9, abs=1e-18)
    assert snap.potential_energy == pytest.approx(0.5 * KX * u * u, rel=1e-9, abs=1e-24)
    assert snap.wrenches[0] == pytest.approx([0.0, -KX * u, 0.0], abs=1e-9 * KX * 1e-6)
    sweep = sim.static_sweep([0.0, u])
    assert sweep.drive_forces[1] == pytest.approx(KX * u, rel=1e-9, abs=1e-12)
    assert sweep.outputs[1] == pytest.approx(u, rel=1e-9, abs=1e-18)


def test_cli_static_without_free_coordinates_prints_the_answer(tmp_path):
    path = tmp_path / "driven.yaml"
    path.write_text(yaml.safe_dump(DRIVEN_PLATFORM))
    p = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "simulate", str(path),
                        "--drive", "step:1e-6", "--static", "--json"],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    out = json.loads(p.stdout)
    assert out["drive_force"] == pytest.approx(KX * 1e-6, rel=1e-9)
    assert np.isfinite(out["output_displacement"])


def test_the_parallelogram_example_moves_on_its_leaves_shear_stiffness():
    """
    The example's platform is pushed along x against both leaves' shear stiffness.

    Independent value: a leaf clamped at both ends and guided (no end rotation) resists a
    transverse displacement with 12 E I / L^3 (Roark, Table 8.1, case 1e / guided end), two
    leaves in parallel, in series with the input notch's axial stiffness. A leaf whose hinge
    frame were turned by pi/2 (as the example once had it) puts its axial stiffness A E / L
    along x instead: the drive force was 2.9 times this.
    """
    sim = Simulation(load_mechanism(ROOT / "config" / "examples" / "parallelogram_stage.yaml"))
    u = 5.0e-6
    result = sim.static(u)
    snap = result.snapshot
    E, t, w, L = 69.0e9, 0.0005, 0.005, 0.020
    leaves = 2 * 12.0 * E * (w * t**3 / 12.0) / L**3
    notch_axial = 3.97092544e7  # kappa_1t E t (engine/hinges/stiffness.py check)
    expected = u / (1.0 / leaves + 1.0 / notch_axial)
    assert snap.drive_force == pytest.approx(expected, rel=1.0e-3)
    # Parallel guidance: both leaves shear alike and the platform barely tilts.
    assert abs(float(result.z[3 * 1 + 2])) < 1.0e-2 * u / L  # turned frames: 2 u / L
