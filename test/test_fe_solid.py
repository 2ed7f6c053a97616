"""
The 3-D finite-element hinge (``model: fe`` in space) against independent answers.

Its in-plane block against the planar finite-element solves (plane stress for a thin plate,
between plane stress and plane strain for a wide one) and against the dissertation's notch
formula by the documented formula/FE difference (docs/hinges.md); a straight leaf against beam
theory with Saint-Venant torsion (``spatial_stiffness.cantilever_stiffness``); the symmetry of
a doubly symmetric hinge (a diagonal K at its centre), positive definiteness; mesh
convergence; and the loaders (a 3-D file and a planar file opened in 3-D).
"""
import copy

import numpy as np
import pytest

from flexure_sim.engine.hinges import spatial_stiffness as closed
from flexure_sim.engine.hinges.fe import fe_model, solid
from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.engine.mechanism.spatial_loader import spatial_from_dict
from flexure_sim.engine.mechanism.values import ConfigError
from flexure_sim.engine.mechanism.yaml_files import read_yaml

NU = 0.33
#: Circular notch D = 4 h (h/R = 0.5), lengths in h, E = 1.
NOTCH = {"h": 1.0, "D": 4.0}
PLANE = [2, 3, 4]  # (rz, x, y) in the 6x6, rotations first


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path_factory, monkeypatch):
    """Every test module solves for itself: a cache directory of its own."""
    monkeypatch.setenv("FLEXURE_SIM_CACHE", str(tmp_path_factory.getbasetemp() / "fe_cache"))


def notch3d(t, n=solid.DEFAULT_RESOLUTION):
    return solid.stiffness("circular", {**NOTCH, "t": t}, 1.0, NU, n)


def in_plane(K6):
    """Return the (rz, x, y) block: the planar 3x3, moment first (docs/spatial.md)."""
    return K6[np.ix_(PLANE, PLANE)]


def planar(t, plane):
    return fe_model.stiffness("circular", {**NOTCH, "t": t}, 1.0, NU, plane)


def test_thin_plate_in_plane_block_is_the_plane_stress_solve():
    # t = h/2 = D/8: the free faces make the plate's stress plane; the rest is discretisation
    # (n = 4: ~1 %, the convergence test) and the plate's finite thickness.
    K = notch3d(0.5)
    ref = planar(0.5, "stress")
    assert np.allclose(np.diag(in_plane(K)), np.diag(ref), rtol=0.02, atol=0)
    strain = planar(0.5, "strain")
    assert np.all(np.abs(np.diag(in_plane(K)) / np.diag(ref) - 1)
                  < 0.25 * np.abs(np.diag(strain) / np.diag(ref) - 1))


@pytest.mark.slow
def test_wide_plate_lies_between_plane_stress_and_strain_nearer_strain():
    # t = 2 D: the interior is in plane strain, the faces' boundary layers (~D/2 deep) not.
    K = np.diag(in_plane(notch3d(8.0)))
    lo, hi = np.diag(planar(8.0, "stress")), np.diag(planar(8.0, "strain"))
    where = (K - lo) / (hi - lo)
    assert np.all(where > 0.5) and np.all(where < 1.0), where


def test_in_plane_block_against_the_notch_formula_by_the_documented_difference():
    # docs/hinges.md, "The formulas against finite elements", h/R = 0.5, dissertation
    # (5.27-5.33) against plane-stress FE: Ko -1.2 %, Kx -39.8 %, Ky -28.1 %.
    K = np.diag(in_plane(notch3d(0.5)))
    formula = np.diag(in_plane(closed.notch_stiffness(4.0, 1.0, 0.5, 1.0, NU)))
    documented = np.array([-1.2, -39.8, -28.1])
    assert np.allclose(100 * (formula / K - 1), documented, atol=1.5)


def test_out_of_plane_bending_against_lobontiu_beam_integrals():
    # The beam integrals of spatial_stiffness (1/k = int dl / (E I_o)) for bending about y
    # and translation along z: a thin notch bends as a beam across its width.
    K = np.diag(notch3d(0.5))
    formula = np.diag(closed.notch_stiffness(4.0, 1.0, 0.5, 1.0, NU))
    assert abs(formula[1] / K[1] - 1) < 0.06  # measured +4.4 %
    assert abs(formula[5] / K[5] - 1) < 0.15  # measured +12 % (shear of a short beam)


def test_doubly_symmetric_notch_is_diagonal_symmetric_and_positive_definite():
    # Mirror symmetry in x, y and z about the centre decouples all six components there.
    K = notch3d(0.5)
    assert np.array_equal(K, K.T)
    assert np.all(np.linalg.eigvalsh(K) > 0)
    d = np.sqrt(np.outer(np.diag(K), np.diag(K)))
    off = np.abs(K) / d - np.eye(6)
    assert off.max() < 2e-3, off.max()


@pytest.mark.slow
def test_leaf_against_beam_theory_with_torsion():
    # A straight leaf L = 8 T, width 2 T, rigid clamps: Euler-Bernoulli with Cowper's shear,
    # Saint-Venant torsion with restrained warping (cantilever_stiffness), within 3 %.
    K = solid.stiffness("leaf", {"thickness": 1.0, "length": 8.0, "width": 2.0,
                                 "fillet": 0.0}, 1.0, NU, 3)
    ref = closed.cantilever_stiffness(8.0, 1.0, 2.0, 1.0, NU)
    assert np.allclose(np.diag(K), np.diag(ref), rtol=0.03, atol=0)
    assert np.all(np.abs(K - np.diag(np.diag(K))) < 2e-3 * np.abs(K).max())


@pytest.mark.slow
def test_mesh_convergence_the_change_shrinks():
    K2, K4, K6 = (np.diag(notch3d(1.0, n)) for n in (2, 4, 6))
    coarse, fine = np.abs(K2 - K4), np.abs(K4 - K6)
    assert np.all(fine < 0.3 * coarse), fine / coarse
    assert np.all(fine / K6 < 0.015)  # measured at most 1.1 % (z), docs/hinges.md


def test_si_scaling_of_a_real_notch():
    # K = E ell S K^ S: the same proportions at another size and modulus.
    E, ell = 69e9, 2.5e-4
    K = solid.stiffness("circular", {"h": ell, "D": 4 * ell, "t": 0.5 * ell}, E, NU)
    S = np.diag([ell] * 3 + [1.0] * 3)
    assert np.allclose(K, E * ell * S @ notch3d(0.5) @ S, rtol=1e-12, atol=0)


SPEC = {"model": "fe", "shape": "circular", "D": 1.0e-3, "h": 2.5e-4, "t": 1.25e-4,
        "E": 69e9, "nu": NU}


def doc3d(spec):
    return {"name": "one", "space": "3d", "defaults": {"damping": {"t_char": 1e-6}},
            "bodies": [{"name": "base", "mass": 1.0, "inertia": [1e-3, 1e-3, 1e-3],
                        "pose": [0, 0, 0]},
                       {"name": "plate", "mass": 0.01, "inertia": [1e-6, 1e-6, 1e-6],
                        "pose": [0.01, 0, 0]}],
            "hinges": [{"name": "n", "a": {"body": "base", "at": [0.005, 0, 0]},
                        "b": {"body": "plate", "at": [-0.005, 0, 0]}, "stiffness": spec}],
            "constraints": [{"type": "fixed", "body": "base"}]}


def test_a_3d_file_takes_model_fe():
    m = spatial_from_dict(doc3d(dict(SPEC)), "one.yaml")
    h = m.hinges[0]
    assert h.stiffness_source == "fe"
    geo = {k: SPEC[k] for k in ("D", "h", "t")}
    assert np.allclose(h.law.K, solid.stiffness("circular", geo, 69e9, NU), rtol=1e-12, atol=0)


@pytest.mark.parametrize("edit, message", [
    ({"resolution": 20}, r"hinges\[0\]\.stiffness\.resolution: expected a whole number"),
    ({"shape": "square"}, r"hinges\[0\]\.stiffness\.shape: unknown hinge shape"),
    ({"D": -1.0}, r"hinges\[0\]\.stiffness\.D"),
])
def test_a_bad_fe_block_in_3d_names_the_key(edit, message):
    with pytest.raises(ConfigError, match=message):
        spatial_from_dict(doc3d({**SPEC, **edit}), "one.yaml")


def test_a_planar_file_with_fe_hinges_opened_in_3d():
    doc = copy.deepcopy(read_yaml(resolve_mechanism_path("fourbar_cantilever"), ConfigError))
    leaf = {"model": "fe", "shape": "leaf", "length": 0.004, "thickness": 0.001,
            "width": 0.002, "E": 3.45e9, "nu": 0.3, "resolution": 8}
    doc["stiffness_models"]["leaf"] = leaf
    doc["constraints"] = doc["constraints"][:1]
    m = spatial_from_dict(doc, "fourbar.yaml")
    geo = {"length": 0.004, "thickness": 0.001, "width": 0.002, "fillet": 0.0}
    want = solid.stiffness("leaf", geo, 3.45e9, 0.3)  # the 3-D default resolution
    for h in m.hinges:
        assert h.stiffness_source == "fe"
        assert np.allclose(h.law.K, want, rtol=1e-12, atol=0)
    # its in-plane block lies between the planar plane-stress and plane-strain solves
    # (width = L / 2: neither limit; measured 16-48 % of the way)
    lo, hi = (np.diag(fe_model.stiffness("leaf", geo, 3.45e9, 0.3, p, 8))
              for p in ("stress", "strain"))
    where = (np.diag(in_plane(want)) - lo) / (hi - lo)
    assert np.all(where > 0) and np.all(where < 1), where
