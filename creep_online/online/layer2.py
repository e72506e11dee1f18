"""Layer 2 (resonance: a1, a2, b with alpha fixed) as a resumable job for the online estimator.

The fit is a generator: every ``next()`` does one bounded unit of work (one
model evaluation over the buffer, ~20-200 us) and yields, so the estimator can
spread it over incoming samples and ``update()`` never blocks. The model output
comes from the same exact SOE/ZOH state representation as the tracker
(``kernels.layer2_shape``): the node history over the buffer is computed once
(it depends on neither alpha nor the resonance), then each (a1, a2) costs one
2-state filter and one matrix-vector product. The gain b is projected out
(variable projection); (ln a1, ln a2) are fitted by Levenberg-Marquardt with
forward-difference Jacobians, started from a (fn, zeta) grid, as the batch
``creep_online.identification`` does with scipy (whose TRF cannot be paused).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Generator

import numpy as np

from . import kernels
from .soe import SoeBasis, resonance_zoh

#: Damping ratios of the starting grid.
GRID_ZETA = (0.02, 0.05, 0.1, 0.2, 0.4, 0.8, 1.5)
#: Natural frequencies of the starting grid (log-spaced).
GRID_FREQS = 24
#: Rows of the node history computed per unit of work.
HISTORY_CHUNK = 2048


@dataclass
class Layer2Result:
    """What the resonance fit found: parameters, 1-sigma std and the cost."""

    a1: float
    a2: float
    b: float
    cost: float
    std: dict = field(default_factory=dict)
    evaluations: int = 0
    iterations: int = 0


class Layer2Job:
    """Resumable layer-2 fit on u, y (offset removed, zero initial state at sample 0)."""

    def __init__(self, basis: SoeBasis, u: np.ndarray, y: np.ndarray, alpha: float,
                 start: tuple[float, float] | None = None, max_iter: int = 40) -> None:
        self.basis = basis
        self.u = np.ascontiguousarray(u, dtype=float)
        y = np.array(y, dtype=float)
        self._mask = np.isfinite(y).astype(float)   # NaN = dropped sample: no weight
        y[self._mask == 0.0] = 0.0
        self.y = y
        self.alpha = float(alpha)
        self.start = start
        self.max_iter = max_iter
        self.result: Layer2Result | None = None
        self.evaluations = 0
        q = basis.size
        self._hist = np.empty((self.u.size, q))
        self._v = np.empty(q + 2)
        self._dv = np.empty(q + 2)
        self._shape = np.empty(self.u.size)
        self._gen = self._run()

    # ------------------------------------------------------------------ driving
    def step(self) -> bool:
        """Do one unit of work; True when the result is ready."""
        if self.result is not None:
            return True
        try:
            next(self._gen)
        except StopIteration:
            pass
        return self.result is not None

    def run(self) -> Layer2Result:
        """Run to completion (block mode, tests)."""
        while not self.step():
            pass
        assert self.result is not None
        return self.result

    # ------------------------------------------------------------------ model
    def _residual(self, la1: float, la2: float) -> tuple[float, float, np.ndarray]:
        """(cost, b, unit-gain shape) for a1 = e^la1, a2 = e^la2, b projected out."""
        a1, a2 = math.exp(la1), math.exp(la2)
        phi, gam = resonance_zoh(a1, a2, self.basis.h)
        kernels.model_coefficients(self.alpha, self.basis.lam, self.basis.dx, a1, a2, self._v, self._dv)
        q = self.basis.size
        s = np.empty(self.u.size)
        kernels.layer2_shape(self._hist, self._v[:q].copy(), self.u, phi, gam, self._v[q], self._v[q + 1], s)
        s *= self._mask
        self.evaluations += 1
        den = float(s @ s)
        if not math.isfinite(den) or den <= 0.0:
            return math.inf, 0.0, s
        b = float(s @ self.y) / den
        r = self.y - b * s
        cost = float(r @ r)
        return (cost if math.isfinite(cost) else math.inf), b, s

    def _run(self) -> Generator[None, None, None]:
        # 1. node history (independent of alpha and of the resonance)
        zeta = np.zeros(self.basis.size)
        for i0 in range(0, self.u.size, HISTORY_CHUNK):
            i1 = min(i0 + HISTORY_CHUNK, self.u.size)
            kernels.node_history(self.u[i0:i1], self.basis.decay, self.basis.gain, zeta, self._hist[i0:i1])
            yield
        h = self.basis.h
        # 2. starting point: grid over (fn, zeta) unless given
        if self.start is None:
            span = self.u.size * h
            f_hi = 0.45 / h
            f_lo = min(max(2.0 / span, 1e-3), f_hi / 8)
            best = (math.inf, 0.0, 0.0)
            for fn in np.geomspace(f_lo, f_hi, GRID_FREQS):
                wn = 2 * math.pi * fn
                for zeta_r in GRID_ZETA:
                    la1, la2 = math.log(2 * zeta_r / wn), math.log(1 / wn**2)
                    cost, _, _ = self._residual(la1, la2)
                    if cost < best[0]:
                        best = (cost, la1, la2)
                    yield
            p = np.array(best[1:])
        else:
            p = np.log(np.asarray(self.start, dtype=float))
        # 3. Levenberg-Marquardt on (ln a1, ln a2), b projected out
        cost, b, s = self._residual(*p)
        yield
        mu = 1e-3
        eps = 1e-6
        jac = np.zeros((self.u.size, 2))
        it = 0
        for it in range(self.max_iter):
            r0 = self.y - b * s
            for k in range(2):
                pk = p.copy()
                pk[k] += eps
                _, bk, sk = self._residual(*pk)
                jac[:, k] = (self.y - bk * sk - r0) / eps
                yield
            jtj = jac.T @ jac
            g = jac.T @ r0
            improved = False
            for _ in range(8):
                a = jtj + mu * np.diag(np.diag(jtj) + 1e-30)
                try:
                    step = -np.linalg.solve(a, g)
                except np.linalg.LinAlgError:
                    mu *= 10
                    continue
                step = np.clip(step, -2.0, 2.0)
                c_new, b_new, s_new = self._residual(*(p + step))
                yield
                if c_new < cost:
                    rel = (cost - c_new) / max(cost, 1e-300)
                    p, cost, b, s = p + step, c_new, b_new, s_new
                    mu = max(mu / 3, 1e-9)
                    improved = True
                    break
                mu *= 10
            if not improved or rel < 1e-10 or float(np.max(np.abs(step))) < 1e-8:
                break
        a1, a2 = math.exp(p[0]), math.exp(p[1])
        std = self._std(jac, cost, b, s, a1, a2)
        self.result = Layer2Result(a1=a1, a2=a2, b=b, cost=cost, std=std,
                                   evaluations=self.evaluations, iterations=it + 1)

    def _std(self, jac: np.ndarray, cost: float, b: float, s: np.ndarray, a1: float, a2: float) -> dict:
        """1-sigma std of a1, a2, b from the Gauss-Newton covariance (b's column included)."""
        n = int(self._mask.sum())
        full = np.column_stack([jac, -s])
        try:
            cov = cost / max(n - 3, 1) * np.linalg.inv(full.T @ full)
            sd = np.sqrt(np.abs(np.diag(cov)))
        except np.linalg.LinAlgError:
            return {"a1": math.inf, "a2": math.inf, "b": math.inf}
        out = {"a1": float(sd[0] * a1), "a2": float(sd[1] * a2), "b": float(sd[2])}
        return {k: (v if math.isfinite(v) else math.inf) for k, v in out.items()}
