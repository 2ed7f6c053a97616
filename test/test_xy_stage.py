"""
Test the shipped XY stage (config/xy_stage.yaml).

The shipped XY stage (config/xy_stage.yaml): two named drives, three named outputs.  Acceptance:
the engine's static solution against an independent linear computation: the stiffness matrix of the
same model assembled here by hand for small displacements, K = sum over hinges A_h^T K_h A_h (A_h:
the first-order map from the body coordinates to the hinge deflection (alpha, p) of frame b
relative to frame a, in frame a; K_h: the hinge's stiffness from the stiffness formulas of the
file), then the constrained solve with the prescribed coordinates eliminated.
"""
import json
import subprocess

import numpy as np
import pytest

from flexure_sim.engine.hinges import stiffness
from flexure_sim.engine.mechanism.loader import load_mechanism, resolve_mechanism_path
from flexure_sim.engine.solver.simulation import Simulation

J = np.array([[0.0, -1.0], [1.0, 0.0]])


def R(a):
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


#: The file's two stiffness models, from the stiffness formulas (config: notch, leaf).
K_OF = {
    "notch": stiffness.notch_stiffness(0.003, 0.00025, 0.02, 69.0e9, 0.33),
    "cantilever": stiffness.cantilever_stiffness(0.02, 0.0005, 0.01, 69.0e9, 0.33),
}


@pytest.fixture(scope="module")
def mech():
    return load_mechanism("xy_stage")


def hand_stiffness(mech) -> np.ndarray:
    """K = sum_h A_h^T K_h A_h at the unstressed pose (all body angles zero in the file)."""
    n = 3 * len(mech.bodies)
    K = np.zeros((n, n))
    for h in mech.hinges:
        A = np.zeros((3, n))
        ia, ib = mech.body_index(h.a.body), mech.body_index(h.b.body)
        ra = R(mech.bodies[ia].pose[2]) @ np.array(h.a.position)
        rb = R(mech.bodies[ib].pose[2]) @ np.array(h.b.position)
        Ra = R(mech.bodies[ia].pose[2] + h.a.angle)
        A[0, 3 * ia + 2], A[0, 3 * ib + 2] = -1.0, 1.0                  # d alpha
        A[1:, 3 * ib:3 * ib + 2] = Ra.T                 # d p = Ra^T (d o_b - d o_a)
        A[1:, 3 * ib + 2] = Ra.T @ (J @ rb)
        A[1:, 3 * ia:3 * ia + 2] = -Ra.T
        A[1:, 3 * ia + 2] = -Ra.T @ (J @ ra)
        K += A.T @ K_OF[h.stiffness_source] @ A
    return K


def hand_outputs(mech, ux: float, uy: float) -> np.ndarray:
    """Platform (x, y, theta) for piezo inputs (ux, uy) from the hand-assembled K."""
    K = hand_stiffness(mech)
    n = K.shape[0]
    dz = np.zeros(n)
    held = []
    for body in ("frame", "piezo_x", "piezo_y"):
        i = mech.body_index(body)
        held += [3 * i, 3 * i + 1, 3 * i + 2]
    dz[3 * mech.body_index("piezo_x")] = ux
    dz[3 * mech.body_index("piezo_y") + 1] = uy
    free = [k for k in range(n) if k not in held]
    dz[free] = -np.linalg.solve(K[np.ix_(free, free)], K[np.ix_(free, held)] @ dz[held])
    i = mech.body_index("platform")
    return dz[3 * i:3 * i + 3]


def hand_gain(mech) -> np.ndarray:
    return np.column_stack([hand_outputs(mech, 1.0, 0.0), hand_outputs(mech, 0.0, 1.0)])


def test_static_solution_matches_the_hand_assembled_linear_stiffness(mech):
    sim = Simulation(mech)
    assert sim.model.drives.names == ("x", "y")
    assert sim.model.output_names == ("x", "y", "theta")
    u = (1.0e-10, -0.6e-10)  # small: the twistor law's nonlinear terms stay below 1e-8
    snap = sim.static({"x": u[0], "y": u[1]}).snapshot
    engine = np.array([snap.outputs[k] for k in ("x", "y", "theta")])
    expected = hand_outputs(mech, *u)
    np.testing.assert_allclose(engine, expected, rtol=1e-6)
    np.testing.assert_allclose(sim.static_gain(), hand_gain(mech), rtol=1e-9, atol=1e-12)


def test_designed_gains_and_cross_coupling_as_documented(mech):
    """The numbers in config/xy_stage.yaml's header and in the README (rounded)."""
    G = hand_gain(mech)
    assert G[0, 0] == pytest.approx(6.87, abs=0.005)
    assert G[1, 1] == pytest.approx(G[0, 0], rel=1e-9)         # mirror-symmetric design
    assert G[1, 0] == pytest.approx(5.8e-3, abs=0.05e-3)        # y per x drive
    assert G[0, 1] == pytest.approx(G[1, 0], rel=1e-9)
    assert G[2, 0] == pytest.approx(-1.47, abs=0.005)           # rad per m of x drive
    assert G[2, 1] == pytest.approx(-G[2, 0], rel=1e-9)


def test_simulate_static_prints_the_gain_matrix(mech):
    out = subprocess.run(["flexure-sim", "simulate", "xy_stage", "--static", "--json"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    gm = result["gain_matrix"]
    assert gm["drives"] == ["x", "y"] and gm["outputs"] == ["x", "y", "theta"]
    np.testing.assert_allclose(gm["matrix"], hand_gain(mech), rtol=1e-9, atol=1e-12)
    assert set(result["drives"]) == {"x", "y"}
    table = subprocess.run(["flexure-sim", "simulate", "xy_stage", "--static"],
                           capture_output=True, text=True, timeout=120)
    assert table.returncode == 0, table.stderr
    assert "static gain" in table.stdout and "theta" in table.stdout
    assert str(resolve_mechanism_path("xy_stage")).endswith("xy_stage.yaml")


def test_a_single_drive_input_for_two_drives_is_a_one_line_error():
    out = subprocess.run(["flexure-sim", "simulate", "xy_stage", "--static",
                          "--drive", "step:1e-6"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert "has 2 drives" in out.stderr and "Traceback" not in out.stderr
