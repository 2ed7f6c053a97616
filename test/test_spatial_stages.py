"""
The shipped 3-D examples against calculations made without the engine.

- The tip-tilt mirror stage (config/tiptilt_stage.yaml): its static gains and modes against a
  linear 6-DOF model of the platform assembled here from the hinges' 6x6 matrices, their
  frames (rpy through SciPy's Rotation) and the rigid-body map of each hinge point.
- The micropositioning stage opened in 3-D: the platform (body 4) on its two hinges e and f,
  the levers held: its z stiffness and out-of-plane modes by hand, 2 k_z, 2 k_rx and
  2 (k_ry + k_z a^2) with a = 14 mm, over the masses of the plate-inertia rule.
"""
import copy
import dataclasses

import numpy as np
import pytest
import scipy.linalg
from scipy.spatial.transform import Rotation

from flexure_sim.engine.analysis import spatial_linear
from flexure_sim.engine.analysis.linear_response import gain_matrix
from flexure_sim.engine.hinges import spatial_stiffness as s6
from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.engine.mechanism.spatial_loader import spatial_from_dict
from flexure_sim.engine.mechanism.spatial_parts import Drive, Output
from flexure_sim.engine.mechanism.values import ConfigError
from flexure_sim.engine.mechanism.yaml_files import read_yaml
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.engine.solver.spatial_statics import static, static_gain


def skew(r):
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def hinge_map(R, r):
    """Deflection (rotation first, hinge frame R at r from the body's origin) of a body move."""
    T = np.zeros((6, 6))
    T[:3, 3:] = R.T
    T[3:, :3] = R.T
    T[3:, 3:] = -R.T @ skew(r)
    return T


def tiptilt_by_hand():
    """K_pp, K_pu (3 caps along z), M of the platform, from the file's numbers only."""
    doc = read_yaml(resolve_mechanism_path("tiptilt_stage"), ConfigError)
    models = doc["stiffness_models"]
    formulas = {"rod": s6.rod_stiffness, "cantilever": s6.cantilever_stiffness}
    bodies = {b["name"]: b for b in doc["bodies"]}
    centre = np.array(bodies["platform"]["pose"], dtype=float)
    Kpp, Kpu = np.zeros((6, 6)), np.zeros((6, 3))
    for h in doc["hinges"]:
        spec = dict(models[h["stiffness"]])
        K = formulas[spec.pop("model")](**{k: float(v) for k, v in spec.items()})
        side = h["b"] if h["b"]["body"] == "platform" else h["a"]
        R = Rotation.from_euler("xyz", side.get("rpy", [0, 0, 0])).as_matrix()
        T = hinge_map(R, np.array(side["at"], dtype=float))
        Kpp += T.T @ K @ T
        other = h["a"]["body"] if side is h["b"] else h["b"]["body"]
        if other.startswith("cap"):
            lift = np.r_[np.zeros(3), R.T @ [0.0, 0.0, 1.0]]
            Kpu[:, int(other[-1]) - 1] = -T.T @ K @ lift
    p = bodies["platform"]
    M = np.diag([p["mass"]] * 3 + list(p["inertia"]))
    assert np.allclose(centre, [0, 0, 0.015])
    return Kpp, Kpu, M


def test_tiptilt_static_gains_are_the_six_dof_model():
    Kpp, Kpu, _ = tiptilt_by_hand()
    x = -np.linalg.solve(Kpp, Kpu)  # platform (x, y, z, rx, ry, rz) per unit cap stroke
    expected = x[[3, 4, 2]]  # tip, tilt, piston
    model = SpatialModel(spatial_from_dict(read_yaml(resolve_mechanism_path("tiptilt_stage"),
                                                     ConfigError)))
    assert model.output_names == ("tip", "tilt", "piston")
    gains = static_gain(model)
    assert np.allclose(gains, expected, rtol=0, atol=1e-6 * np.abs(expected).max())
    lin = spatial_linear.linearize(model)
    assert np.allclose(gain_matrix(lin, ["tip", "tilt", "piston"]), expected, rtol=0,
                       atol=1e-6 * np.abs(expected).max())
    # nearly the kinematic gains: piston 1/3 per stack, tip 1/(1.5 r) rad per m of stack 1
    assert expected[2] == pytest.approx(np.full(3, 1 / 3), rel=2e-2)
    assert expected[0, 0] == pytest.approx(1 / 0.015, rel=2e-2)


def test_tiptilt_modes_are_the_six_dof_model():
    Kpp, _, M = tiptilt_by_hand()
    w2 = scipy.linalg.eigh(Kpp, M, eigvals_only=True)
    expected = np.sqrt(w2) / (2 * np.pi)
    model = SpatialModel(spatial_from_dict(read_yaml(resolve_mechanism_path("tiptilt_stage"),
                                                     ConfigError)))
    modes = spatial_linear.modes(spatial_linear.linearize(model, wrenches=False))
    assert np.allclose(modes.frequencies, expected, rtol=1e-6, atol=0)
    assert 4e3 < expected[0] < 8e3


def platform_on_its_hinges():
    """Return the stage in 3-D, every body but the platform held, a force drive along z."""
    doc = copy.deepcopy(read_yaml(resolve_mechanism_path("microstage"), ConfigError))
    doc["constraints"] = [{"type": "fixed", "body": b}
                          for b in ("body1", "body2", "body3", "body5", "body6")]
    doc["outputs"] = [{"name": "z", "body": "body4", "axis": [1.0, 0.0]}]
    del doc["output"], doc["compression_hinge"]
    mech = spatial_from_dict(doc)
    push = Drive("body4", (0.0, 0.0, 1.0), 1e-3, (-10.0, 10.0), 1.0, "fz", "z", "force")
    return dataclasses.replace(mech, constraints=mech.constraints + (push,),
                               outputs=(Output("body4", (0.0, 0.0, 1.0), "z"),))


def test_microstage_platform_z_stiffness_and_modes_by_hand():
    """
    The platform on its two hinges: z stiffness and out-of-plane modes by hand.

    Hinges e and f at (-+14 mm, 0) from the platform's centre, frames unrotated, 6x6 diagonal
    (notch, t = 20 mm): k_z,platform = 2 k_z; rotation about x (along the line of the two
    hinges) twists both: 2 k_rx; about y it bends both and moves them along z by -+a theta: 2
    (k_ry + a^2 k_z). Inertia of the plate rule: I_xx = I_yy = I_zz / 2 + m t^2 / 12.
    """
    K = s6.notch_stiffness(0.003, 0.00025, 0.02, 69.0e9, 0.33)
    k_rx, k_ry, k_z = K[0, 0], K[1, 1], K[5, 5]
    m, a, t = 0.01568, 0.014, 0.02
    Izz = m * (0.028**2 + 0.010**2) / 12  # microstage.sci's formula (config/microstage.yaml)
    Ixy = Izz / 2 + m * t * t / 12
    model = SpatialModel(platform_on_its_hinges())
    st = static(model, 1.0)  # 1 N along z
    assert model.output_values(st.z)[0] == pytest.approx(1.0 / (2 * k_z), rel=1e-9)
    freq = spatial_linear.modes(spatial_linear.linearize(model, wrenches=False)).frequencies
    for k, inertia in ((2 * k_z, m), (2 * k_rx, Ixy), (2 * (k_ry + a * a * k_z), Ixy)):
        f = np.sqrt(k / inertia) / (2 * np.pi)
        assert np.min(np.abs(freq - f)) <= 1e-9 * f
