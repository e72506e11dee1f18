"""Every simulator against independent references.

References: FOMCON's lsim outputs (paper method), inverse-Laplace step
responses at 30 digits and ODE-integrated piecewise responses (exact method),
the closed form t^alpha / Gamma(1+alpha) (fractional integral), and scipy
quadrature of the convolution integral for damping cases the data lacks.
"""
import json
import math

import numpy as np
import pytest
from scipy.integrate import quad

from creep_online import CreepModel, simulate
from creep_online.discretize import step_response_grid
from creep_online.simulate import fractional_integral, superpose


def _csv(path):
    return np.loadtxt(path, delimiter=",", skiprows=1)


def fomcon_cases(root):
    return json.loads((root / "fomcon" / "cases.json").read_text())["cases"]


def test_paper_method_matches_fomcon_to_1e9(reference_data):
    for case in fomcon_cases(reference_data):
        data = _csv(reference_data / "fomcon" / case["csv"])
        m = CreepModel(case["alpha"], case["a1"], case["a2"], case["b"])
        y = simulate(m, data[:, 0], data[:, 1], method="paper")
        rel = np.max(np.abs(y - data[:, 2])) / np.max(np.abs(data[:, 2]))
        assert rel < 1e-9, (case["name"], rel)


def test_exact_method_matches_inverse_laplace_steps(reference_data):
    refs = json.loads((reference_data / "oracle" / "mpmath_refs.json").read_text())["models"]
    h = 1e-4
    for ref in refs:
        data = _csv(reference_data / "oracle" / ref["csv"])
        alpha, a1, a2, b = (float(ref[k]) for k in ("alpha", "a1", "a2", "b"))
        idx = np.rint(data[:, 0] / h).astype(int)
        on_grid = np.abs(idx * h - data[:, 0]) < 1e-12
        s = b * step_response_grid(alpha, a1, a2, h, idx.max() + 1)
        rel = np.abs(s[idx[on_grid]] - data[on_grid, 1]) / np.abs(data[on_grid, 1])
        assert on_grid.sum() >= 20
        assert rel.max() < 1e-12, (ref["csv"], rel.max())


def exact_refs(root):
    return json.loads((root / "oracle" / "exact_refs.json").read_text())


def test_exact_method_matches_piecewise_references(reference_data):
    # the references are integrated to 1e-10 relative; we agree to that level
    for ref in exact_refs(reference_data):
        data = _csv(reference_data / "oracle" / f"{ref['name']}.csv")
        m = CreepModel(ref["alpha"], ref["a1"], ref["a2"], ref["b"])
        y = simulate(m, data[:, 0], data[:, 1])
        rel = np.max(np.abs(y - data[:, 2])) / np.max(np.abs(data[:, 2]))
        assert rel < 1e-9, (ref["name"], rel)


def _quad_step(alpha, a1, a2, t):
    """S(t) = int_0^t g(t - tau) tau^alpha / Gamma(1+alpha) dtau with the resonance impulse response g."""
    p = np.roots([a2, a1, 1.0]).astype(complex)
    if abs(p[0] - p[1]) < 1e-6 * abs(p[0]):  # repeated (np.roots splits it by ~1e-8)
        lam = p.real.mean()
        g = lambda s: (s * math.exp(lam * s)) / a2  # noqa: E731 (repeated pole)
    else:
        g = lambda s: ((np.exp(p[0] * s) - np.exp(p[1] * s)) / (a2 * (p[0] - p[1]))).real  # noqa: E731
    val, _ = quad(lambda tau: g(t - tau), 0.0, t, weight="alg", wvar=(alpha, 0.0),
                  epsabs=0, epsrel=1e-13, limit=400)
    return val / math.gamma(1.0 + alpha)


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")  # quad's roundoff notice at 1e-13
@pytest.mark.parametrize("zeta", [0.02, 1.0, 4.0, 40.0])
def test_exact_step_response_under_critically_and_over_damped(zeta):
    m = CreepModel.from_resonance(0.3, 50.0, zeta)
    h = 2e-4
    s = step_response_grid(m.alpha, m.a1, m.a2, h, 2001)
    for n in (1, 3, 17, 40, 333, 2000):
        ref = _quad_step(m.alpha, m.a1, m.a2, n * h)
        assert s[n] == pytest.approx(ref, rel=1e-10, abs=1e-14), (zeta, n)


def test_fractional_integral_of_a_step_is_the_closed_form():
    h, n = 1e-3, 5000
    t = np.arange(n) * h
    for alpha in (0.0133, 0.3, 0.7):
        z = fractional_integral(np.ones(n), h, alpha)
        np.testing.assert_allclose(z, t**alpha / math.gamma(1 + alpha), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("alpha", [0.0133, 0.05, 0.4])
def test_truncated_memory_error_is_the_dropped_tail(alpha):
    """With memory L the step's fractional integral is (L h)^alpha / Gamma(1+alpha) for n > L: the
    error is exactly ((N h)^alpha - (L h)^alpha) / Gamma(1+alpha), large for small alpha."""
    h, n, memory = 1e-3, 10000, 1000
    z_full = fractional_integral(np.ones(n), h, alpha)
    z_short = fractional_integral(np.ones(n), h, alpha, memory=memory)
    tail = ((n - 1) * h) ** alpha - (memory * h) ** alpha
    assert z_full[-1] - z_short[-1] == pytest.approx(tail / math.gamma(1 + alpha), rel=1e-10)
    if alpha == 0.0133:  # README.md, short-memory table: N/L = 10 loses ~3 %
        assert 0.025 < (z_full[-1] - z_short[-1]) / z_full[-1] < 0.035


def _order(errors, hs):
    return np.polyfit(np.log(hs), np.log(errors), 1)[0]


def test_convergence_orders_against_the_exact_reference(reference_data):
    """paper (eq. 13) and split form converge at first order in h; exact is exact at every h."""
    ref = next(r for r in exact_refs(reference_data) if r["name"].startswith("exact_updown"))
    data = _csv(reference_data / "oracle" / f"{ref['name']}.csv")
    m = CreepModel(ref["alpha"], ref["a1"], ref["a2"], ref["b"])
    scale = np.max(np.abs(data[:, 2]))
    hs, errs = [], {"paper": [], "split": [], "exact": []}
    for stride in (16, 8, 4, 2):
        sub = data[::stride]
        hs.append(sub[1, 0] - sub[0, 0])
        for method in errs:
            y = simulate(m, sub[:, 0], sub[:, 1], method=method)
            errs[method].append(np.max(np.abs(y - sub[:, 2])) / scale)
    assert 0.85 < _order(errs["paper"], hs) < 1.2
    assert 0.85 < _order(errs["split"], hs) < 1.6
    assert max(errs["exact"]) < 1e-9
    assert errs["split"][-1] < errs["paper"][-1]


def test_superposition_sparse_and_fft_agree():
    rng = np.random.default_rng(1)
    s = step_response_grid(0.2, 1e-3, 1e-6, 1e-4, 3000)
    few = np.repeat(rng.normal(size=10), 300)
    many = np.repeat(rng.normal(size=300), 10)
    for u in (few, many):
        direct = np.array([sum((u[k] - (u[k - 1] if k else 0.0)) * s[n - k] for k in range(n + 1)
                               if u[k] != (u[k - 1] if k else 0.0)) for n in range(0, 3000, 97)])
        np.testing.assert_allclose(superpose(s, u)[::97], direct, rtol=1e-9, atol=1e-12)


def test_memory_argument_rules():
    m = CreepModel(0.3, 0.01, 1e-4)
    t = np.arange(100) * 1e-3
    u = np.ones(100)
    with pytest.raises(ValueError, match="memory"):
        simulate(m, t, u, method="exact", memory=10)
    with pytest.raises(ValueError, match="unknown method"):
        simulate(m, t, u, method="euler")
    # full memory through the truncation path equals the untruncated result
    np.testing.assert_allclose(simulate(m, t, u, "paper", memory=1000), simulate(m, t, u, "paper"), rtol=1e-14)


def test_batched_foh_matrices_match_the_matrix_exponential():
    from creep_online.discretize import foh_matrices, foh_matrices_batch
    h = 1e-3
    cases = [(0.02, 4e-4), (2 * 1.0 / 300, 1 / 300**2), (2 * 4.0 / 50, 1 / 50**2), (1e-5, 1e-8)]
    a1 = np.array([c[0] for c in cases])
    a2 = np.array([c[1] for c in cases])
    phi, g0, g1 = foh_matrices_batch(a1, a2, h)
    for k, (x1, x2) in enumerate(cases):
        ref = foh_matrices(x1, x2, h)
        for got, want in zip((phi[k], g0[k], g1[k]), ref):
            np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-12 * np.abs(want).max())
