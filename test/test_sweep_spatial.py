"""
Sweeps of 3-D studies (``space: 3d``, or a 3-D mechanism file) by the spatial engine.

References: the planar engine's sweep of the same designs for the in-plane quantities, and
for the out-of-plane mode a generalized eigenproblem of a finite-difference stiffness with a
mass matrix assembled here from the bodies.
"""
import numpy as np
import pytest
import scipy.linalg

from flexure_sim.engine.analysis.study import StudyError, study_from_dict
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.tools.design.sweep_outputs import OUTPUTS, evaluate_batch

THICKNESS = [0.012, 0.02]


def _study(outputs, space="3d", mechanism="microstage", input=2.0e-6, parameters=None):
    data = {"mechanism": mechanism, "input": input, "outputs": list(outputs),
            "parameters": parameters or [{"name": "t", "path": "stiffness_models.notch.t",
                                          "values": THICKNESS}]}
    if space is not None:
        data["space"] = space
    return study_from_dict(data, "study3d.yaml", OUTPUTS)


def test_in_plane_columns_equal_the_planar_sweep():
    """A planar stage swept in 3-D: gain and first mode as the planar engine's sweep gives them."""
    spatial = evaluate_batch(_study(["gain", "first_mode"]), 0, len(THICKNESS))
    planar = evaluate_batch(_study(["gain", "first_mode"], space=None), 0, len(THICKNESS))
    assert spatial["status"] == ["ok"] * len(THICKNESS), spatial["error"]
    assert np.allclose(spatial["gain"], planar["gain"], rtol=1e-12, atol=0)
    assert np.allclose(spatial["first_mode"], planar["first_mode"], rtol=1e-9, atol=0)
    # the plate's width changes the in-plane notch stiffness (k ~ t): the mode moves with it
    assert spatial["first_mode"][0] < spatial["first_mode"][1]


def _finite_difference_modes(mech):
    """Frequencies (Hz) and out-of-plane energy shares from a central-difference stiffness."""
    model = SpatialModel(mech)
    F = model.part.free
    z0 = model.z0.copy()
    zero = np.zeros_like(z0)
    K = np.empty((len(F), len(F)))
    for c, j in enumerate(F):
        h = 1e-9 if j % 6 < 3 else 1e-7
        up, down = z0.copy(), z0.copy()
        up[j] += h
        down[j] -= h
        Qp = model.terms(up, zero, 0.0)[0]
        Qm = model.terms(down, zero, 0.0)[0]
        K[:, c] = -(Qp[F] - Qm[F]) / (2 * h)
    N = len(z0)
    M = np.zeros((N, N))
    for i, body in enumerate(mech.bodies):
        M[6 * i:6 * i + 3, 6 * i:6 * i + 3] = body.mass * np.eye(3)
        M[6 * i + 3:6 * i + 6, 6 * i + 3:6 * i + 6] = np.array(body.inertia)
    M = M[np.ix_(F, F)]
    w2, shapes = scipy.linalg.eigh(0.5 * (K + K.T), M)
    out = np.array([k % 6 in (2, 3, 4) for k in F])
    shares = np.einsum("ik,ik->k", shapes[out], (M @ shapes)[out])
    return np.sqrt(w2) / (2 * np.pi), shares


def test_first_out_of_plane_mode_against_a_finite_difference_stiffness():
    """The lowest mode moving mostly out of the plane, about rest, as an independent FD model."""
    study = _study(["first_out_of_plane_mode"], input=0.0)
    cols = evaluate_batch(study, 0, len(THICKNESS))
    assert cols["status"] == ["ok"] * len(THICKNESS), cols["error"]
    for k in range(len(THICKNESS)):
        freq, shares = _finite_difference_modes(study.mechanism(study.sample(k)))
        expected = freq[np.flatnonzero(shares > 0.5)[0]]
        assert cols["first_out_of_plane_mode"][k] == pytest.approx(expected, rel=1e-6)
    # a wider plate stiffens the hinges out of the plane: the mode rises
    assert cols["first_out_of_plane_mode"][0] < cols["first_out_of_plane_mode"][1]


def test_a_3d_file_is_swept_in_3d_by_default():
    """config/tiptilt_stage.yaml has space: 3d; its gain matrix comes per output and drive."""
    study = _study(["gain"], space=None, mechanism="tiptilt_stage",
                   input={"p1": 1e-6, "p2": 0.0, "p3": 0.0},
                   parameters=[{"path": "bodies.platform.mass", "values": [0.02, 0.04]}])
    assert study.space == "3d"
    cols = evaluate_batch(study, 0, 2)
    assert cols["status"] == ["ok", "ok"], cols["error"]
    gains = [c for c in cols if c.startswith("gain.")]
    assert len(gains) == 9  # tip, tilt, piston against p1, p2, p3
    # a static gain does not depend on the platform's mass
    assert all(cols[c][0] == pytest.approx(cols[c][1], rel=1e-12, abs=1e-300) for c in gains)


@pytest.mark.parametrize("space, outputs, mechanism, key, words", [
    ("3d", ["compression"], "microstage", "outputs", "compression: not available in 3-D"),
    ("2d", ["first_out_of_plane_mode"], "microstage", "outputs", "space: 3d"),
    ("2d", ["gain"], "tiptilt_stage", "space", "3-D file"),
    ("4d", ["gain"], "microstage", "space", "expected 2d or 3d"),
])
def test_what_a_3d_study_cannot_do_is_refused_by_name(space, outputs, mechanism, key, words):
    input = 1e-6 if mechanism == "microstage" else {"p1": 1e-6, "p2": 0.0, "p3": 0.0}
    with pytest.raises(StudyError) as err:
        _study(outputs, space=space, mechanism=mechanism, input=input,
               parameters=[{"path": "bodies.body4.mass" if mechanism == "microstage"
                            else "bodies.platform.mass", "values": [0.01]}])
    message = str(err.value)
    assert f"study3d.yaml: {key}:" in message and words in message
