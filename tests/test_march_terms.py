"""``kernels.state_march`` (Taylor terms dropped below 1e-14, t^alpha as exp(alpha ln t)) against the
plain march it replaced: every one of the eight Taylor terms, t**alpha, in numpy and a Python loop.

The two differ only in round-off and in terms below 1e-14 of the forcing, so the
step responses agree to 2e-14 of their size (measured <= 7e-15, as the replaced kernel), over the regimes where 8, 4 and 3
terms are kept (the first 72, from 1,778 and from 21,544 samples).
"""
import math

import numpy as np
import pytest

from creep_online import kernels
from creep_online.discretize import head_terms, taylor_moments


def _plain_march(n, h, alpha, phi, head, taylor):
    k = np.arange(n - 1)
    t = np.where(k > 0, k * h, 1.0)
    deriv = t**alpha / math.gamma(1.0 + alpha)
    force = np.outer(deriv, taylor[0])
    for m in range(1, taylor.shape[0]):
        deriv = deriv * (alpha - (m - 1)) / t
        force += np.outer(deriv, taylor[m])
    force[:head.shape[0]] = head
    s = np.zeros(n)
    x = np.zeros(2)
    for i in range(n - 1):
        x = phi @ x + force[i]
        s[i + 1] = x[0]
    return s


@pytest.mark.parametrize("alpha, a1, a2, h", [(0.0133, 1e-4, 5e-8, 1e-4), (0.3, 0.02, 4e-4, 1e-3),
                                              (0.9, 1e-3, 1e-5, 5e-3), (0.05, 2.0, 0.5, 1e-3)])
def test_march_equals_the_plain_march(alpha, a1, a2, h):
    n = 30000
    phi, taylor = taylor_moments(a1, a2, h)
    head = head_terms(alpha, a1, a2, h, 32)
    got = kernels.state_march(n, h, alpha, math.gamma(1.0 + alpha), phi, head, taylor)
    want = _plain_march(n, h, alpha, phi, head, taylor)
    assert np.max(np.abs(got - want)) <= 2e-14 * np.max(np.abs(want))
