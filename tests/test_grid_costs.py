"""``kernels.foh_grid_costs`` (all grid points marched together) against one ``resonance_foh`` per point.

The reference simulates each grid point's split-form response and projects the
gain out with numpy; the kernel's per-point arithmetic is the same, so the costs
agree to round-off of the final dot products.
"""
import numpy as np

from creep_online import kernels
from creep_online.discretize import foh_matrices_batch
from creep_online.simulate import fractional_integral


def _reference(z, y, phi, g0, g1, h):
    out = []
    for k in range(phi.shape[0]):
        s = kernels.resonance_foh(z, phi[k], g0[k], g1[k], h)
        ss = s @ s
        out.append(y @ y - (s @ y) ** 2 / ss if ss > 0 else y @ y)
    return np.array(out)


def test_grid_costs_equal_one_simulation_per_point():
    rng = np.random.default_rng(4)
    for h, n, alpha in ((1e-4, 4096, 0.05), (5e-3, 600, 0.6), (1e-3, 3, 0.3)):
        u = np.where(np.arange(n) < n // 3, 1.0, -0.5)
        z = fractional_integral(u, h, alpha)
        y = z * 0.7 + rng.standard_normal(n) * 0.01
        fn = np.geomspace(2.0 / (n * h), 0.45 / h, 23)
        zeta = np.resize([0.01, 0.1, 0.5, 1.0, 2.0], fn.size)
        wn = 2 * np.pi * fn
        phi, g0, g1 = foh_matrices_batch(2 * zeta / wn, 1 / wn**2, h)
        got = kernels.foh_grid_costs(z, y, phi, g0, g1, h)
        np.testing.assert_allclose(got, _reference(z, y, phi, g0, g1, h), rtol=1e-12, atol=1e-14 * (y @ y))
