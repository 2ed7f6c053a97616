"""
The step's quadratic integrals: the whole doubling and the stiff modes split off.

Against adaptive quadrature of the integrands (an independent method): the doubling
(``quadratic_integrals``) on a generator with a mode at -1e6 / h, the split (``stiff_split``)
on generators with a real and a complex pair of fast modes; the split against the doubling of
the whole generator on the stage's own linearization; generators the split does not apply to
are doubled as before, bit for bit.
"""
import math

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver import integrator, step_energy, stiff_split
from flexure_sim.engine.solver.quadratic_integrals import balancing, quadratic_integrals
from flexure_sim.engine.solver.simulation import Simulation


def _generator(A, h, q, rng, undamped=1):
    """
    M of ``step_energy.energy_matrices`` (w, f, n, then q program chains) and a Q like its.

    Q couples w and the chains' beta as the dissipation does; the first ``undamped`` states of
    w are not damped (as C_x leaves the positions out).
    """
    m = A.shape[0]
    n = 3 * m + 4 * q
    M = np.zeros((n, n))
    M[:m, :m], M[:m, m:2 * m], M[m:2 * m, 2 * m:3 * m] = A, np.eye(m), np.eye(m) / h
    M[:m, 3 * m:3 * m + 2 * q] = rng.normal(size=(m, 2 * q)) / h
    M[3 * m:3 * m + 3 * q, 3 * m + q:] = np.eye(3 * q)
    B = rng.normal(size=(m + q, m + q))
    Q = np.zeros((n, n))
    inner = np.r_[undamped:m, 3 * m + q:3 * m + 2 * q]
    Q[np.ix_(inner, inner)] = (B @ B.T)[undamped:, undamped:]
    return M, Q


def _quadrature(M, Q, h, m):
    """int_0^h e^{M^T s} Q e^{Ms} ds and int_0^h e^{Ms}[:m, m:] ds by adaptive quadrature."""
    n = M.shape[0]

    def integrand(s):
        e = scipy.linalg.expm(s * M)
        return np.concatenate([(e.T @ Q @ e).ravel(), e[:m, m:].ravel()])

    points = list(np.logspace(-14, math.log10(h), 12))
    ref = scipy.integrate.quad_vec(integrand, 0, h, epsrel=1e-12, points=points)[0]
    return ref[:n * n].reshape(n, n), ref[n * n:].reshape(m, n - m)


@pytest.mark.parametrize("programs", [0, 1])
def test_quadratic_integrals_equal_their_integrals_for_a_stiff_generator(programs):
    """
    The whole doubling: G and int_0^h W(s) ds against adaptive quadrature.

    A has a mode at -1e6 / h (the stage's stiffest at its step): Van Loan's block exponential
    would hold e^{1e6} there; the doubling must not.
    """
    rng = np.random.default_rng(5)
    m, h = 4, 1e-4
    A = rng.normal(size=(m, m)) / h - 2.0 / h * np.eye(m)
    A[0, 0] = -1e6 / h
    M, Q = _generator(A, h, programs, rng, undamped=0)
    G, IW = quadratic_integrals(M, Q, h, m)
    G_ref, IW_ref = _quadrature(M, Q, h, m)
    assert G == pytest.approx(G_ref, rel=1e-8, abs=1e-12 * np.abs(G).max())
    assert IW == pytest.approx(IW_ref, rel=1e-8, abs=1e-12 * np.abs(IW).max())


@pytest.mark.parametrize("programs", [0, 1])
def test_split_integrals_equal_their_integrals(programs):
    """
    G's input block and int_0^h W ds, split, against quadrature of e^{M^T s} Q e^{Ms}.

    A has a real fast mode (-1e3 / h) and a complex pair (-120 / h +- 80 i / h), near the
    threshold (-50 / h), where the fast modes' own terms still count, coupled to three slow
    modes; Q leaves one state undamped.
    """
    rng = np.random.default_rng(11)
    m, h, q = 5, 1e-4, programs
    A = rng.normal(size=(m, m)) / h - 2.0 / h * np.eye(m)
    A[0, 0] = -1e3 / h
    A[3:5, 3:5] = np.array([[-120.0, 80.0], [-80.0, -120.0]]) / h
    M, Q = _generator(A, h, q, rng)
    assert np.sum(np.linalg.eigvals(A).real * h < -stiff_split.FAST) == 3
    split = stiff_split._split(M, Q, h, m, balancing(A))
    assert split is not None
    G, IW = split
    G_ref, IW_ref = _quadrature(M, Q, h, m)
    assert G == pytest.approx(G_ref[m:, m:], rel=1e-8, abs=1e-12 * np.abs(G).max())
    assert IW == pytest.approx(IW_ref, rel=1e-8, abs=1e-12 * np.abs(IW).max())


def _stage_generator():
    """M, Q, h, m of the stage's first linearization with the energy integrals."""
    caught = []
    sim = Simulation(load_mechanism("microstage"))
    sim.set_command(1.35e-6)
    sim.step(1)
    model, state = sim.model, sim.state
    original = step_energy.step_integrals
    try:
        step_energy.step_integrals = lambda *args: caught.append(args) or original(*args)
        integrator.linearize(model, sim.data, model.pack(state), state.t, state.command)
    finally:
        step_energy.step_integrals = original
    return caught[0]


def test_the_stage_is_split_and_agrees_with_the_whole_doubling():
    """The stage at its step takes the split; both methods agree to 1e-10 of G's largest."""
    M, Q, h, m = _stage_generator()
    G, IW = stiff_split.step_integrals(M, Q, h, m)
    split = stiff_split._split(M, Q, h, m, balancing(M[:m, :m]))
    assert split is not None and np.array_equal(G, split[0]) and np.array_equal(IW, split[1])
    Gd, IWd = quadratic_integrals(M, Q, h, m)
    assert np.abs(G - Gd[m:, m:]).max() <= 1e-10 * np.abs(Gd[m:, m:]).max()
    assert np.abs(IW - IWd).max() <= 1e-10 * np.abs(IWd).max()
    assert np.array_equal(G, G.T)


def test_a_generator_with_only_fast_modes_is_left_to_the_whole_doubling():
    """Every mode fast (a coarse step): nothing slow to double; the split declines."""
    rng = np.random.default_rng(2)
    m, h = 4, 1e-4
    A = rng.normal(size=(m, m)) / h - 3e3 / h * np.eye(m)
    assert np.all(np.linalg.eigvals(A).real * h < -stiff_split.FAST)
    M, Q = _generator(A, h, 1, rng)
    assert stiff_split._split(M, Q, h, m, balancing(A)) is None


def test_generators_without_fast_modes_or_of_another_form_are_doubled_whole():
    """No fast mode, or inputs that do not force w as the step's f does: the doubling's bits."""
    rng = np.random.default_rng(3)
    m, h = 4, 1e-4
    mild = rng.normal(size=(m, m)) / h - 2.0 / h * np.eye(m)
    stiff = mild.copy()
    stiff[0, 0] = -1e6 / h
    for A, scale in ((mild, 1.0), (stiff, 2.0)):
        M, Q = _generator(A, h, 0, rng)
        M[:m, m:2 * m] *= scale      # f forcing w twice over: not the step's generator
        assert stiff_split._step_generator(M, m) == (scale == 1.0)
        G, IW = stiff_split.step_integrals(M, Q, h, m)
        Gd, IWd = quadratic_integrals(M, Q, h, m)
        assert np.array_equal(G, Gd[m:, m:]) and np.array_equal(IW, IWd)
