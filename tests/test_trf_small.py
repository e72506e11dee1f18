"""``trf_small.trf`` against scipy's least_squares(method="trf") on random bounded problems.

The port follows scipy's iteration step for step; only round-off differs (the
SVD and the n-vector arithmetic), so both must make the same number of
evaluations and stop at the same point, also where the bounds are active and
where a parameter is unidentifiable.
"""
import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from creep_online.trf_small import trf


def _problem(seed: int):
    """A damped-cosine fit y ~ exp(-p0 t) cos(p1 t) (+ p2 t when three parameters), noisy, with bounds."""
    rng = np.random.default_rng(seed)
    n = 2 + seed % 2
    t = np.linspace(0.0, 3.0, int(rng.integers(5, 400)))
    truth = np.array([rng.uniform(0.2, 2.0), rng.uniform(1.0, 6.0), rng.uniform(-1, 1)])[:n]

    def model(p):
        e = np.exp(-p[0] * t)
        out = e * np.cos(p[1] * t)
        jac = [-t * out, -t * e * np.sin(p[1] * t)]
        if n == 3:
            out = out + p[2] * t
            jac.append(t)
        return out, np.column_stack(jac)

    y = model(truth)[0] + rng.uniform(0.001, 0.3) * rng.standard_normal(t.size)

    def evaluate(p):
        out, jac = model(p)
        return out - y, jac

    x0 = truth * rng.uniform(0.5, 1.5, n)
    width = rng.choice([0.05, 0.3, 10.0])            # narrow boxes make the bounds active
    lb, ub = x0 - width * abs(x0) * rng.uniform(0.1, 1, n), x0 + width * abs(x0) * rng.uniform(0.1, 1, n)
    return evaluate, x0, lb, ub


def _scipy(evaluate, x0, lb, ub):
    sol = least_squares(lambda p: evaluate(p)[0], x0, jac=lambda p: evaluate(p)[1], bounds=(lb, ub),
                        method="trf", x_scale=np.ones(len(x0)))
    return sol.x, sol.nfev, sol.status


@pytest.mark.parametrize("seed", range(40))
def test_same_evaluations_and_minimum_as_scipy(seed):
    evaluate, x0, lb, ub = _problem(seed)
    x, nfev, status = trf(evaluate, x0, lb, ub)
    x_ref, nfev_ref, status_ref = _scipy(evaluate, x0, lb, ub)
    assert (nfev, status) == (nfev_ref, status_ref)
    np.testing.assert_allclose(x, x_ref, rtol=1e-9, atol=1e-12)


def test_an_unidentifiable_parameter_stops_where_scipy_stops():
    t = np.linspace(0, 1, 200)
    y = 2.0 * t + 0.01 * np.sin(40 * t)

    def evaluate(p):          # only the product p0 p1 is determined
        return p[0] * p[1] * t - y, np.column_stack((p[1] * t, p[0] * t))

    lb, ub = np.array([math.log(1e-3), -5.0]), np.array([10.0, 10.0])
    x, nfev, status = trf(evaluate, [0.5, 1.0], lb, ub)
    x_ref, nfev_ref, status_ref = _scipy(evaluate, np.array([0.5, 1.0]), lb, ub)
    assert (nfev, status) == (nfev_ref, status_ref)
    np.testing.assert_allclose(x, x_ref, rtol=1e-9)


def test_the_svd_is_scipys_bit_for_bit():
    from scipy.linalg import svd

    from creep_online.trf_small import _svd
    rng = np.random.default_rng(0)
    for shape in ((4, 2), (600, 2), (37, 3)):
        a = rng.standard_normal(shape)
        for got, want in zip(_svd(a), svd(a, full_matrices=False)):
            assert np.array_equal(got, want)
