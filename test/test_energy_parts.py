"""
Parts of the energy integrals that were made cheaper without changing a bit.

``step_energy._rows_times`` (Mat^T x four rows per pass) and ``_form_t`` (x^T Mat x along the
rows of Mat^T) against the row-by-row sums in Python floats, and
``quadratic_integrals.power_entries`` (N^p / p!'s entries, kept for the last N) against N's
powers.
"""
import math

import numpy as np
import pytest

from flexure_sim.engine.solver import quadratic_integrals
from flexure_sim.engine.solver.step_energy import _form_t, _rows_times


@pytest.mark.parametrize("shape", [(50, 50), (13, 50), (7, 3), (1, 4), (0, 5)])
def test_rows_times_sums_each_entry_in_the_order_of_the_rows(shape):
    rng = np.random.default_rng(sum(shape))
    Mat = rng.normal(size=shape) * 10.0 ** rng.integers(-8, 8, size=shape)
    x = rng.normal(size=shape[0]) * 10.0 ** rng.integers(-8, 8, size=shape[0])
    start = rng.normal(size=shape[1])
    want = [float(v) for v in start]
    for j in range(shape[0]):                 # one row per pass, in order: the old loop
        for i in range(shape[1]):
            want[i] += float(Mat[j, i]) * float(x[j])
    got = _rows_times(Mat, x, start.copy())
    assert [v.hex() for v in got] == [v.hex() for v in want]


@pytest.mark.parametrize("n", [13, 6, 1, 0])
def test_form_from_the_transpose_is_the_row_by_row_form(n):
    rng = np.random.default_rng(n)
    Mat = rng.normal(size=(n, n)) * 10.0 ** rng.integers(-8, 8, size=(n, n))
    x = rng.normal(size=n + 3) * 10.0 ** rng.integers(-8, 8, size=n + 3)
    want = 0.0
    for i in range(n):                        # each row from 0.0 in column order, then the rows
        row = 0.0
        for j in range(n):
            row += float(Mat[i, j]) * float(x[3 + j])
        want += float(x[3 + i]) * row
    assert _form_t(np.ascontiguousarray(Mat.T), x[3:], np.empty(len(Mat))).hex() == want.hex()


def _generator_inputs(m, h, programs):
    """N of the step's generator (``step_energy.energy_matrices``): f' = n / h, program chains."""
    q = programs
    r = 2 * m + 4 * q
    N = np.zeros((r, r))
    N[:m, m:2 * m] = np.eye(m) / h
    N[2 * m:2 * m + 3 * q, 2 * m + q:] = np.eye(3 * q)
    return N


def _dense_powers(N):
    """{p: N^p / p!} for p >= 1 while nonzero."""
    out, p = {}, 1
    while True:
        power = np.linalg.matrix_power(N, p) / math.factorial(p)
        if not power.any():
            return out
        out[p] = power
        p += 1


@pytest.mark.parametrize("programs", [0, 2])
def testpower_entries_are_n_powers_and_follow_a_new_n(programs):
    for h in (1e-4, 2.5e-5, 1e-4):              # back to the first N after another one
        N = _generator_inputs(5, h, programs)
        coo = quadratic_integrals.power_entries(N)
        want = _dense_powers(N)
        assert sorted(set(coo[:, 3].astype(int))) == sorted(want)
        for p, power in want.items():
            rebuilt = np.zeros_like(N)
            rows = coo[coo[:, 3] == p]
            rebuilt[rows[:, 0].astype(int), rows[:, 1].astype(int)] = rows[:, 2]
            assert np.array_equal(rebuilt, power)
    assert quadratic_integrals.power_entries(N.copy()) is coo      # the same N: kept


@pytest.mark.parametrize("m", [0, 1, 7, 25])
def test_balancing_is_scipys_and_refuses_what_scipy_refuses(m):
    import scipy.linalg

    rng = np.random.default_rng(m)
    A = rng.normal(size=(m, m)) * 10.0 ** rng.integers(-6, 6, size=(m, m))
    want = scipy.linalg.matrix_balance(A, permute=False, separate=True)[1][0]
    assert np.array_equal(quadratic_integrals.balancing(A), want)
    if m:
        A[0, -1] = np.nan
        with pytest.raises(ValueError, match="infs or NaNs"):
            quadratic_integrals.balancing(A)
