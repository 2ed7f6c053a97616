"""
Test several named drives, drives on a rotation, force drives, named outputs.

Several named drives, drives on a rotation, force-controlled drives, named outputs.  Expected
values come from closed forms (a hinge of known rotational stiffness Ko: moment Ko theta, angle
torque / Ko) or from the exact tangent stiffness (``linear.tangent_at``) solved here by hand, never
from the engine's static solver itself.
"""
import copy

import numpy as np
import pytest

from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism, mechanism_from_dict
from flexure_sim.engine.analysis.linear import linearize, tangent_at
from flexure_sim.engine.solver.simulation import Simulation

KO = 2.5  # N m / rad


def rotor(drive: dict, outputs=None) -> dict:
    """One body on one hinge of rotational stiffness KO at the body's origin."""
    doc = {
        "name": "rotor",
        "defaults": {"law": "twistor", "damping": {"t_char": 1e-3}},
        "bodies": [{"name": "base", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
                   {"name": "disc", "mass": 0.01, "inertia": 1e-6, "pose": [0.01, 0, 0]}],
        "hinges": [{"name": "h", "a": {"body": "base", "at": [0.01, 0]},
                    "b": {"body": "disc", "at": [0, 0]},
                    "stiffness": {"model": "matrix", "Ko": KO, "Kt": [1e7, 2e6]}}],
        "constraints": [{"type": "fixed", "body": "base"}, drive],
    }
    if outputs:
        doc["outputs"] = outputs
    return mechanism_from_dict(doc)


def test_a_prescribed_angle_needs_the_moment_ko_theta():
    theta = 3e-3
    mech = rotor({"type": "drive", "name": "turn", "body": "disc", "axis": "theta",
                  "response_time": 1e-3, "stroke": [-0.01, 0.01], "slew_rate": 1.0},
                 [{"name": "angle", "body": "disc", "coordinate": "theta"}])
    snap = Simulation(mech).static({"turn": theta}).snapshot
    assert snap.drive_names == ("turn",)
    # Ko theta to first order: the twistor law's terms of third order in the angle are
    # about theta^2 / 6 relative, so theta^2 bounds the difference.
    np.testing.assert_allclose(snap.drive_forces, [KO * theta], rtol=theta**2)
    assert snap.drive_force == pytest.approx(KO * theta, rel=theta**2)
    assert snap.outputs == {"angle": pytest.approx(theta, rel=1e-12)}
    # x, y of the disc are free and stay at rest (the hinge turns about its own origin).
    np.testing.assert_allclose(snap.poses[1, :2], [0.01, 0.0], atol=1e-15)


def test_a_commanded_torque_turns_the_body_by_torque_over_ko():
    torque = 4e-3
    mech = rotor({"type": "force", "name": "torquer", "body": "disc", "axis": "theta",
                  "response_time": 1e-3, "stroke": [-1, 1], "slew_rate": 1.0})
    snap = Simulation(mech).static(torque).snapshot
    np.testing.assert_allclose(snap.drive_positions, [torque / KO], rtol=(torque / KO)**2)
    np.testing.assert_allclose(snap.drive_forces, [torque])
    np.testing.assert_allclose(snap.drive_inputs, [torque])


def _microstage_doc():
    from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
    from flexure_sim.engine.mechanism.yaml_files import read_yaml
    path = resolve_mechanism_path("microstage")
    return read_yaml(path, ConfigError), str(path)


def test_force_drive_displacement_is_force_over_the_exact_tangent_stiffness():
    doc, source = _microstage_doc()
    doc = copy.deepcopy(doc)
    doc["constraints"][1] = {"type": "force", "name": "push", "body": "body6", "axis": [1, 0],
                             "response_time": 1e-3, "stroke": [-10, 10], "slew_rate": 1e3}
    doc.pop("compression_hinge")
    mech = mechanism_from_dict(doc, source)
    sim = Simulation(mech)
    force = 1e-3
    snap = sim.static({"push": force}).snapshot
    # Independent: -K_FF dz_F = e_F f with K = dQ/dz at rest (exact tangent stiffness).
    K = tangent_at(sim, sim.z0)[0]
    free = sim.part.free
    e = np.zeros(len(sim.z0))
    e[3 * mech.body_index("body6")] = 1.0
    dz = np.zeros(len(sim.z0))
    dz[free] = np.linalg.solve(-K[np.ix_(free, free)], e[free] * force)
    np.testing.assert_allclose(snap.drive_positions[0], e @ dz, rtol=1e-6)
    np.testing.assert_allclose(snap.output, sim.model.output_matrix[0] @ dz, rtol=1e-6)
    # ... and the exact static gain says the same per newton.
    np.testing.assert_allclose(sim.static_gain()[0, 0] * force, snap.output, rtol=1e-6)


def two_drive_microstage():
    """
    Return the microstage with a second, named drive.

    The microstage with a second, named drive: a torque-free tangential drive turning the output
    body (body4) about its origin, body6's drive named ``piezo``.
    """
    doc, source = _microstage_doc()
    doc = copy.deepcopy(doc)
    doc["constraints"][1]["name"] = "piezo"
    doc["constraints"].append({"type": "drive", "name": "tilt", "body": "body3", "axis": "theta",
                               "response_time": 1e-3, "stroke": [-1e-3, 1e-3],
                               "slew_rate": 1.0})
    doc.pop("output")
    doc["outputs"] = [{"name": "x", "body": "body4", "axis": [1, 0]},
                      {"name": "y", "body": "body4", "axis": [0, 1]},
                      {"name": "theta", "body": "body4", "coordinate": "theta"}]
    return mechanism_from_dict(doc, source)


def test_two_drives_superpose_for_small_inputs_and_match_the_exact_gain():
    mech = two_drive_microstage()
    sim = Simulation(mech)
    assert sim.model.drives.names == ("piezo", "tilt")
    G = sim.static_gain()
    assert G.shape == (3, 2)
    u = np.array([1e-9, 1e-7])
    snap = sim.static(u).snapshot
    out = np.array([snap.outputs[n] for n in ("x", "y", "theta")])
    np.testing.assert_allclose(out, G @ u, rtol=1e-5, atol=1e-6 * np.abs(G @ u).max())
    # one value per drive, as a vector or a mapping, gives the same answer
    again = sim.static({"tilt": u[1], "piezo": u[0]}).snapshot
    np.testing.assert_array_equal(again.drive_forces, snap.drive_forces)
    np.testing.assert_allclose(snap.drive_inputs, u)


def test_single_drive_gain_matches_the_static_solve_of_the_stage():
    sim = Simulation(load_mechanism("microstage"))
    u = 1e-9
    assert sim.static_gain()[0, 0] * u == pytest.approx(sim.static(u).snapshot.output, rel=1e-6)
    assert sim.model.drives.names == ("drive",)
    assert sim.model.output_names == ("output",)


@pytest.mark.parametrize("value, message", [
    (1e-6, "one number given for 2 drives"),
    ([1e-6], "1 drive inputs given for 2 drives"),
    ({"piezo": 1e-6}, "missing ['tilt']"),
    ({"piezo": 1e-6, "tilt": 0, "z": 1}, "unknown ['z']"),
    ([np.nan, 0.0], "must be finite"),
])
def test_bad_drive_inputs_are_named(value, message):
    sim = Simulation(two_drive_microstage())
    with pytest.raises(ValueError) as err:
        sim.static(value)
    assert message in str(err.value)


def test_the_linear_model_has_one_input_per_drive_named_after_it():
    """
    The linear model of two drives (issue 13): inputs and actuator states by drive name.

    Its static gain D - C A^-1 B equals the exact static gain of the statics (-K_FF^-1 K_FP D,
    statics.static_gain: another formula on the tangent stiffness alone).
    """
    sim = Simulation(two_drive_microstage())
    lm = linearize(sim, wrenches=False)
    assert lm.input_names == ["piezo", "tilt"]
    assert lm.state_names[-2:] == ["drive.piezo.u", "drive.tilt.u"]
    assert lm.output_names[:6] == ["x", "y", "theta", "compression", "drive_force.piezo",
                                   "drive_force.tilt"]
    G = lm.D[:3] - lm.C[:3] @ np.linalg.solve(lm.A, lm.B)
    want = sim.static_gain()
    np.testing.assert_allclose(G, want, rtol=1e-7, atol=1e-9 * np.abs(want).max())


def test_config_rejects_duplicate_drive_names_and_forces_on_held_coordinates():
    doc, source = _microstage_doc()
    twice = copy.deepcopy(doc)
    twice["constraints"].append({"type": "drive", "body": "body3", "axis": [1, 0],
                                 "response_time": 1e-3, "stroke": [0, 1e-6],
                                 "slew_rate": 1.0})
    with pytest.raises(ConfigError, match="duplicate drive name 'drive': name every drive"):
        mechanism_from_dict(twice, source)
    held = copy.deepcopy(doc)
    held["constraints"].append({"type": "force", "name": "f", "body": "body1", "axis": [1, 0],
                                "response_time": 1e-3, "stroke": [0, 1], "slew_rate": 1.0})
    with pytest.raises(ConfigError, match="force drive needs coordinate x of body 'body1' free"):
        mechanism_from_dict(held, source)
    bad = copy.deepcopy(doc)
    bad["constraints"][1]["axis"] = "phi"
    with pytest.raises(ConfigError, match="one of"):
        mechanism_from_dict(bad, source)


def test_a_stepped_single_drive_reports_the_same_per_drive_as_in_its_scalar_fields():
    sim = Simulation(load_mechanism("microstage"))
    sim.set_command({"drive": 1e-6})
    sim.step(20)
    snap = sim.snapshot()
    assert snap.drive_names == ("drive",)
    np.testing.assert_allclose(snap.drive_inputs, [snap.drive_input], rtol=0, atol=0)
    np.testing.assert_allclose(snap.drive_forces, [snap.drive_force], rtol=1e-12)
    np.testing.assert_allclose(snap.drive_positions, [snap.drive_input], rtol=1e-12)
    assert snap.outputs == {"output": snap.output}
    assert 0 < snap.drive_input < 1e-6 and snap.drive_force > 0
