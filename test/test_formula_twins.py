"""
One definition per formula (issue 10 item 3).

Where Numba needs a compiled copy, it is the same source compiled, or a twin pinned here to the
reference at random inputs to machine precision.
"""
import math

import numpy as np
import pytest

from flexure_sim.engine.laws import quadratic as hinge_laws
from flexure_sim.engine.solver import kernels
from flexure_sim.engine.kinematics import planar as kinematics
from flexure_sim.engine.solver.assembly import Assembly
from flexure_sim.engine.mechanism.loader import load_mechanism

EPS = np.finfo(float).eps


def test_half_cotangent_has_one_source():
    """
    The force kernel compiles kinematics.half_cot_scalar itself.

    Also, hinge_laws uses kinematics' array version of it: no second series with its own threshold.
    """
    assert kernels._half_cot.py_func is kinematics.half_cot_scalar
    assert not hasattr(hinge_laws, "_half_cot_derivatives")
    rng = np.random.default_rng(0)
    a = np.concatenate([rng.uniform(-3, 3, 50), rng.uniform(-2e-2, 2e-2, 50), [0.0, 1e-2, -1e-2]])
    f, f1, f2 = kinematics.half_cot_derivatives(a)
    for k, x in enumerate(a):
        assert kernels._half_cot(x) == (f[k], f1[k], f2[k])


def test_half_cotangent_series_and_closed_form_meet():
    """Both branches agree across the threshold and with finite differences of f."""
    for a in (kinematics.HALF_COT_SERIES * (1 - 1e-9), kinematics.HALF_COT_SERIES * (1 + 1e-9)):
        f, f1, f2 = kinematics.half_cot_scalar(a)
        assert f == pytest.approx(0.5 * a / math.tan(0.5 * a), rel=4 * EPS)
        h = 1e-4
        plus, minus = kinematics.half_cot_scalar(a + h), kinematics.half_cot_scalar(a - h)
        assert f1 == pytest.approx((plus[0] - minus[0]) / (2 * h), rel=1e-7)
        assert f2 == pytest.approx((plus[1] - minus[1]) / (2 * h), rel=1e-7)


@pytest.mark.parametrize("name", ["microstage", "fourbar_mixed"])
def test_compiled_relative_displacement_is_the_reference(name):
    """kernels.hinge_relative against Assembly.relative: r(z) and dr/dzz, random poses."""
    asm = Assembly(load_mechanism(name))
    rng = np.random.default_rng(1)
    z0 = np.array([b.pose for b in asm.mechanism.bodies], dtype=float).ravel()
    dr = np.zeros((3, 6))
    for scale in (1e-6, 1e-2, 1.0):
        z = z0 + rng.normal(size=len(z0)) * scale
        r, dr_ref, _ = asm.relative(z, second=False)
        for h in range(len(asm.ia)):
            A, B = 3 * asm.ia[h], 3 * asm.ib[h]
            got = kernels.hinge_relative(*z[A:A + 3], *z[B:B + 3], *asm.ca[h], *asm.cb[h],
                                         asm.phia[h], asm.phib[h], dr)
            scale_r = np.abs(r[h]).max() + np.abs(z[[A, A + 1, B, B + 1]]).max()
            assert np.allclose(got, r[h], rtol=0, atol=8 * EPS * scale_r)
            assert np.allclose(dr, dr_ref[h], rtol=0, atol=8 * EPS * (1 + np.abs(dr_ref[h]).max()))


@pytest.mark.parametrize("kind,coords", [(kernels.TWISTOR, "twistor"), (kernels.TWIST, "twist")])
def test_compiled_law_coordinates_are_the_reference(kind, coords):
    """kernels.law_coordinates against hinge_laws' coordinate maps: c(r) and dc/dr."""
    rng = np.random.default_rng(2)
    alpha = np.concatenate([rng.uniform(-2, 2, 30), rng.uniform(-1e-2, 1e-2, 30)])
    p = rng.normal(size=(len(alpha), 2)) * 1e-3
    ref = hinge_laws.COORDINATES[coords](alpha, p, second=False)
    off = 1 if coords == "twistor" else 0  # the twistor's sigma is not a law coordinate
    dv = np.zeros((3, 3))
    for k in range(len(alpha)):
        c = kernels.law_coordinates(kind, alpha[k], p[k, 0], p[k, 1], dv)
        c_ref, dc_ref = ref.c[k, off:], ref.dc[k, off:]
        assert np.allclose(c, c_ref, rtol=0, atol=8 * EPS * np.abs(c_ref).max())
        assert np.allclose(dv, dc_ref, rtol=0, atol=8 * EPS * np.abs(dc_ref).max())


def test_hinge_stiffness_and_damping_live_in_the_law_only():
    """No unread Hinge.K / Hinge.B copies next to the law's own (issue 10 item 5)."""
    import dataclasses

    from flexure_sim.engine.mechanism.parts import Hinge

    names = {f.name for f in dataclasses.fields(Hinge)}
    assert "K" not in names and "B" not in names
    assert names == {"name", "a", "b", "law", "stiffness_source", "stress"}
    hinge = load_mechanism("microstage").hinges[0]
    assert hinge.law.K[1, 1] == pytest.approx(1.588e8, rel=1e-3)
