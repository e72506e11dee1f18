"""Batch identification: the paper's two layers, made fast.

The scheme of Tashakori et al. (Actuators 2024, 13, 534), output-error least
squares with trust-region-reflective steps (scipy's ``least_squares(method="trf")``
iteration; layer 2 runs it without scipy's wrappers, ``trf_small``):

* **Layer 1 (creep)**: alpha from the creep regime (samples more than ``t_c``
  after the last input change), on a coarser step (bin averages). Long after a
  step the response is the creep law plus the resonance's low-frequency
  correction ``sum_k c_k t^(alpha-k) / Gamma(1+alpha-k)``, so no simulation is
  needed; the gain is linear and projected out. Then the eq. 12 retune.
* **Layer 2 (resonance)**: a1, a2 and b with alpha fixed, on the transient
  windows (``t_c`` after each change) at the full rate, with the exact
  simulator; b is linear and projected out (variable projection).
* Optional joint polish of all four on the whole record, warm-started.

``t_c`` and the starting point come from the data: a coarse creep fit gives a
first alpha, a grid over (fn, zeta) on the first transient gives the
resonance, and ``t_c`` is the resonance's settling time.

When the result is not at the noise floor, ``global_fit`` takes over
(multi-start, free offset, the initial state of records taken in operation).
The final residual is tested for input changes that fall between samples
(``timing``), and the 1-sigma intervals are widened for coloured residuals.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from .special import digamma, rgamma

from . import kernels
from ._threads import single_threaded
from .discretize import foh_matrices_batch, step_response_grid, step_response_sensitivity
from .checks import is_real, number, positive
from .errors import DataError, IdentificationError
from .global_fit import GRID_ZETAS, GlobalFit, at_floor, floor_ratio, global_fit, global_uncertainty, n_bic
from .metrics import fit_percent, long_run_variance_factor, noise_std_estimate, rms
from .model import IDENTIFY_ALPHA_BOUNDS as ALPHA_BOUNDS  # alpha search interval of layer 1 and the polish
from .initial_state import FreeResponse
from .model import CreepModel, ExtendedModel, FittedModel
from .record import SAFE_AMPLITUDE, Record, check_time_and_output
from .simulate import fractional_integral, increments, input_changes, superpose, superpose_rows, uniform_step
from .timing import TimingCheck, check_timing
from .trf_small import trf

#: At most this many input changes count as a piecewise-constant (step) input.
MAX_STEP_FRACTION = 0.05
#: Relative 1-sigma above which a parameter is reported as poorly determined.
POORLY_DETERMINED = 0.2
#: Default number of coarse points for layer 1 (the paper's Remark 4: coarse is enough).
LAYER1_POINTS = 1500


# --------------------------------------------------------------------------- results
@dataclass
class IdentificationResult:
    """What identification found, how well it fits and what it could not determine."""

    model: CreepModel
    fit_percent: float
    elapsed_s: float
    t_c: float
    offset: float = 0.0
    input_offset: float = 0.0
    warnings: list[str] = field(default_factory=list)
    stages: dict[str, dict] = field(default_factory=dict)
    uncertainty: dict[str, float] = field(default_factory=dict)
    noise_std: float = float("nan")
    y_hat: np.ndarray | None = field(default=None, repr=False)
    #: The fitted free response of the state the record started in (None: it started at rest).
    initial_response: FreeResponse | None = field(default=None, repr=False)

    def simulate(self, t: np.ndarray, u: np.ndarray, initial: str = "fitted") -> np.ndarray:
        """The fitted model's output for input u at times t, in the fit's conventions: ``y_hat`` again on the record.

        offset + b G[u - input_offset] (the plant at rest at ``input_offset`` before t[0]), plus with
        ``initial="fitted"`` the free response of the initial state the fit estimated, as a function of
        t - t[0]; ``initial="zero"`` leaves it out (the plant at rest). Any time vector (non-uniform too).
        """
        if initial not in ("fitted", "zero"):
            raise DataError(f"initial must be 'fitted' or 'zero', got {initial!r}")
        t = np.asarray(t, dtype=float)
        y = self.fitted_model().simulate(t, np.asarray(u, dtype=float))
        if initial == "fitted" and self.initial_response is not None:
            y = y + self.initial_response(t - t[0])
        return y

    def fitted_model(self, **provenance) -> FittedModel:
        """This result as a ``FittedModel`` (what ``save_model`` writes); ``provenance`` adds to its ``fitted``."""
        fitted = {"command": "identify", "fit_percent": self.fit_percent,
                  "initial_state_estimated": self.initial_response is not None, **provenance}
        return FittedModel(ExtendedModel(self.model, {}, self.offset), input_offset=self.input_offset,
                           initial_state="free_response", fitted=fitted)

    def to_dict(self) -> dict:
        """JSON-ready summary: the stable keys first (the ``identify --json`` keys, tests/test_cli.py)."""
        m = self.model
        return {
            "alpha": m.alpha, "a1": m.a1, "a2": m.a2, "b": m.b,
            "fit_percent": self.fit_percent, "elapsed_s": self.elapsed_s,
            "fn_hz": m.fn, "zeta": m.zeta, "t_c": self.t_c, "offset": self.offset,
            "input_offset": self.input_offset,
            "noise_std": self.noise_std, "uncertainty": self.uncertainty,
            "warnings": list(self.warnings), "stages": self.stages,
        }


# --------------------------------------------------------------------------- input analysis
@dataclass
class InputSchedule:
    """Where the input changes and how long each level is held."""

    index: np.ndarray        # sample index of each change
    size: np.ndarray         # size of each change
    since_change: np.ndarray  # time since the last change at every sample (NaN before the first)
    hold_start: np.ndarray   # start index of each hold (one per change)
    hold_stop: np.ndarray    # stop index (exclusive)
    piecewise: bool          # few changes: the layered scheme applies


def input_schedule(t: np.ndarray, u: np.ndarray) -> InputSchedule:
    """Find the input changes (u[-1] taken as 0) and the holds between them."""
    du = increments(u)
    scale = max(float(np.max(np.abs(u))), 1e-300)
    idx = np.flatnonzero(np.abs(du) > 1e-12 * scale)
    n = t.size
    since = np.full(n, np.nan)  # before the first change: neither transient nor creep
    stops = np.append(idx[1:], n)
    for i0, i1 in zip(idx, stops):
        since[i0:i1] = t[i0:i1] - t[i0]
    piecewise = idx.size <= max(4, MAX_STEP_FRACTION * n)
    return InputSchedule(idx, du[idx], since, idx.copy(), stops, piecewise)


# --------------------------------------------------------------------------- layer 1
def creep_asymptote(tau: np.ndarray, alpha: float, a1: float, a2: float) -> np.ndarray:
    """Unit-step response long after the step: sum_k c_k tau^(alpha-k) / Gamma(1+alpha-k).

    c_0 = 1, c_1 = -a1, c_2 = a1^2 - a2, c_3 = -a1^3 + 2 a1 a2 are the Taylor
    coefficients of 1/(1 + a1 s + a2 s^2); the neglected terms decay
    exponentially. a1 = a2 = 0 gives the pure creep law of the paper's
    double-logarithmic model.
    """
    coef = (1.0, -a1, a1 * a1 - a2, -a1**3 + 2.0 * a1 * a2)
    out = np.zeros_like(tau)
    for k, c in enumerate(coef):
        if c != 0.0:
            out += c * tau ** (alpha - k) * rgamma(1.0 + alpha - k)
    return out


def creep_asymptote_dalpha(tau: np.ndarray, alpha: float, a1: float, a2: float,
                           log_tau: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(``creep_asymptote``, its derivative in alpha): d/d alpha of tau^(alpha-k) / Gamma(1+alpha-k) is the
    term times (ln tau - digamma(1+alpha-k)). ``log_tau``: ln tau, when the caller has it."""
    coef = (1.0, -a1, a1 * a1 - a2, -a1**3 + 2.0 * a1 * a2)
    log_tau = np.log(tau) if log_tau is None else log_tau
    out = np.zeros_like(tau)
    d_out = np.zeros_like(tau)
    for k, c in enumerate(coef):
        if c != 0.0:
            term = c * tau ** (alpha - k) * rgamma(1.0 + alpha - k)
            out += term
            d_out += term * (log_tau - digamma(1.0 + alpha - k))
    return out, d_out


def _coarse_bins(mask: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Group the masked samples into consecutive runs of ``width``: (start, stop) indices."""
    starts, stops = [], []
    runs = np.flatnonzero(np.diff(np.concatenate(([0], mask.view(np.int8), [0]))))
    for r0, r1 in zip(runs[::2], runs[1::2]):
        edges = np.arange(r0, r1 - width + 1, width)
        starts.extend(edges)
        stops.extend(edges + width)
    return np.asarray(starts, dtype=np.int64), np.asarray(stops, dtype=np.int64)


def layer1_alpha(t: np.ndarray, u: np.ndarray, y: np.ndarray, t_c: float, *, a1: float = 0.0,
                 a2: float = 0.0, step: float | None = None, alpha0: float = 0.1,
                 schedule: InputSchedule | None = None) -> tuple[float, float, dict]:
    """Layer 1: (alpha, gain, info) from the creep regime (more than t_c after the last change).

    Samples are averaged over bins of ``step`` seconds (default: about
    LAYER1_POINTS bins), the model is evaluated at the bin centres, the gain is
    projected out and alpha found by Levenberg-Marquardt with the analytic
    derivative (one parameter: scipy's TRF wrapper cost more than the model).
    """
    sched = schedule or input_schedule(t, u)
    h = float(t[1] - t[0])
    mask = sched.since_change > t_c
    if mask.sum() < 4:
        raise IdentificationError(f"no creep regime: fewer than 4 samples lie more than t_c={t_c:.3g} s after an input change")
    if step is None:
        step = max(h, mask.sum() * h / LAYER1_POINTS)
    width = max(1, int(round(step / h)))
    b0, b1 = _coarse_bins(mask, width)
    if b0.size < 3:
        raise IdentificationError("creep regime too short for layer 1 at this coarse step")
    csum = np.concatenate(([0.0], np.cumsum(y)))
    y_bin = (csum[b1] - csum[b0]) / width
    t_mid = 0.5 * (t[b0] + t[b1 - 1])
    active = sched.index[np.searchsorted(sched.index, b0, side="right") - 1]
    # responses of all changes up to each bin's own last change
    tau = t_mid[:, None] - t[sched.index][None, :]
    live = sched.index[None, :] <= active[:, None]
    tau_live = np.where(live, tau, 1.0)
    sizes = np.where(live, sched.size[None, :], 0.0)

    log_tau = np.log(tau_live)

    def evaluate(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        value, d_value = creep_asymptote_dalpha(tau_live, p[0], a1, a2, log_tau)
        phi, d_phi = np.sum(sizes * value, axis=1), np.sum(sizes * d_value, axis=1)
        gain, r = _projected(y_bin, phi)
        jac = _projected_jacobian(phi, d_phi[None, :], r, gain, False)
        return r, jac @ jac.T, jac @ r, gain

    start = time.perf_counter()
    p0 = np.array([min(max(alpha0, ALPHA_BOUNDS[0] * 2), 0.9)])
    x, _, gain, nfev = _levenberg_marquardt(evaluate, p0, np.array([ALPHA_BOUNDS[0]]),
                                            np.array([ALPHA_BOUNDS[1]]), LAYER1_MAX_ITER)
    alpha = float(x[0])
    info = {"alpha": alpha, "gain": gain, "points": int(b0.size), "step_s": width * h,
            "nfev": nfev, "elapsed_s": time.perf_counter() - start}
    return alpha, gain, info


#: Levenberg-Marquardt iterations of layer 1 (one parameter, an analytic derivative).
LAYER1_MAX_ITER = 50


def retune_alpha(alpha0: float, y: np.ndarray, y_hat: np.ndarray, i_c: int, i_f: int, half: int) -> float:
    """Eq. 12: alpha = alpha0 (y*_f - y*_c) / (y_hat_f - y_hat_c), with window averages against noise."""
    def avg(v: np.ndarray, i: int) -> float:
        return float(np.mean(v[max(i - half, 0):i + half + 1]))
    den = avg(y_hat, i_f) - avg(y_hat, i_c)
    if den == 0.0:
        return alpha0
    return alpha0 * (avg(y, i_f) - avg(y, i_c)) / den


# --------------------------------------------------------------------------- layer 2
def _projected(y: np.ndarray, s: np.ndarray) -> tuple[float, np.ndarray]:
    """Best gain for y ~ b s and the residual (variable projection)."""
    den = float(s @ s)
    b = float(s @ y) / den if den > 0 else 0.0
    return b, y - b * s


def _projected_affine(y: np.ndarray, s: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Best (b, c) for y ~ b s + c and the residual: the gain and a free output offset."""
    ms, my = float(s.mean()), float(y.mean())
    sc = s - ms
    den = float(sc @ sc)
    b = float(sc @ (y - my)) / den if den > 0 else 0.0
    c = my - b * ms
    return b, c, y - b * s - c


def _projected_jacobian(s: np.ndarray, ds: np.ndarray, r: np.ndarray, b: float, free_offset: bool) -> np.ndarray:
    """Exact Jacobian (rows: parameters) of the projected residual r(p) = y - C beta(p), C = [s(p)] or [s(p), 1].

    Golub-Pereyra: with ds = ds/dp (rows) and the projected gain b, dr/dp_k =
    -b ds_k + C (C'C)^-1 (b C' ds_k - e_s (ds_k . r)), e_s picking the gain:
    the Jacobian that finite differences of the projected residual approximate,
    from the shape's own derivatives.
    """
    rd = ds @ r
    if free_offset:
        total = float(s.sum())
        gram = np.array([[float(s @ s), total], [total, float(s.size)]])
        rhs = b * np.vstack((ds @ s, ds.sum(axis=1)))
        rhs[0] -= rd
        try:
            coef = np.linalg.solve(gram, rhs)
        except np.linalg.LinAlgError:
            coef = np.zeros_like(rhs)
        return coef[0][:, None] * s + (coef[1][:, None] - b * ds)
    ss = float(s @ s)
    coef = (b * (ds @ s) - rd) / ss if ss > 0 else np.zeros(ds.shape[0])
    return coef[:, None] * s - b * ds


def model_output(alpha: float, a1: float, a2: float, h: float, u: np.ndarray, n: int | None = None) -> np.ndarray:
    """Unit-gain exact response to the ZOH input u (first n samples)."""
    n = u.size if n is None else n
    s = step_response_grid(alpha, a1, a2, h, n)
    return superpose(s, u[:n])


def model_output_sensitivity(alpha: float, a1: float, a2: float, h: float, u: np.ndarray,
                             n: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``model_output`` and its derivatives in (alpha, ln a1, ln a2): (s, ds of shape (3, n), step).

    The step response's forward sensitivities superposed like the response
    itself (superposition is linear): one march instead of one simulation
    per finite-difference column. s equals ``model_output`` bit for bit;
    ``step`` is the unit-step response at n + 1 instants (for the timing check).
    """
    n = u.size if n is None else n
    rows = step_response_sensitivity(alpha, a1, a2, h, n + 1)
    out = superpose_rows(rows, u[:n])
    out[2] *= a1
    out[3] *= a2
    return out[0], out[1:], rows[0]


#: Longest first transient (samples) the starting grid scores: 4096 samples resolve 2 periods of
#: fs/2048; slower resonances are found by the global fallback's grid.
GRID_WINDOW = 4096
#: The (fn, zeta) starting grid: 28 log-spaced frequencies x the damping ratios ``GRID_ZETAS`` (those of
#: the global fit's starting grid, ``global_fit.py``).


def resonance_grid(t: np.ndarray, u: np.ndarray, y: np.ndarray, alpha: float, stop: int,
                   f_lo: float, f_hi: float) -> tuple[float, float]:
    """Starting (fn, zeta) from a grid on samples [0, stop), using the cheap split form.

    All grid points' FOH matrices come from one vectorised closed form and one
    numba pass scores them (gain projected out).
    """
    h = float(t[1] - t[0])
    z = fractional_integral(u[:stop], h, alpha)
    fn, zeta = np.meshgrid(np.geomspace(f_lo, f_hi, 28), GRID_ZETAS, indexing="ij")
    fn, zeta = fn.ravel(), zeta.ravel()
    wn = 2 * np.pi * fn
    phi, g0, g1 = foh_matrices_batch(2 * zeta / wn, 1 / wn**2, h)
    costs = kernels.foh_grid_costs(z, np.ascontiguousarray(y[:stop]), phi, g0, g1, h)
    k = int(np.argmin(costs))
    return float(fn[k]), float(zeta[k])


def layer2_resonance(t: np.ndarray, u: np.ndarray, y: np.ndarray, alpha: float, mask: np.ndarray,
                     a1: float, a2: float) -> tuple[float, float, float, dict]:
    """Layer 2: (a1, a2, b, info) with alpha fixed, on the masked samples at the full rate.

    Parameters are log(a1), log(a2); b is projected out. The exact simulator
    runs up to the last masked sample; each evaluation also returns the
    analytic Jacobian (forward sensitivities), so no finite-difference
    simulations. The trust-region solver is scipy's TRF iteration without its
    wrappers (``trf_small.trf``, the same steps up to round-off).
    """
    h = float(t[1] - t[0])
    n = int(np.flatnonzero(mask)[-1]) + 1
    m = mask[:n]
    ym = y[:n][m]
    last: dict = {}

    def evaluate(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = (float(p[0]), float(p[1]))
        if last.get("key") != key:
            s, ds, _ = model_output_sensitivity(alpha, math.exp(p[0]), math.exp(p[1]), h, u, n)
            s, ds = s[m], ds[1:, m]
            b, r = _projected(ym, s)
            last.update(key=key, r=r, jac=_projected_jacobian(s, ds, r, b, False).T, b=b)
        return last["r"], last["jac"]

    start = time.perf_counter()
    lo = [math.log(a1) - 12, math.log(a2) - 12]
    hi = [math.log(a1) + 12, math.log(a2) + 12]
    x, nfev, _ = trf(evaluate, [math.log(a1), math.log(a2)], lo, hi)
    a1f, a2f = math.exp(x[0]), math.exp(x[1])
    evaluate(x)
    info = {"a1": a1f, "a2": a2f, "b": last["b"], "samples": int(m.sum()), "nfev": nfev,
            "elapsed_s": time.perf_counter() - start}
    return a1f, a2f, last["b"], info


# --------------------------------------------------------------------------- polish
def joint_polish(t: np.ndarray, u: np.ndarray, y: np.ndarray, model: CreepModel,
                 free_offset: bool = False) -> tuple[CreepModel, dict]:
    """All four parameters on the whole record (b, and the offset if free, projected out), warm-started.

    Parameters alpha, ln a1, ln a2; Levenberg-Marquardt with the analytic
    Jacobian of the projected residual. Returns the polished model and an
    info dict with the parameter std, ``shape``, the polished model's
    unit-gain output (its last simulation), and ``step``, its unit-step
    response at n + 1 instants.
    """
    h = float(t[1] - t[0])

    def evaluate(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
        s, ds, step = model_output_sensitivity(p[0], math.exp(p[1]), math.exp(p[2]), h, u)
        if free_offset:
            b, c, r = _projected_affine(y, s)
        else:
            (b, r), c = _projected(y, s), 0.0
        a, g = kernels.projected_normal_equations(s, ds, r, b, free_offset)
        return r, a, g, (s, ds, b, c, step)

    start = time.perf_counter()
    p0 = np.array([model.alpha, math.log(model.a1), math.log(model.a2)])
    lo = np.array([ALPHA_BOUNDS[0], p0[1] - 5, p0[2] - 5])
    hi = np.array([ALPHA_BOUNDS[1], p0[1] + 5, p0[2] + 5])
    x, r, (s, ds, b, c, step), nfev = _levenberg_marquardt(evaluate, p0, lo, hi)
    polished = CreepModel(float(x[0]), math.exp(x[1]), math.exp(x[2]), b)
    info = {"nfev": nfev, "elapsed_s": time.perf_counter() - start, "offset": c,
            "uncertainty": _covariance_sd(ds, s, r, polished, free_offset), "shape": s, "step": step}
    return polished, info


#: Iterations of the Levenberg-Marquardt fits (the polish starts close: a few do).
POLISH_MAX_ITER = 30


def _levenberg_marquardt(evaluate, p0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                         max_iter: int = POLISH_MAX_ITER) -> tuple[np.ndarray, np.ndarray, object, int]:
    """Levenberg-Marquardt bounded by clipping: (x, r(x), payload(x), evaluations).

    ``evaluate(x)`` returns (residual r, J J', J r, payload) with J the
    Jacobian (one row per parameter); the Jacobian comes with every
    evaluation (forward sensitivities), so an accepted step needs no further
    simulation. Stops when the Gauss-Newton step from x would move the
    parameters by less than ``CONVERGED_SIGMAS`` of their standard deviations
    (then x is the minimum for every purpose and the step is not simulated),
    when a step moves them by less than 1e-10 (relative) or lowers the cost
    by less than 1e-12 (relative), or when no damping lowers it.

    Replaces scipy's least_squares: few parameters and a start already close,
    so a few steps do; scipy's wrapper cost about as much as the simulations.
    """
    x = np.clip(p0, lo, hi)
    r, a, g, payload = evaluate(x)
    cost, lam, nfev = float(r @ r), 0.0, 1
    for _ in range(max_iter):
        if _converged(a, g, cost, r.size):
            break
        d = np.maximum(np.diag(a), 1e-300)
        while True:
            try:
                dx = -np.linalg.solve(a + lam * np.diag(d), g)
            except np.linalg.LinAlgError:
                dx = np.zeros_like(x)
            xn = np.clip(x + dx, lo, hi)
            rn, an, gn, pn = evaluate(xn)
            nfev += 1
            cn = float(rn @ rn)
            if cn <= cost or lam > 1e10:
                break
            lam = max(10.0 * lam, 1e-4)
        if cn > cost:
            break
        moved = float(np.max(np.abs(xn - x) / np.maximum(1.0, np.abs(x))))
        decrease = (cost - cn) / max(cost, 1e-300)
        x, r, a, g, payload, cost, lam = xn, rn, an, gn, pn, cn, lam / 10.0
        if moved < 1e-10 or decrease < 1e-12:
            break
    return x, r, payload, nfev


#: The polish stops when its next Gauss-Newton step is below this many standard deviations (Mahalanobis).
CONVERGED_SIGMAS = 1e-3


def _converged(a: np.ndarray, g: np.ndarray, cost: float, m: int) -> bool:
    """Whether the Gauss-Newton step -a^-1 g is below CONVERGED_SIGMAS standard deviations.

    The step's squared length in the covariance's metric sigma^2 a^-1 is
    g' a^-1 g / sigma^2, with sigma^2 = cost / (m - p) the residual variance.
    """
    try:
        step2 = float(g @ np.linalg.solve(a, g))
    except np.linalg.LinAlgError:
        return False
    sigma2 = cost / max(m - g.size, 1)
    return math.isfinite(step2) and step2 <= CONVERGED_SIGMAS**2 * sigma2


def _covariance_sd(jac_s: np.ndarray, s: np.ndarray, r: np.ndarray, m: CreepModel,
                   free_offset: bool) -> dict[str, float]:
    """1-sigma of (alpha, a1, a2, b) from the Gauss-Newton covariance of the full model b s(p) (+ c).

    ``jac_s``: ds/d(alpha, ln a1, ln a2), one row per parameter.
    """
    rows = [m.b * jac_s, s[None, :]] + ([np.ones((1, s.size))] if free_offset else [])
    jac = np.vstack(rows)
    sigma2 = float(r @ r) / max(r.size - jac.shape[0], 1)
    try:
        cov = sigma2 * np.linalg.inv(jac @ jac.T)
    except np.linalg.LinAlgError:
        return {k: float("inf") for k in ("alpha", "a1", "a2", "b")}
    sd = np.sqrt(np.abs(np.diag(cov)))
    return {"alpha": float(sd[0]), "a1": float(sd[1] * m.a1), "a2": float(sd[2] * m.a2), "b": float(sd[3])}


# --------------------------------------------------------------------------- driver
#: Fewest samples before the first input change from which an output offset is estimated.
MIN_OFFSET_SAMPLES = 100


def _pre_step_samples(sched: InputSchedule) -> int:
    return int(sched.index[0]) if sched.index.size else 0


def _offset(y: np.ndarray, sched: InputSchedule) -> float:
    """Starting output offset: the mean before the first input change, or 0 when fewer than
    MIN_OFFSET_SAMPLES precede it.

    With enough pre-step samples the polish then fits the offset jointly with
    the model (the pre-step mean alone carries noise that biased alpha by
    0.8 %, 36 standard deviations, on a 10 kHz record with 100 such samples).
    With fewer, creep with a small alpha and a constant are nearly collinear,
    so the offset is taken as zero.
    """
    first = _pre_step_samples(sched)
    return float(np.mean(y[:first])) if first >= MIN_OFFSET_SAMPLES else 0.0


@single_threaded
def identify(t: np.ndarray, u: np.ndarray, y: np.ndarray, *, t_c: float | None = None,
             alpha0: float | None = None, resonance0: tuple[float, float] | None = None,
             layer1_step: float | None = None, retune: bool = True, polish: bool = True,
             offset: float | None = None, source: str = "<array>") -> IdentificationResult:
    """Identify (alpha, a1, a2, b) from a uniformly sampled record, at rest or taken in operation.

    ``t_c`` (end of the transient, s), ``alpha0`` and ``resonance0`` =
    (fn_hz, zeta) override the data-driven choices; ``offset`` is the output
    level at rest (default: fitted jointly when at least MIN_OFFSET_SAMPLES
    precede the first input change, else 0). ``polish`` runs the joint
    4-parameter refinement and, when the fit misses the noise floor, the global
    fit (which also estimates the initial state of a record that starts with
    the plant moving). Warnings say what the data cannot determine.
    """
    start = time.perf_counter()
    check_options(t_c=t_c, alpha0=alpha0, resonance0=resonance0, layer1_step=layer1_step, offset=offset)
    rec = Record(t, u, y, source).validate()
    try:
        h = uniform_step(rec.t)
    except DataError as exc:
        raise DataError(f"{source}: {exc} (identify simulates on a uniform grid; "
                        "'creep-online diagnose' fits non-uniform records)") from None
    check_ranges(rec, h)
    span = rec.duration
    if layer1_step is not None and not layer1_step < span:
        raise DataError(f"{source}: layer1_step ({layer1_step:g} s) must be shorter than the record ({span:g} s)")
    if t_c is not None and not t_c < span:
        raise DataError(f"{source}: t_c ({t_c:g} s) must lie inside the record ({span:g} s)")
    su, sy = amplitude_scales(rec.u, rec.y)
    if su != 1.0 or sy != 1.0:
        scaled = _identify_scaled(rec, su, sy, t_c=t_c, alpha0=alpha0, resonance0=resonance0,
                                  layer1_step=layer1_step, retune=retune, polish=polish, offset=offset)
        scaled.elapsed_s = time.perf_counter() - start
        return scaled
    t = rec.t - rec.t[0]
    u, y_raw = rec.u, rec.y
    sched = input_schedule(t, u)
    free_offset = offset is None and _pre_step_samples(sched) >= MIN_OFFSET_SAMPLES
    user_offset = offset
    offset = _offset(y_raw, sched) if offset is None else float(offset)
    y = y_raw - offset
    warnings: list[str] = []
    stages: dict[str, dict] = {}
    noise = noise_std_estimate(y)

    u0 = 0.0
    if sched.piecewise:
        model, t_c = _layered(t, u, y, h, sched, t_c, alpha0, resonance0, layer1_step, retune, stages)
    else:
        # a record taken in operation: deviations from its first input level, output offset fitted
        u0 = float(u[0])
        u = u - u0
        model, t_c = _general_start(t, u, y, h, alpha0, resonance0, stages)
        warnings.append("input is not piecewise constant (changes at most samples): "
                        "layers skipped, joint fit only, output offset fitted")
        polish = True
    uncertainty: dict[str, float] = {}
    if polish:
        model, info = joint_polish(t, u, y, model, free_offset=free_offset or not sched.piecewise)
        uncertainty = info.pop("uncertainty")
        y_hat = model.b * info.pop("shape")        # the polish's last simulation is the final model's
        step = model.b * info.pop("step")
        offset += info["offset"]
        y = y - info["offset"]
        stages["polish"] = {**info, **model.params()}
    else:
        y_hat = model.b * model_output(model.alpha, model.a1, model.a2, h, u)
    residual = y - y_hat
    found = None
    initial_response = None
    final_noise = noise_std_estimate(residual)
    if polish and not at_floor(residual, final_noise):
        found = _escalate(rec.u, y_raw, h, model, residual, user_offset, stages)
        if found is not None:
            model, uncertainty = found.model, global_uncertainty(found)
            offset, u0 = (user_offset or 0.0) + found.offset, float(rec.u[0]) if found.problem.init else 0.0
            u, y = rec.u - u0, y_raw - offset
            y_hat = found.y_hat - found.offset
            residual = y - y_hat
            final_noise = noise_std_estimate(residual)
            if found.problem.init:
                initial_response = FreeResponse.from_weights(model.alpha, model.a1, model.a2, h, u.size,
                                                             found.coef[1 + int(found.problem.offset):])
                warnings.append("the record starts in operation (the plant moves at the first sample): its initial "
                                f"state was estimated with {found.problem.linear_count - 1 - int(found.problem.offset)} "
                                "free-response terms (past steps, resonance modes)")
    inflate = math.sqrt(long_run_variance_factor(residual))
    uncertainty = {k: sd * inflate for k, sd in uncertainty.items()}
    if inflate > 1.0:
        stages["uncertainty_inflation"] = {"factor": inflate}
    ratio = floor_ratio(residual, final_noise)
    if polish and found is None:               # the polished model is final: its step response is at hand
        timing = check_timing(step, *input_changes(u), residual, final_noise) if sched.piecewise else None
    else:
        timing = _timing(model, h, u, residual, sched, final_noise) if polish else None
    if timing is not None:
        stages["timing"] = {"excess_sigmas": timing.excess_sigmas, "flagged": timing.flagged,
                            "median_shift_samples": float(np.nanmedian(timing.shift))}
        if timing.flagged:
            warnings.append(timing.describe())
    if polish and ratio > FLOOR_WARNING:
        warnings.append(_floor_warning(ratio, residual, y))
    warnings += _identifiability(t, u, y, h, model, t_c, sched, noise)
    warnings += [f"{k} is poorly determined by these data (1-sigma {sd / abs(getattr(model, k)):.0%})"
                 for k, sd in uncertainty.items() if sd > POORLY_DETERMINED * abs(getattr(model, k))]
    return IdentificationResult(
        model=model, fit_percent=fit_percent(y, y_hat), elapsed_s=time.perf_counter() - start,
        t_c=t_c, offset=offset, input_offset=u0, warnings=warnings, stages=stages,
        uncertainty=uncertainty, noise_std=noise, y_hat=y_hat + offset, initial_response=initial_response)


def _floor_warning(ratio: float, residual: np.ndarray, y: np.ndarray) -> str:
    """The warning for a fit above the noise floor; a noise-free record (most of the residual exactly 0, so
    its white-noise level is 0) has no floor to be measured against, and says so instead of a ratio."""
    if math.isfinite(ratio):
        return (f"the fit does not reach the noise floor (residual rms {ratio:.2f} x its white-noise level): "
                "the data hold something the model does not (another effect, coloured noise, timing)")
    spread = float(np.std(y))
    share = f" ({rms(residual) / spread:.2g} of the output's spread)" if spread > 0 else ""
    return (f"the record is noise-free (its residual has no white noise), so the fit cannot be judged against a "
            f"noise floor: residual rms {rms(residual):.3g}{share}")


def _timing(model: CreepModel, h: float, u: np.ndarray, residual: np.ndarray,
            sched: InputSchedule, noise: float) -> TimingCheck | None:
    """The sub-sample timing test of the input changes (piecewise-constant inputs only)."""
    if not sched.piecewise:
        return None
    idx, size = input_changes(u)
    step = model.b * step_response_grid(model.alpha, model.a1, model.a2, h, u.size + 1)
    return check_timing(step, idx, size, residual, noise)


#: Residual rms above this multiple of its white-noise level after all starts: warn.
FLOOR_WARNING = 1.1


#: Fewest samples before the first input change that can show the plant at rest.
REST_SAMPLES = 20


def starts_at_rest(y: np.ndarray, sched: InputSchedule) -> bool:
    """Whether the output is constant up to noise before the first input change (then no free
    initial-state terms are tried: a record from rest does not need them)."""
    first = _pre_step_samples(sched)
    if first < REST_SAMPLES:
        return False
    head = y[:first] - np.mean(y[:first])
    return at_floor(head)


def _escalate(u: np.ndarray, y_raw: np.ndarray, h: float, model: CreepModel, fast_residual: np.ndarray,
              user_offset: float | None, stages: dict) -> GlobalFit | None:
    """The global multi-start fit, warm-started from the layers; its result if it beats theirs (BIC)."""
    start = time.perf_counter()
    y = y_raw if user_offset is None else y_raw - user_offset
    try:
        found = global_fit(u, y, h, warm=[model], offset_free=user_offset is None,
                           try_init=not starts_at_rest(y, input_schedule(np.arange(u.size) * h, u)))
    except ValueError:
        return None
    fast_bic = n_bic(fast_residual, 3 + 1 + int(user_offset is None))
    better = found.bic < fast_bic
    stages["global"] = {"elapsed_s": time.perf_counter() - start, "initial_state": found.problem.init,
                        "starts": len(found.info["tried"]), "floor_ratio": floor_ratio(found.residual),
                        "kept": bool(better), **found.model.params()}
    return found if better else None


def _positive(name: str, value: float | None) -> None:
    if value is not None:
        positive(value, name)


def check_options(*, t_c=None, alpha0=None, resonance0=None, layer1_step=None, offset=None) -> None:
    """DataError naming the first invalid identification setting."""
    _positive("t_c (end of the transient, s)", t_c)
    _positive("layer1_step (s)", layer1_step)
    if alpha0 is not None and not (is_real(alpha0) and 0 < alpha0 < 1):
        raise DataError(f"alpha0 must lie in (0, 1), got {alpha0!r}")
    if resonance0 is not None:
        try:
            fn, zeta = resonance0
        except (TypeError, ValueError):
            raise DataError(f"resonance0 must be (fn_hz, zeta), got {resonance0!r}") from None
        _positive("resonance0 fn_hz", fn)
        _positive("resonance0 zeta", zeta)
    if offset is not None and not (is_real(offset) and math.isfinite(number(offset, "offset"))):
        raise DataError(f"offset must be a finite number, got {offset!r}")


def check_ranges(rec: Record, h: float) -> None:
    """DataError when the time axis or the output cannot be identified at all (with the reason)."""
    check_time_and_output(rec.t, rec.y, rec.source)


def amplitude_scales(u: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Powers of 2 to divide u and y by so that both lie well inside the floating range (1.0 when they do)."""
    def scale(v: np.ndarray) -> float:
        peak = float(np.max(np.abs(v)))
        if peak == 0.0 or SAFE_AMPLITUDE[0] <= peak <= SAFE_AMPLITUDE[1]:
            return 1.0
        return math.ldexp(1.0, math.frexp(peak)[1])
    return scale(u), scale(y)


def _identify_scaled(rec: Record, su: float, sy: float, **kw) -> "IdentificationResult":
    """identify() on u/su, y/sy, with b, offset, y_hat and uncertainties scaled back (or refused)."""
    off = kw.pop("offset")
    res = identify(rec.t, rec.u / su, rec.y / sy, offset=None if off is None else off / sy,
                   source=rec.source, **kw)
    m = res.model
    b = m.b * (sy / su)
    if not (math.isfinite(b) and b != 0.0):
        raise IdentificationError(f"{rec.source}: gain b = {m.b:g} x {sy:g} / {su:g} is outside the floating-point "
                                  f"range: rescale u or y")
    res.model = CreepModel(m.alpha, m.a1, m.a2, b)
    if "b" in res.uncertainty:
        res.uncertainty["b"] *= sy / su
    res.offset *= sy
    res.input_offset *= su
    res.noise_std *= sy
    res.y_hat = res.y_hat * sy
    if res.initial_response is not None:
        res.initial_response = res.initial_response.scaled(sy)
    res.warnings.append(f"u and y were rescaled by 1/{su:g} and 1/{sy:g} for the computation "
                        f"(amplitudes outside {SAFE_AMPLITUDE[0]:g}..{SAFE_AMPLITUDE[1]:g})")
    return res


def _layered(t, u, y, h, sched, t_c, alpha0, resonance0, layer1_step, retune, stages):
    """The paper's two layers with data-driven t_c and starting point."""
    holds = t[np.minimum(sched.hold_stop, t.size - 1)] - t[sched.hold_start]
    longest = float(holds.max())
    first_stop = int(sched.hold_stop[0])
    # 1. a first alpha from the late part of every hold (pure creep law)
    tc0 = t_c if t_c is not None else 0.2 * longest
    if alpha0 is None:
        alpha0, _, info = layer1_alpha(t, u, y, tc0, step=layer1_step, schedule=sched)
        stages["alpha_start"] = info
    # 2. resonance start: grid on the first transient with that alpha
    if resonance0 is None:
        window = int(sched.index[0]) + min(max(int(min(tc0, 0.5 * holds[0]) / h), 8), GRID_WINDOW)
        window = min(window, first_stop)
        f_hi = 0.45 / h
        f_lo = min(max(2.0 / (window * h), 1e-3), f_hi / 4)
        fn0, zeta0 = resonance_grid(t, u, y, alpha0, window, f_lo, f_hi)
    else:
        fn0, zeta0 = resonance0
    start = CreepModel.from_resonance(alpha0, fn0, zeta0)
    stages["start"] = {"alpha": alpha0, "fn_hz": fn0, "zeta": zeta0}
    # 3. t_c from the resonance's settling time (clamped to leave a creep regime)
    auto_tc = t_c is None
    if auto_tc:
        t_c = _settled(start, h, longest)
    # 4. layer 2 with alpha fixed, then layer 1 with the resonance correction, then retune
    transient = sched.since_change <= t_c
    a1, a2, b, info = layer2_resonance(t, u, y, alpha0, transient, start.a1, start.a2)
    stages["layer2"] = info
    if auto_tc:
        t_c = _settled(CreepModel(alpha0, a1, a2, b), h, longest)
        transient = sched.since_change <= t_c
    alpha, _, info = layer1_alpha(t, u, y, t_c, a1=a1, a2=a2, step=layer1_step,
                                  alpha0=alpha0, schedule=sched)
    stages["layer1"] = info
    if retune:
        alpha = _retune(t, u, y, h, sched, t_c, alpha, a1, a2, stages)
    a1, a2, b, info = layer2_resonance(t, u, y, alpha, transient, a1, a2)
    stages["layer2_final"] = info
    return CreepModel(alpha, a1, a2, b), t_c


def _settled(model: CreepModel, h: float, longest: float) -> float:
    """t_c: 1.5 settling times of the resonance, at least 20 samples, at most half the longest hold."""
    return float(np.clip(1.5 * model.settling_time, 20 * h, 0.5 * longest))


def _retune(t, u, y, h, sched, t_c, alpha, a1, a2, stages) -> float:
    """Eq. 12 on the longest hold; kept only if it lowers the creep-regime error."""
    k = int(np.argmax(sched.hold_stop - sched.hold_start))
    i_c = int(sched.hold_start[k] + round(t_c / h))
    i_f = int(sched.hold_stop[k]) - 1
    half = max(1, (i_f - i_c) // 50)
    if i_f - i_c < 4 * half:
        return alpha
    creep = sched.since_change > t_c
    y_creep = y[creep]

    def creep_error(a: float) -> tuple[float, float, np.ndarray]:
        """(error, gain, unit-gain output): the creep regime's samples gathered once per simulation."""
        yh = model_output(a, a1, a2, h, u)
        yh_creep = yh[creep]
        g = float(yh_creep @ y_creep / (yh_creep @ yh_creep))
        r = y_creep - g * yh_creep
        return float(r @ r), g, yh

    err0, g0, yh0 = creep_error(alpha)
    new = float(np.clip(retune_alpha(alpha, y, g0 * yh0, i_c, i_f, half), *ALPHA_BOUNDS))
    err1, _, _ = creep_error(new)
    keep = err1 < err0
    stages["retune"] = {"alpha_before": alpha, "alpha_eq12": new, "kept": bool(keep)}
    return new if keep else alpha


def _general_start(t, u, y, h, alpha0, resonance0, stages):
    """Starting model for inputs that are not piecewise constant: grid over the whole record."""
    alpha0 = 0.1 if alpha0 is None else alpha0
    if resonance0 is None:
        f_hi = 0.45 / h
        fn0, zeta0 = resonance_grid(t, u, y, alpha0, t.size, min(2.0 / t[-1], f_hi / 4), f_hi)
    else:
        fn0, zeta0 = resonance0
    m = CreepModel.from_resonance(alpha0, fn0, zeta0)
    s = model_output(m.alpha, m.a1, m.a2, h, u)
    b, _, _ = _projected_affine(y, s)
    stages["start"] = {"alpha": alpha0, "fn_hz": fn0, "zeta": zeta0}
    return CreepModel(m.alpha, m.a1, m.a2, b if b != 0 else 1.0), float(m.settling_time)


def _identifiability(t, u, y, h, model, t_c, sched, noise) -> list[str]:
    """Plain-language warnings for parameters the data cannot pin down."""
    out = []
    fs = 1.0 / h
    if model.fn > 0.25 * fs:
        out.append(f"resonance at {model.fn:.4g} Hz is above fs/4 = {0.25 * fs:.4g} Hz: "
                   "a1 and a2 are poorly identifiable; sample faster")
    if sched.piecewise:
        creep_span = float(t[-1]) / max(t_c, h)
        if creep_span < 5.0:
            out.append(f"record too short for creep: it spans only {creep_span:.1f} x t_c "
                       f"(t_c = {t_c:.3g} s); alpha is poorly identifiable")
    if np.isfinite(noise) and float(np.std(y)) < 1.5 * noise:
        out.append("no usable excitation: the output varies no more than its noise "
                   f"(std {float(np.std(y)):.3g} vs noise {noise:.3g})")
    return out
