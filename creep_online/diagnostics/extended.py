"""Extended-model fits: the base creep model plus catalogue effects, by variable projection.

Every effect in ``creep_online.effects`` enters the output linearly once its
few *nonlinear* parameters are fixed (a frequency, a delay, a time constant,
an exponent). So each fit is a small ``least_squares`` (trust-region
reflective, bounded) over the nonlinear parameters -- the base model's
(alpha, fn, zeta) plus at most two per effect -- with all gains, weights,
amplitudes and the offset solved in closed form at every evaluation
(variable projection). Starting points: the base fit (warm start) and short
grid searches for each effect's nonlinear parameters.

Every effect-specific step (its parameters and bounds, its design columns,
its starting grid, its reported parameters) is a hook of the effect's module
in ``creep_online.effects`` (the ``Effect`` contract in
``creep_online/effects/base.py``); this module only wires the stages.

Python API: :func:`prepare` a record once, :func:`fit_base`, then
:func:`fit_extended` for any effects (one or several, e.g. two at once);
``ExtendedFit.simulate`` (or ``creep_online.model.ExtendedModel``) simulates the result.
"""
from __future__ import annotations

import math
import threading
import weakref
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.linalg import get_lapack_funcs, qr
from scipy.linalg import lstsq as scipy_lstsq
from scipy.optimize import least_squares

from .. import effects as fx
from ..effects import FitView, InputEffect, ParallelEffect, ParamSpec, Stage, check_effect_names, effect_names, get_effect
from ..discretize import step_response_sensitivity
from ..effects.forward import SNAP_RTOL, snapped_time  # noqa: F401 - SNAP_RTOL: the snapping rule, re-exported
from ..errors import DataError, ModelError
from ..identification import POORLY_DETERMINED
from ..metrics import fit_percent, long_run_variance_factor, noise_std_estimate, rms
from ..model import EXTENDED_FIT_ALPHA_BOUNDS as ALPHA_BOUNDS
from ..model import CreepModel, ExtendedModel, FittedModel, with_effects
from ..record import check_amplitudes, check_time_and_output
from .._threads import single_threaded
from . import spectra
from .pool import ordered_map
from .varpro import projected_jacobian

#: Relative singular-value cut-off of the linear least squares (``_solve``).
RCOND = 1e-10
_GELSY, _GELSY_LWORK = get_lapack_funcs(("gelsy", "gelsy_lwork"), (np.zeros((1, 1)),))
#: Bounds of the base model's damping (alpha's are ``model.EXTENDED_FIT_ALPHA_BOUNDS``).
ZETA_BOUNDS = (1e-3, 20.0)
#: An eigenvalue of the column-normalised J^T J at or below this share of the largest is a direction the record
#: does not determine (``base_uncertainty``): ~1e-6 of the columns' norm, beyond what a 1e-8 polish resolves.
UNDETERMINED_CONDITION = 1e-12
#: The factors fn and zeta are moved by, up and down, to probe the cost's profile (``_profile_open``).
PROFILE_FACTORS = (2.0, 4.0, 8.0)
#: Evaluations allowed per least-squares fit.
MAX_NFEV = 40
#: Extended fits: this many grid starts get a short polish of SHORT_NFEV evaluations first.
SHORT_STARTS = 4
SHORT_NFEV = 8
#: ... and this many priority starts (spectral peaks, swapped modes) too.
PRIORITY_STARTS = 5
#: Broad spectral humps (a damped mode's ringing) ``residual_peaks`` adds to the narrow lines.
HUMPS = 3
#: A short polish stops once a step lowers the cost by less than SHORT_FTOL (relative; xtol SHORT_XTOL): the short
#: polish only ranks the starts for the final one. Replayed on 708 recorded short polishes (22 records) this
#: saves ~26 % of their evaluations (a converged or stalled start's last ones), and the best start kept is
#: within 6e-4 of the cost of the best one then (the final polish takes it from there).
SHORT_FTOL = 1e-3
SHORT_XTOL = 1e-6
#: Long records explore starting points on a prefix of at least EXPLORE_SAMPLES samples that also
#: holds EXPLORE_EXCITATION of the input's total variation (used when it is < 2/3 of the record).
EXPLORE_SAMPLES = 6000
EXPLORE_EXCITATION = 0.3
#: Relative step of the finite differences (the effects' own parameters; every parameter on non-uniform records).
DIFF_STEP = 1e-7
#: Solutions remembered per design (``Design.project``) ...
SOLVED_CACHE = 8
#: Base-path responses remembered per record (parameter sets; ``Prepared.base_path``) ...
BASE_PATH_CACHE = 8
#: Parallel-effect paths remembered per record (``Prepared.parallel_path``) ...
PARALLEL_PATH_CACHE = 16
#: Reported-solution rows remembered per record (``_reported_rows``: one per set of variants) ...
REPORTED_CACHE = 4
#: ... and at most this many bytes in each of those memories (the most recent response or solution always kept).
#: The counts suit the explore window; on a long record one entry of a hysteresis fit (13 rows' responses, or a coupled
#: design's tangent of 27 columns) is 5-11 MB at 50,000 samples, and eight to sixteen of each, per record and per
#: design, held a diagnosis near 1 GB. There a fit's evaluations reuse the last one or two entries (the Jacobian
#: at the point just evaluated); on the 150 V piezo record 24 MB held ~25 MB more at the peak for no evaluation
#: saved, and 12 MB ~40 MB more than 6 MB for 0.4 s of CPU (~60 responses and superposers built again in 10,000).
#: Every remembered value is exact reuse, so the bound changes no result.
CACHE_BYTES = 6 * 2**20
#: Gauss-Newton steps of a coupled design's gain ratios (``Design._coupled_project``), and their relative tolerance.
COUPLING_STEPS = 8
COUPLING_RTOL = 1e-10
#: Relative tolerance (ftol, xtol) of the final polish: RSS to ~1e-7 is ample for the evidence.
FULL_TOL = 1e-7
#: Evaluations of the final polish on the whole record after exploring on a prefix ...
FULL_NFEV = 8
#: ... which stops once a step gains less than FULL_FTOL of the cost (evidence N ln(RSS ratio) to ~N x 1e-5).
FULL_FTOL = 1e-5
#: An extended fit that explains most of the base misfit (residual below RESTART_EXPLAINED of the
#: base's) but stays above RESTART_ABOVE_FLOOR times its own noise estimate is restarted from a grid
#: over the base parameters (alpha, fn, zeta) with the effect's fitted parameters kept: a strong
#: effect pulls the base fit (and so the warm start) into a wrong resonance. (A wrong candidate
#: explains little and is not restarted: the diagnosis pays for the restart only where it can help.)
#: A base fit with a parameter on its bound restarts every extended fit above the floor (``_on_a_bound``).
#: A fit whose resonance lies above the record's Nyquist frequency is restarted whatever its misfit (``_beyond_nyquist``).
#: (1.2 until a fit in a wrong basin at 1.18x its own estimate, 1.20x the true noise, was left: hysteresis + second
#: creep 3-10x seed 47. The single-effect bands' fits end at 0.98-1.06x the noise. 1.1 until hysteresis' basis
#: grew to 24 thresholds: the same pair's wrong basin then ended at 1.075x its own estimate, 1.09x the noise;
#: restarted, 0.988x.)
RESTART_ABOVE_FLOOR = 1.05
#: A fit that reports its uncertainty and determines a1 or a2 only to a relative 1-sigma above this (finite: an
#: undetermined one is reported so) is restarted too, whatever its misfit (``_weakly_determined``): a flat cost there
#: lets another basin lie close. A hysteresis triangle (seed 3) stopped at 1.016x the noise with a1 80 % and a2 40 %
#: off, reported at 7 % and 9 %; restarted, the plant's basin, 161 noise variances lower (a1 5.2 %, a2 2.5 % off).
RESTART_UNCERTAIN = 0.05
RESTART_EXPLAINED = 0.5
#: The restart grid: alpha values and damping values (fn: the record's frequency-response peaks and two defaults).
RESTART_ALPHAS = (0.05, 0.2, 0.4, 0.7, 0.95)
RESTART_ZETAS = (0.03, 0.1, 0.3, 1.0)


# --------------------------------------------------------------------------- prepared data
@dataclass
class Prepared:
    """A record made ready for repeated fits: time, input, output, weights and cached input transforms."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    weights: np.ndarray | None = None
    u_pre: float | None = None
    t_pre: float | None = None
    source: str = "<array>"
    notes: list[str] = field(default_factory=list)
    u_range: float | None = None   # input range (sets the hysteresis thresholds); default from u
    u_scale: float | None = None   # max |u| (scales the polynomial columns); default from u
    _cache: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self.t = np.ascontiguousarray(self.t, dtype=float)
        self.u = np.ascontiguousarray(self.u, dtype=float)
        self.y = np.ascontiguousarray(self.y, dtype=float)
        self.n = self.t.size
        self.uniform = fx.is_uniform(self.t) and (self.t_pre is None or self.t_pre == self.t[0])
        self.h = (self.t[-1] - self.t[0]) / max(self.n - 1, 1) if self.uniform else float(np.min(np.diff(self.t)))
        if self.u_range is None:
            self.u_range = float(np.ptp(self.u))
        if self.u_scale is None:
            self.u_scale = max(float(np.max(np.abs(self.u))), 1e-300)
        self.wy = self.y if self.weights is None else self.y * self.weights

    def explore_data(self) -> "Prepared":
        """A window for cheap exploration: long enough and excited enough; the record itself if not shorter.

        It starts at the record's start, or (record in equilibrium before its
        first input change) shortly before that change: the samples before it
        only carry the offset.
        """
        if "explore" not in self._cache:
            a = 0
            if self.u_pre is None and self.t_pre is None:
                moved = np.flatnonzero(self.u != self.u[0])
                if moved.size:
                    a = max(0, int(moved[0]) - EXPLORE_SAMPLES // 10)
            du = np.abs(np.diff(self.u[a:], prepend=self.u[a] if self.u_pre is None else self.u_pre))
            tv = np.cumsum(du)
            need = int(np.searchsorted(tv, EXPLORE_EXCITATION * tv[-1])) + 1 if tv[-1] > 0 else self.n
            n = max(EXPLORE_SAMPLES, need)
            self._cache["explore"] = self.window(a, a + n) if n < 2 * self.n // 3 else self
        return self._cache["explore"]

    def window(self, a: int, b: int) -> "Prepared":
        """Samples a..b-1 (a > 0 only for records in equilibrium until after a), same input scaling."""
        w = None if self.weights is None else self.weights[a:b]
        return Prepared(self.t[a:b], self.u[a:b], self.y[a:b], w, self.u_pre, self.t_pre, self.source,
                        list(self.notes), self.u_range, self.u_scale)

    def prefix(self, n: int) -> "Prepared":
        """The first n samples, with the same input scaling (a shorter record of the same experiment)."""
        w = None if self.weights is None else self.weights[:n]
        return Prepared(self.t[:n], self.u[:n], self.y[:n], w, self.u_pre, self.t_pre, self.source,
                        list(self.notes), self.u_range, self.u_scale)

    @property
    def fs(self) -> float:
        return 1.0 / self.h

    def superposer(self, inputs: tuple[tuple[InputEffect, str | None], ...] = ()) -> fx.Superposer:
        """The superposer of the input rows: u, then each input effect's rows (built when no live one has them).

        ``inputs``: (input-stage effect, its variant) pairs in registry order;
        () is the plain input. Held weakly: a superposer lives as long as a
        design holds it (``Design.superposer``), so the designs of one fit and
        their copies on other threads share one, and none outlives the last
        design that uses it. On a long record one input effect's variant holds
        its rows and their spectra (15 MB for hysteresis' 13 rows at 50,000
        samples); a fit's designs each use one variant, and a variant no
        design uses any more is freed at once instead of staying in a memory of
        recent ones beside the next variant's.
        """
        key = "+".join(f"{e.name}[{variant}]" for e, variant in inputs) or "u"
        with _CACHE_LOCK:
            live = self._cache.setdefault("superposer", weakref.WeakValueDictionary())
            sup = live.get(key)
        if sup is not None:
            return sup
        x = self.input_rows(inputs, self.u)
        pre = None
        if self.u_pre is not None:
            pre = self.input_rows(inputs, np.array([self.u_pre]), before=True)[:, 0]
        sup = fx.Superposer(self.t, x, x_pre=pre, t_pre=self.t_pre, overwrite_x=True)   # x: built for it
        with _CACHE_LOCK:                        # another thread built the same meanwhile: both use the first one
            return live.setdefault(key, sup)

    def release(self) -> None:
        """Forget the remembered responses (not the exploration window, nor the superposers the live designs
        hold, ``superposer``): the next fit builds what it asks for again. Exact reuse only, so no result changes;
        on a long record they are most of a diagnosis' memory between its stages (a hysteresis fit's responses
        and reported rows, 5-10 MB each at 50,000 samples), and the next stage (the pair search, on a window) does
        not ask for them. The exploration window's own remembered responses go too (the next stage's designs
        explore other parameters)."""
        with _CACHE_LOCK:
            for key in [k for k in self._cache if k not in ("explore", "superposer")]:
                del self._cache[key]
        window = self._cache.get("explore")
        if window is not None and window is not self:
            window.release()

    def base_path(self, inputs: tuple[tuple[InputEffect, str | None], ...], alpha: float, a1: float, a2: float,
                  delay: float) -> np.ndarray:
        """The base model's unit-gain responses to the input rows, delayed (uniform records), read-only.

        Remembered for the last BASE_PATH_CACHE parameter sets: the fits
        evaluate the same base parameters again and again with only an
        effect's own parameters changed (its finite-difference Jacobian
        columns, its starting grids), and this path (the exact simulation,
        the delay's spline, the superposition) is most of an evaluation.
        """
        key = ("+".join(f"{e.name}[{variant}]" for e, variant in inputs) or "u", alpha, a1, a2, delay)
        return _remembered(self._cache.setdefault("base_path", {}), key, BASE_PATH_CACHE, lambda: self.superposer(
            inputs).apply(fx.delayed_grid(self.step_grid(alpha, a1, a2), self.h, delay)))

    def step_grid(self, alpha: float, a1: float, a2: float) -> np.ndarray:
        """The base model's undelayed unit-step response on the grid (uniform records), read-only.

        Remembered for the last BASE_PATH_CACHE parameter sets apart from
        ``base_path``: a delay's grid starts, its Jacobian columns (the
        spline's slope) and a combination's grid vary the delay with the base
        parameters fixed, and each would march the same response again.
        """
        return _remembered(self._cache.setdefault("step_grid", {}), (alpha, a1, a2), BASE_PATH_CACHE,
                           lambda: fx.base_step_grid(alpha, a1, a2, self.h, self.n))

    def parallel_path(self, effect: ParallelEffect, theta: dict[str, float], own: tuple[float, ...], delay: float,
                      tau: np.ndarray | None,
                      inputs: tuple[tuple[InputEffect, str | None], ...] = ()) -> np.ndarray:
        """A parallel effect's unit-gain responses to the input rows, delayed, read-only (shape (rows, n)).

        ``inputs`` () is the plain input (one row); a design with input effects
        (``Design.coupled``) asks for their rows too, since the forward model
        feeds every path, the parallel ones included, the transformed input.
        Remembered like ``base_path``, by the base parameters, the effect's own
        ``own`` and the delay: a fit with two effects varies one effect's
        parameters with the other's fixed (its finite-difference columns, the
        starting grids), and a second mode's step response (complex
        exponentials) costs more than the rest of an evaluation. ``tau``: the
        grid times minus the delay (uniform records), None otherwise.
        """
        rows = "+".join(f"{e.name}[{variant}]" for e, variant in inputs) or "u"
        key = (effect.name, theta["alpha"], theta["log10_fn"], theta["log10_zeta"], own, delay)
        key = key if rows == "u" else key + (rows,)

        def make() -> np.ndarray:
            step = effect.unit_step(theta)
            shifted = (lambda tt: step(tt - delay))
            return self.superposer(inputs).apply(shifted(tau + delay) if tau is not None else shifted)
        return _remembered(self._cache.setdefault("parallel_path", {}), key, PARALLEL_PATH_CACHE, make)

    def base_path_sensitivity(self, inputs: tuple[tuple[InputEffect, str | None], ...], alpha: float, a1: float,
                              a2: float, delay: float) -> np.ndarray:
        """Derivatives of the delayed base step response in (alpha, a1, a2), shape (3, n) (uniform records).

        The exact march's forward sensitivities (one pass, ~2.4 plain marches),
        delayed by the same spline as the path (linear in the response);
        superposed on the input rows (``superposer(inputs).apply`` or
        ``.products``) they are ``base_path``'s derivatives.
        """
        ds = step_response_sensitivity(alpha, a1, a2, self.h, self.n)
        return fx.delayed_grid(ds[1:], self.h, delay)

    def base_path_slope(self, alpha: float, a1: float, a2: float, delay: float) -> np.ndarray:
        """The delayed base step response's derivative in the delay, shape (n,) (uniform records)."""
        return fx.delayed_grid_slope(self.step_grid(alpha, a1, a2), self.h, delay)

    def input_rows(self, inputs: tuple[tuple[InputEffect, str | None], ...], u: np.ndarray,
                   before: bool = False) -> np.ndarray:
        """u and the rows the input effects add (``before``: u is the input before the record)."""
        return np.vstack([u[None, :]] + [e.design_rows(self, u, variant, before) for e, variant in inputs])


#: Guards the remembered responses of every ``Prepared`` (the candidate fits of ``diagnose`` may run on
#: threads, ``diagnostics/pool.py``): held only to look up, insert and evict, never while computing.
_CACHE_LOCK = threading.Lock()


def _remembered(cache: dict, key: tuple, size: int, make: Callable[[], np.ndarray],
                nbytes: Callable[[object], int] = lambda v: v.nbytes, keep: int = 1) -> np.ndarray:
    """``cache[key]``, or ``make()`` remembered (an array: read-only) with the least recently used entries beyond
    ``size`` or ``CACHE_BYTES`` (``nbytes`` of an entry) evicted, but for the ``keep`` most recent ones (0: an
    entry larger than ``CACHE_BYTES`` is not remembered at all).

    Exact reuse only: a remembered array is bit for bit what ``make()`` gives
    again, so hits, misses and evictions (which depend on what other threads
    evaluate meanwhile) never change a result. Two threads missing the same
    key both compute it; the later insert wins, with equal values.
    """
    with _CACHE_LOCK:
        if key in cache:
            value = cache.pop(key)
            cache[key] = value                   # most recently used last
            return value
    value = make()
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    with _CACHE_LOCK:
        cache[key] = value
        _evict(cache, size, nbytes, keep)
    return value


def _evict(cache: dict, size: int, nbytes: Callable[[object], int], keep: int = 1) -> None:
    """Drop the least recently used entries (first in ``cache``) beyond ``size`` entries or ``CACHE_BYTES``
    bytes (``nbytes`` of an entry), keeping the ``keep`` most recent ones."""
    total = sum(nbytes(v) for v in cache.values())
    while len(cache) > keep and (len(cache) > size or total > CACHE_BYTES):
        total -= nbytes(cache.pop(next(iter(cache))))


def prepare(t: np.ndarray, u: np.ndarray, y: np.ndarray, *, source: str = "<array>",
            weights: str | np.ndarray | None = "auto", u_pre: float | None = None,
            t_pre: float | None = None) -> Prepared:
    """Make a record ready for fitting.

    ``u_pre``/``t_pre``: the input before the record and the time it jumped to
    u[0] (default: none -- the record starts in equilibrium at u[0], deviation
    variables). ``weights='auto'`` weights non-uniform (log-spaced) records by
    1/|y| (a relative, log-domain fit) and leaves uniform ones unweighted.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    check_time_and_output(t, y, source)
    check_amplitudes(np.asarray(u, dtype=float), y, source)
    w = None
    notes: list[str] = []
    t, jitter = snapped_time(t)
    if jitter > 0.0:
        h = (t[-1] - t[0]) / (t.size - 1)
        notes.append(f"time stamps jitter by up to {100 * jitter:.2g} % of the step: treated as uniform (h = {h:.6g} s)")
    if isinstance(weights, str):
        if weights != "auto":
            raise DataError(f"weights must be 'auto', None or an array, got {weights!r}")
        if not fx.is_uniform(t):
            floor = 1e-3 * float(np.max(np.abs(y)))
            w = 1.0 / np.maximum(np.abs(y), max(floor, 1e-300))
            notes.append("non-uniform time: residuals weighted by 1/|y| (relative, log-domain fit)")
    elif weights is not None:
        w = np.asarray(weights, dtype=float)
    return Prepared(t, u, y, w, u_pre, t_pre, source, notes)


# --------------------------------------------------------------------------- the design
class Design:
    """Columns of the extended model for given nonlinear parameters, and their projection.

    theta = (alpha, log10 fn, log10 zeta) then each effect's nonlinear
    parameters in the order of ``effects``. Columns: the dynamic paths (the
    base path on the input rows, then one per parallel effect), delayed and
    filtered, then the offset and the additive effects' columns.
    ``variants`` picks an effect's discrete variant (e.g. hysteresis'
    initial state; default: its first). With input effects and parallel
    paths together (``coupled``) every path sees the transformed input, as
    in the forward model, and each parallel path's gain is solved as a ratio
    to the base gain (``_coupled_project``).
    """

    def __init__(self, data: Prepared, effects: tuple[str, ...] = (), harmonics: int = 1,
                 variants: dict[str, str] | None = None) -> None:
        check_effect_names(effects)
        self.data = data
        self.effects = tuple(effects)
        self.harmonics = harmonics
        fmax = 0.5 * data.fs if data.uniform else 1.0 / data.h
        fmin = 1.0 / (data.t[-1] - data.t[0])
        self.specs = [ParamSpec("alpha", *ALPHA_BOUNDS),
                      ParamSpec("log10_fn", math.log10(fmin), math.log10(2.0 * fmax)),
                      ParamSpec("log10_zeta", math.log10(ZETA_BOUNDS[0]), math.log10(ZETA_BOUNDS[1]))]
        owners: list[str] = []
        for e in self.effects:
            more = get_effect(e).nonlinear_params(data)
            self.specs += more
            owners += [e] * len(more)
        self.own = {e: [s.name for s, o in zip(self.specs[3:], owners) if o == e] for e in self.effects}
        self.names = [s.name for s in self.specs]
        self.lo = np.array([s.lo for s in self.specs])
        self.hi = np.array([s.hi for s in self.specs])
        ordered = [get_effect(n) for n in effect_names() if n in self.effects]
        self.stages = {stage: [e for e in ordered if e.stage == stage] for stage in Stage}
        self.variants = {e.name: (variants or {}).get(e.name, e.variants[0] if e.variants else None)
                         for e in ordered}
        self.inputs = tuple((e, self.variants[e.name]) for e in self.stages[Stage.INPUT])
        # input effects and parallel paths: every path sees the transformed input (``_coupled_project``)
        self.coupled = bool(self.inputs and self.stages[Stage.PARALLEL])
        # differentiated exactly: the base parameters, and a delay's when no parallel path (whose own step
        # response would need its time derivative) is delayed with the base path
        delays = [3 + i for i, e in enumerate(owners) if get_effect(e).stage == Stage.DELAY]
        self.exact = [0, 1, 2] + (delays if not self.stages[Stage.PARALLEL] else [])
        # and a parallel path's own parameters when its effect gives the step response's derivatives
        self.parallel_exact = {e.name: self.own_indices(e.name)
                               for e in self.stages[Stage.PARALLEL] if _differentiable(e)}
        self.exact += [k for idx in self.parallel_exact.values() for k in idx]
        self.col_names: list[str] = []
        self.nfev = 0
        self._solved: dict[bytes, tuple] = {}    # theta -> (coefficients, output, weighted residual), recent ones
        self._weighted: tuple[bytes, np.ndarray] | None = None   # (theta, weighted design) of the last evaluation
        self._reported: tuple[bytes, tuple | None] | None = None  # (theta, ``_reported``) of the last one asked
        self._superposer: fx.Superposer | None = None              # held while this design lives (``superposer``)

    def copy(self) -> "Design":
        """The same design with its own (empty) solution cache and evaluation counter (for another thread)."""
        return Design(self.data, self.effects, self.harmonics, self.variants)

    def superposer(self) -> fx.Superposer:
        """The superposer of this design's input rows (``Prepared.superposer``), held for the design's lifetime:
        its evaluations, its Jacobians and the remembered paths built from it all use these rows, and a record
        keeps a superposer only while a design holds it."""
        if self._superposer is None:
            self._superposer = self.data.superposer(self.inputs)
        return self._superposer

    def release(self) -> None:
        """Let go of the superposer and the weighted designs (the last evaluation's, a coupled design's tangents);
        the remembered solutions stay.

        A point the design has evaluated is then answered as before (its
        solution, its reported solution), and a new point gets the superposer
        again (built anew if no other design holds it). A fit's last stages ask
        its designs only for evaluated points, and on a long record these are
        20-26 MB per design beside the next variant's rows (hysteresis, 50,000
        samples).
        """
        self._superposer = None
        self._weighted = None
        self._solved = {key: entry[:3] + (None,) for key, entry in self._solved.items()}

    def explored(self) -> "Design":
        """The same design on the record's exploration window (``Prepared.explore_data``); itself if that window
        is the record."""
        small = self.data.explore_data()
        return self if small is self.data else Design(small, self.effects, self.harmonics, self.variants)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def own_indices(self, effect: str) -> list[int]:
        """Positions in theta of an effect's own parameters."""
        return [self.index(n) for n in self.own[effect]]

    def _base(self, theta: np.ndarray) -> tuple[dict[str, float], float, float, float, float]:
        """(theta by name, alpha, a1, a2, delay): the base model's parameters and the total delay."""
        p = dict(zip(self.names, theta))
        alpha, fn, zeta = p["alpha"], 10 ** p["log10_fn"], 10 ** p["log10_zeta"]
        wn = 2 * math.pi * fn
        a1, a2 = 2 * zeta / wn, 1 / wn**2
        d = 0.0
        for e in self.stages[Stage.DELAY]:
            d = d + e.fitted_delay(p)
        return p, alpha, a1, a2, d

    def _paths(self, theta: np.ndarray) -> tuple[dict[str, float], np.ndarray, list[np.ndarray], np.ndarray]:
        """(theta by name, base path rows, each parallel path's rows, static columns), unfiltered, unweighted.

        The base path's rows are its responses to the input rows (u, then the
        input effects' rows). A parallel path sees the transformed input only in
        a ``coupled`` design (its rows are then responses to the same input
        rows); otherwise it is one row, the response to u. Sets ``col_names``.
        """
        data = self.data
        p, alpha, a1, a2, d = self._base(theta)
        sup = self.superposer()                  # held first: the remembered paths below are built from it
        if data.uniform:
            base = data.base_path(self.inputs, alpha, a1, a2, d)
            tau = sup.grid_tau - d
        else:
            base = sup.apply(lambda tt: fx.base_step_at(alpha, a1, a2, tt - d))
            tau = None
        inputs = self.inputs if self.coupled else ()
        par = [data.parallel_path(e, p, tuple(p[n] for n in self.own[e.name]), d, tau, inputs)
               for e in self.stages[Stage.PARALLEL]]
        names: list[str] = ["b"]
        for e, _ in self.inputs:
            names += e.column_names()
        names += [e.gain_column for e in self.stages[Stage.PARALLEL]]
        static, more_names = self._static_columns(p)
        self.col_names = names + more_names
        return p, base, par, static

    def columns(self, theta: np.ndarray) -> np.ndarray:
        """Design matrix (n, p) of an uncoupled design: dynamic paths (delayed, filtered) then offset and
        additive columns."""
        p, base, par, static = self._paths(theta)
        if not self.stages[Stage.OUTPUT_FILTER]:
            return np.vstack([base, *par, static]).T          # one copy of the rows, not a stack of a stack
        cols = np.vstack([base, *par])
        for e in self.stages[Stage.OUTPUT_FILTER]:
            cols = e.filter_columns(self.data.t, cols, p)
        return np.vstack([cols, static]).T

    def _static_columns(self, p: dict[str, float]) -> tuple[np.ndarray, list[str]]:
        """The offset and the additive effects' columns (k, n), and their names."""
        static = [np.ones(self.data.n)]
        names = ["offset"]
        for e in self.stages[Stage.ADDITIVE]:
            more, more_names = e.output_columns(self.data.t, p, self.harmonics)
            static += more
            names += more_names
        return np.array(static), names

    def _coupled_paths(self, theta: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
        """(base path rows, each parallel path's rows, static columns), filtered, unweighted (``coupled``).

        Both dynamic groups are responses to the same input rows (u, then the
        input effects' rows): the parallel paths too see the transformed input.
        """
        p, base, par, static = self._paths(theta)
        for e in self.stages[Stage.OUTPUT_FILTER]:
            base = e.filter_columns(self.data.t, base, p)
            par = [e.filter_columns(self.data.t, q, p) for q in par]
        return base, par, static

    def project(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(coefficients, model output, weighted residual) with the linear parameters solved exactly (read-only).

        The last SOLVED_CACHE solutions are remembered: the fits ask again for
        points they have evaluated (a polish's start and end, the ranking of
        polished starts, the result), ~20 % of all requests.
        """
        key = np.asarray(theta, dtype=float).tobytes()
        if key in self._solved:
            self._solved[key] = self._solved.pop(key)      # most recently used last
            return self._solved[key][:3]
        self.nfev += 1
        data = self.data
        if self.coupled:
            coef, y_hat, wres, wphi = self._coupled_project(theta)
        else:
            phi = self.columns(theta)
            wphi = phi if data.weights is None else phi * data.weights[:, None]
            coef = _solve(wphi, data.wy)
            y_hat = phi @ coef
            wres = data.wy - wphi @ coef
        for a in (coef, y_hat, wres):
            a.setflags(write=False)
        self._weighted = (key, wphi[0] if self.coupled else wphi)
        self._solved[key] = (coef, y_hat, wres, wphi if self.coupled else None)
        _evict(self._solved, SOLVED_CACHE, _solution_bytes)
        return coef, y_hat, wres

    def _coupled_project(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
        """(coefficients, output, weighted residual, (weighted tangent design, curvature)) of the coupled model.

        With input effects the forward model (``effects.simulate_with_effects``)
        feeds every path the transformed input v = sum_i (c_i / c_0) x_i (x: the
        input rows, c: the base path's coefficients, c_0 = b), so a parallel
        path of gain g adds g P(v) = kappa sum_i c_i P_i with kappa = g / b: for
        a fixed kappa the model is linear in c (columns B_i + kappa P_i). kappa
        (one per parallel path) is found by Gauss-Newton on the joint problem,
        each step one least squares with the model's derivatives in kappa,
        K = sum_i c_i P_i, beside the columns; it starts from the uncoupled
        solution (each path on the plain input, its gain free). Fitting each
        path on the plain input instead left a pair of hysteresis and a second
        creep at 1.5-3x the noise from the true parameters, and the fitted
        model simulated to ~500x the noise off its own fit. Every column is a
        combination of the rows B, P, static, so one QR of those rows turns
        each least squares into a small one (rows x columns of R). The
        coefficients are reported in the uncoupled layout (the path's gain
        g = kappa b), so every effect reads its parameters as before; the
        tangent design (B_i + kappa P_i, K, static) is what the exact Jacobian
        projects on, with the inner problem's curvature (d tangent / d(c, kappa))^T r.
        """
        base, par, static = self._coupled_paths(theta)
        rows, npar, w = base.shape[0], len(par), self.data.weights
        basis = np.vstack([base, *par, static])                 # rows B, P_1, ..., P_J, static
        wbasis = basis if w is None else basis * w
        r, qy = _triangular(wbasis, self.data.wy)
        m, nstat = basis.shape[0], static.shape[0]
        tail = np.zeros((m, nstat))
        tail[m - nstat:] = np.eye(nstat)

        def paths(kappa: np.ndarray) -> np.ndarray:
            """Combinations of the basis rows giving the columns B_i + kappa . P_i."""
            out = np.zeros((m, rows))
            out[:rows] = np.eye(rows)
            for j in range(npar):
                out[rows * (1 + j):rows * (2 + j)] = kappa[j] * np.eye(rows)
            return out

        def slopes(c: np.ndarray) -> np.ndarray:
            """Combinations giving K_j = sum_i c_i P_ji (the model's derivatives in kappa)."""
            out = np.zeros((m, npar))
            for j in range(npar):
                out[rows * (1 + j):rows * (2 + j), j] = c
            return out

        free = np.zeros((m, npar))
        free[rows * (1 + np.arange(npar)), np.arange(npar)] = 1.0      # each path on the plain input, gain free
        first = _solve(r @ np.hstack([paths(np.zeros(npar)), free, tail]), qy)
        start = first[rows:rows + npar] / first[0] if first[0] != 0.0 else np.zeros(npar)
        start = np.where(np.isfinite(start), start, 0.0)
        kappa, c = start, first[:rows]
        for _ in range(COUPLING_STEPS):
            sol = _solve(r @ np.hstack([paths(kappa), slopes(c), tail]), qy)
            step, c = sol[rows:rows + npar], sol[:rows]
            if not np.all(np.isfinite(step)):
                break
            kappa = kappa + step
            if np.all(np.abs(step) <= COUPLING_RTOL * np.maximum(np.abs(kappa), 1e-300)):
                break
        best = None
        for kap in (kappa, start):                             # the uncoupled start as a safeguard
            combo = np.hstack([paths(kap), tail])
            sol = _solve(r @ combo, qy)
            wres = self.data.wy - wbasis.T @ (combo @ sol)
            if best is None or wres @ wres < best[0]:
                best = (float(wres @ wres), kap, combo, sol, wres)
        _, kappa, combo, sol, wres = best
        c = sol[:rows]
        coef = np.concatenate([c, kappa * c[0], sol[rows:]])
        y_hat = basis.T @ (combo @ sol)
        tangent = wbasis.T @ np.hstack([paths(kappa), slopes(c), tail])
        # d(B_i + kappa_j P_ji)/d kappa_j = d(K_j)/d c_i = P_ji, against the residual
        pr = (wbasis[rows:rows * (1 + npar)] @ wres).reshape(npar, rows)
        curvature = np.zeros((coef.size, coef.size))
        curvature[:rows, rows:rows + npar] = pr.T
        curvature[rows:rows + npar, :rows] = pr
        return coef, y_hat, wres, (tangent, curvature)

    @property
    def analytic(self) -> bool:
        """True when ``jacobian`` differentiates the base parameters exactly (uniform records)."""
        return self.data.uniform

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """d(weighted residual)/d(theta): exact (variable projection) in the base parameters, a delay and
        the parallel paths' own parameters (``exact``), finite differences in the other effects' own.

        The base path's derivatives in (alpha, a1, a2) come from the exact
        march's forward sensitivities (``discretize.step_response_sensitivity``,
        as identify's Jacobian), delayed and superposed like the path itself
        (both linear) and filtered by the output-filter effects (linear too);
        ``varpro.projected_jacobian`` turns them into the projected residual's.
        A parallel path's come from its effect's ``unit_step_derivatives``
        (superposed on the plain input; on the input rows in a ``coupled``
        design, whose tangent design stands for the columns and whose inner
        problem, bilinear in the gain ratio, adds its curvature). Any other
        effect parameter costs one
        more evaluation (forward difference, step as scipy's
        ``diff_step=1e-7``), mostly with the base path remembered. Uniform
        records only (``analytic``).
        """
        theta = np.asarray(theta, dtype=float)
        coef, _, wres = self.project(theta)
        moved, pulled = self._exact_products(theta, coef, wres)
        jac = np.empty((wres.size, theta.size))
        curvature = self._curvature(theta) if self.coupled else None
        jac[:, self.exact] = projected_jacobian(self._weighted_columns(theta), moved, pulled, curvature)
        for k in range(theta.size):
            if k not in self.exact:
                jac[:, k] = self._difference(theta, k, wres)
        return jac

    def _weighted_columns(self, theta: np.ndarray) -> np.ndarray:
        """The weighted design at theta: the last evaluation's (scipy asks for jac(x) after fun(x)) or anew
        (the coupled model's tangent design, remembered with its solution)."""
        if self.coupled:
            return self._tangent(theta)[0]
        if self._weighted is None or self._weighted[0] != theta.tobytes():
            phi = self.columns(theta)
            self._weighted = (theta.tobytes(), phi if self.data.weights is None else phi * self.data.weights[:, None])
        return self._weighted[1]

    def _curvature(self, theta: np.ndarray) -> np.ndarray:
        """A coupled design's inner curvature at theta (``varpro.projected_jacobian``), remembered with its solution."""
        return self._tangent(theta)[1]

    def _tangent(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A coupled design's (weighted tangent design, curvature) at theta, remembered with its solution; computed
        again where ``release`` let it go (the same numbers: not an evaluation of the fit, as the uncoupled design's
        columns in ``_weighted_columns``)."""
        key = theta.tobytes()
        if key not in self._solved:
            self.project(theta)
        entry = self._solved[key]
        if entry[3] is None:
            entry = self._solved[key] = entry[:3] + (self._coupled_project(theta)[3],)
        return entry[3]

    def _exact_products(self, theta: np.ndarray, coef: np.ndarray, wres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(D_k c, D_k^T r) for D_k = d(weighted design)/d(theta_k), k in ``exact``: shapes (m, n), (m, p).

        The base parameters (and a delay) move only the base path's columns
        (the first, one per input row); a parallel effect's own parameters
        only its path's column (its gain's). Each group's products come from
        its superposer (``_superposed``) with the step responses' derivatives.
        """
        data = self.data
        p, alpha, a1, a2, d = self._base(theta)
        ln10 = math.log(10.0)
        chain = np.array([[1.0, 0.0, 0.0], [0.0, -ln10 * a1, -2.0 * ln10 * a2], [0.0, ln10 * a1, 0.0]])
        steps = chain @ data.base_path_sensitivity(self.inputs, alpha, a1, a2, d)
        if len(self.exact) > 3 and not self.stages[Stage.PARALLEL]:
            slope = data.base_path_slope(alpha, a1, a2, d)
            steps = np.vstack([steps] + [self._delay_rate(theta, k) * slope for k in self.exact[3:]])
        sup = self.superposer()
        rows = sup.rows
        w = data.weights
        v = wres if w is None else wres * w
        moved, pulled_rows = self._superposed(sup, steps, coef[:rows], v, p)
        pulled = np.zeros((len(self.exact), coef.size))
        pulled[: len(steps), :rows] = pulled_rows
        parts, k = [moved], len(steps)
        for j, e in enumerate(self.stages[Stage.PARALLEL]):
            if e.name not in self.parallel_exact:
                continue
            col = rows + j                          # the path's column: after the base path's rows, in stage order
            dsteps = np.atleast_2d(e.unit_step_derivatives(p)(sup.grid_tau - d))
            if self.coupled:     # columns B_i + kappa P_i, and K = sum_i c_i P_i (coefficient 0 at the solution)
                kappa = coef[col] / coef[0] if coef[0] != 0.0 else 0.0
                m, q = self._superposed(sup, dsteps, kappa * coef[:rows], v, p)
                pulled[k:k + len(dsteps), :rows] = kappa * q
                pulled[k:k + len(dsteps), col] = q @ coef[:rows]
            else:
                # the plain input's rows: uncoupled parallel paths come only in designs without input effects
                m, q = self._superposed(sup, dsteps, coef[col:col + 1], v, p)
                pulled[k:k + len(dsteps), col] = q[:, 0]
            parts.append(m)
            k += len(dsteps)
        moved = np.vstack(parts)
        return (moved if w is None else moved * w), pulled

    def _superposed(self, sup: fx.Superposer, steps: np.ndarray, weights: np.ndarray, v: np.ndarray,
                    p: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(sum_i weights_i D_i, D_i . v) for the columns D the step responses ``steps`` give on sup's rows.

        Without an output filter straight from the superposer (two inverse FFTs
        per response whatever the number of input rows); an output filter
        (linear) gets the columns themselves, filtered.
        """
        if not self.stages[Stage.OUTPUT_FILTER]:
            return sup.products(steps, weights, v)
        dcols = sup.apply(steps)                                        # (k, rows, n)
        for e in self.stages[Stage.OUTPUT_FILTER]:
            dcols = e.filter_columns(self.data.t, dcols, p)
        return np.einsum("krn,r->kn", dcols, weights), dcols @ v

    def _delay_rate(self, theta: np.ndarray, k: int) -> float:
        """d(total delay)/d(theta_k) (a forward difference of the delay hooks: exact for a delay linear in theta_k)."""
        step = DIFF_STEP * max(1.0, abs(theta[k]))
        if theta[k] + step > self.hi[k]:
            step = -step
        moved = theta.copy()
        moved[k] += step
        return (self._base(moved)[4] - self._base(theta)[4]) / (moved[k] - theta[k])

    def _difference(self, theta: np.ndarray, k: int, r0: np.ndarray) -> np.ndarray:
        """Forward difference of the residual in parameter k (scipy's 2-point step, kept inside the bounds)."""
        step = DIFF_STEP * (1.0 if theta[k] >= 0 else -1.0) * max(1.0, abs(theta[k]))
        if not self.lo[k] <= theta[k] + step <= self.hi[k]:
            step = -step
        moved = theta.copy()
        moved[k] += step
        return (self.residual(moved) - r0) / (moved[k] - theta[k])

    def residual(self, theta: np.ndarray) -> np.ndarray:
        return self.project(theta)[2]

    def cost(self, theta: np.ndarray) -> float:
        r = self.residual(theta)
        return float(r @ r)


def _solution_bytes(entry: tuple) -> int:
    """Bytes of one remembered solution (``Design.project``): its arrays and a coupled design's tangent."""
    coef, y_hat, wres, extra = entry
    return coef.nbytes + y_hat.nbytes + wres.nbytes + (0 if extra is None else extra[0].nbytes + extra[1].nbytes)


def _triangular(rows: np.ndarray, wy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, Q^T wy) of the QR factorisation rows^T = Q R (economic), without forming Q.

    One Householder QR of [rows^T, wy]: its last column comes out as Q^T wy
    (the same reflectors applied to it), so Q, n x m, is neither built nor
    multiplied (half the work of ``qr(mode="economic")`` and its product).
    """
    m, n = rows.shape
    aug = np.empty((n, m + 1), order="F")
    aug[:, :m] = rows.T
    aug[:, m] = wy
    raw = qr(aug, mode="raw", overwrite_a=True, check_finite=False)[1]
    k = min(m, n)
    return raw[:k, :m], raw[:k, m]


def _solve(wphi: np.ndarray, wy: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of the weighted design (columns scaled to unit norm; gelsy, as identify)."""
    scale = np.linalg.norm(wphi, axis=0)
    scale[scale == 0] = 1.0
    return _gelsy(wphi / scale, wy, overwrite=True) / scale      # the scaled copy is LAPACK's to overwrite


#: (rows, columns) -> LAPACK's optimal work size for gelsy (``_gelsy``).
_GELSY_WORK: dict[tuple[int, int], int] = {}


def _gelsy(a: np.ndarray, b: np.ndarray, overwrite: bool = False) -> np.ndarray:
    """``scipy.linalg.lstsq(a, b, cond=RCOND, lapack_driver="gelsy", check_finite=False)[0]`` for real 2-d ``a``
    and 1-d ``b``: the same LAPACK call with the same arguments (so the same numbers), without the wrapper's
    per-call checks and work-size query (~60 us, a tenth of an evaluation on a 6,000-sample window, where
    a coupled design solves ten small problems per evaluation). ``overwrite``: ``a`` (Fortran-ordered) is the
    caller's scratch, factorised in place rather than copied (a design's size: 5 MB at 50,000 samples)."""
    m, n = a.shape
    if m == 0 or n == 0 or a.dtype != np.float64 or b.ndim != 1:
        return scipy_lstsq(a, b, cond=RCOND, lapack_driver="gelsy", check_finite=False)[0]
    work = _GELSY_WORK.get((m, n))
    if work is None:
        size, info = _GELSY_LWORK(m, n, 1, RCOND)
        if info != 0:
            return scipy_lstsq(a, b, cond=RCOND, lapack_driver="gelsy", check_finite=False)[0]
        work = _GELSY_WORK[(m, n)] = int(size)
    if m < n:
        b = np.concatenate([b, np.zeros(n - m)])
    x, info = _GELSY(a, b, np.zeros((n, 1), dtype=np.int32), RCOND, work, overwrite, False)[1::3]
    if info < 0:
        raise ValueError(f"illegal value in {-info}-th argument of internal gelsy")
    return x[:n]


# --------------------------------------------------------------------------- results
@dataclass
class ExtendedFit:
    """One fitted model: base parameters, effect parameters, output and residual."""

    effects: tuple[str, ...]
    model: CreepModel
    offset: float
    effect_params: dict[str, dict]
    theta: np.ndarray
    coef: np.ndarray
    y_hat: np.ndarray
    residual: np.ndarray          # y - y_hat (unweighted)
    rss: float                    # weighted residual sum of squares (what was minimised)
    n_params: int                 # nonlinear + linear parameters
    fit_percent: float
    residual_rms: float
    nfev: int = 0
    u_pre: float | None = None
    t_pre: float | None = None
    alternatives: list = field(default_factory=list, repr=False)  # other polished base starts
    names: list = field(default_factory=list, repr=False)         # names of theta's entries
    uncertainty: dict = field(default_factory=dict)  # 1-sigma of alpha, a1, a2 (``base_uncertainty``; fit_extended's)

    def simulate(self, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        """This model's output for input u at times t, in the fitted record's conventions (``y_hat`` again on it).

        Time stamps that jitter around a uniform grid are read on that grid, as the fit read them.
        """
        return fx.simulate_with_effects(self.model, t, u, self.effect_params, offset=self.offset,
                                        u_pre=self.u_pre, t_pre=self.t_pre)

    def fitted_model(self, **provenance) -> FittedModel:
        """This fit as a ``FittedModel`` (what ``save_model`` writes); ``provenance`` adds to its ``fitted``."""
        fitted = {"command": "fit", "fit_percent": self.fit_percent, "effects": list(self.effects), **provenance}
        return FittedModel(ExtendedModel(self.model, dict(self.effect_params), self.offset), input_offset=self.u_pre,
                           initial_state="reading", fitted=fitted)

    def to_dict(self) -> dict:
        return {"effects": list(self.effects), **self.model.describe(), "offset": self.offset,
                "effect_params": self.effect_params, "fit_percent": self.fit_percent,
                "residual_rms": self.residual_rms, "n_params": self.n_params, "uncertainty": self.uncertainty}

    def poorly_determined(self) -> list[str]:
        """Warnings for the base parameters whose 1-sigma exceeds POORLY_DETERMINED of their value (identify's
        rule and words): a slow sine or triangle does not excite the resonance, and its a1, a2 are then
        whatever the fit stopped at."""
        out = []
        for k, sd in self.uncertainty.items():
            value = abs(getattr(self.model, k))
            if not sd <= POORLY_DETERMINED * value:
                shown = f"{sd / value:.0%}" if math.isfinite(sd) and value > 0.0 else "unbounded"
                out.append(f"{k} is poorly determined by these data (1-sigma {shown})")
        return out


def _differentiable(effect: ParallelEffect) -> bool:
    """True when a parallel effect overrides ``unit_step_derivatives`` (its path is then differentiated exactly)."""
    return type(effect).unit_step_derivatives is not ParallelEffect.unit_step_derivatives


def _result(design: Design, theta: np.ndarray) -> ExtendedFit:
    """The fit at ``theta``: the search's linear solution, or the reported one where an input effect has its own
    (``_reported``); the parameters the BIC counts are the search's (its columns are the effects' freedom)."""
    data = design.data
    coef, y_hat, wres = (a.copy() for a in design.project(theta))
    n_params = len(theta) + len(coef)
    names, found = design.col_names, {}
    reported = _reported(design, theta)
    if reported is not None:
        coef, names, y_hat, wres, found = reported
        coef, y_hat, wres = coef.copy(), y_hat.copy(), wres.copy()
    p = dict(zip(design.names, theta))
    c = dict(zip(names, coef))
    b = c["b"]
    if b == 0.0 or not math.isfinite(b):
        b = 1e-300
    model = CreepModel.from_resonance(p["alpha"], 10 ** p["log10_fn"], 10 ** p["log10_zeta"], b)
    eff = {e: get_effect(e).fitted_params(FitView(p, c, b, data, design.variants[e], design.harmonics, found))
           for e in design.effects}
    res = data.y - y_hat
    return ExtendedFit(design.effects, model, c["offset"], eff, np.array(theta), coef, y_hat, res,
                       float(wres @ wres), n_params, fit_percent(data.y, y_hat), rms(res),
                       design.nfev, data.u_pre, data.t_pre, names=list(design.names))


def _reported(design: Design, theta: np.ndarray) -> tuple[np.ndarray, list[str], np.ndarray, np.ndarray, dict] | None:
    """(coefficients, their names, output, weighted residual, what the solve found) of the reported solution at
    ``theta``, or None when no input effect has one (``InputEffect.reported_solution``).

    The search fits hysteresis' weights in a reduced basis, unconstrained
    (cheap, and what it needs to find the plant); the model it reports is
    solved once more at the same nonlinear parameters on the effect's own rows
    with its constraints and prior, so that the reported weights are the
    model's and ``simulate`` reproduces ``y_hat``. Built like ``Design._paths``
    with those rows; a coupled design keeps the search's gain ratios of the
    parallel paths. One effect with a reported solution per design.
    """
    key = np.asarray(theta, dtype=float).tobytes()
    if design._reported is None or design._reported[0] != key:      # asked again at the same point: remembered
        design._reported = (key, _reported_solution(design, theta))
    return design._reported[1]


def _reported_solution(design: Design, theta: np.ndarray) -> tuple | None:
    """``_reported`` computed."""
    data = design.data
    if not design.inputs:
        return None
    solutions, sup = _remembered(data._cache.setdefault("reported", {}), tuple((e.name, v) for e, v in design.inputs),
                                 REPORTED_CACHE, lambda: _reported_rows(design), _reported_bytes, keep=0)
    own = [(e, sol) for e, _, sol in solutions if sol is not None]
    if not own:
        return None
    coef, _, wres = design.project(theta)
    noise_var = float(wres @ wres) / max(data.n - len(coef) - len(theta), 1)
    p, alpha, a1, a2, d = design._base(theta)
    names, cols = ["b"], {}
    for e, _, sol in solutions:
        more = sol.names if sol is not None else e.column_names()
        cols[e.name] = np.arange(len(names), len(names) + len(more))
        names += more
    static, static_names = design._static_columns(p)
    rows_n, parallel = sup.rows, design.stages[Stage.PARALLEL]
    tau = sup.grid_tau - d if data.uniform else None
    if design.coupled:        # columns B_i + kappa P_i with the search's kappa = g / b
        first = len(design.col_names) - len(static_names) - len(parallel)
        kappa = [coef[first + j] / coef[0] if coef[0] != 0.0 else 0.0 for j in range(len(parallel))]
        # every path sees the transformed input: B_i + kappa P_i is the superposition of the combined step
        # response (linear in it), one pass over the rows instead of one per path
        steps = [e.unit_step(p) for e in parallel]
        if data.uniform:
            step = fx.delayed_grid(data.step_grid(alpha, a1, a2), data.h, d) + sum(
                k * s(tau) for k, s in zip(kappa, steps))
        else:
            def step(tt: np.ndarray) -> np.ndarray:
                return fx.base_step_at(alpha, a1, a2, tt - d) + sum(k * s(tt - d) for k, s in zip(kappa, steps))
        more = []
    else:
        if data.uniform:
            step = fx.delayed_grid(data.step_grid(alpha, a1, a2), data.h, d)
        else:
            def step(tt: np.ndarray) -> np.ndarray:
                return fx.base_step_at(alpha, a1, a2, tt - d)
        more = [data.parallel_path(e, p, tuple(p[k] for k in design.own[e.name]), d, tau) for e in parallel]
        names = names + [e.gain_column for e in parallel]
    phi = _stacked(design, sup, step, more, static, p)
    names = names + static_names
    wphi = phi if data.weights is None else phi * data.weights[:, None]
    effect, sol = own[0]
    x, found = sol.solve(wphi, data.wy, 0, cols[effect.name], float(coef[0]), noise_var)
    y_hat = phi @ x
    wres = data.wy - wphi @ x
    if design.coupled:        # reported in the uncoupled layout: each path's gain g = kappa b
        x = np.concatenate([x[:rows_n], [k * x[0] for k in kappa], x[rows_n:]])
        names = names[:rows_n] + [e.gain_column for e in design.stages[Stage.PARALLEL]] + names[rows_n:]
    return x, names, y_hat, wres, {effect.name: found}


def _stacked(design: Design, sup: fx.Superposer, step: np.ndarray | Callable, more: list[np.ndarray],
             static: np.ndarray, p: dict[str, float]) -> np.ndarray:
    """The reported solution's design (n, columns): the superposition of ``step`` on sup's rows, the ``more``
    rows (parallel paths), filtered by the output-filter effects, then the ``static`` rows. Without a filter the
    superposition is written straight into the design's rows: stacked, it would be a second copy of the 25 rows
    beside the design (10 MB for hysteresis at 50,000 samples)."""
    filters = design.stages[Stage.OUTPUT_FILTER]
    if filters:
        dynamic = [sup.apply(step)] + more
        for e in filters:
            dynamic = [e.filter_columns(design.data.t, q, p) for q in dynamic]
        return np.vstack(dynamic + [static]).T
    rows = np.empty((sup.rows + sum(q.shape[0] for q in more) + static.shape[0], sup.n))
    sup.apply(step, out=rows[:sup.rows])
    rows[sup.rows:] = np.vstack(more + [static])
    return rows.T


def _reported_rows(design: Design) -> tuple[list[tuple], fx.Superposer | None]:
    """(each input effect, its variant and its reported solution; the superposer of the reported rows, None when
    no effect has a reported solution): what ``_reported_solution`` needs of a record and the variants, remembered
    per record (``Prepared``) within ``CACHE_BYTES`` (an exploration window's; a long record's, 10 MB of steps
    for hysteresis' 25 rows at 50,000 samples and 30 MB with their spectra, is built again when asked again,
    without the spectra)."""
    data = design.data
    solutions = [(e, variant, e.reported_solution(data, variant)) for e, variant in design.inputs]
    if all(sol is None for _, _, sol in solutions):
        return solutions, None

    def rows(u: np.ndarray, before: bool = False) -> np.ndarray:
        return np.vstack([u[None, :]] + [sol.rows(u, before) if sol is not None else e.design_rows(data, u, v, before)
                                          for e, v, sol in solutions])

    pre = None if data.u_pre is None else rows(np.array([data.u_pre]), before=True)[:, 0]
    x = rows(data.u)
    # rows' steps and their spectra: 24 bytes per row and sample; beyond CACHE_BYTES the entry is not
    # remembered, and spectra kept for its one ``apply`` would only add to the peak
    keep = 24 * x.size <= CACHE_BYTES
    return solutions, fx.Superposer(data.t, x, x_pre=pre, t_pre=data.t_pre, keep_spectra=keep, overwrite_x=True)


def _reported_bytes(entry: tuple) -> int:
    """Bytes of a remembered ``_reported_rows``: its superposer's input steps and their spectra (uniform records)
    or times since each input change (the reported solutions run their rows again when asked)."""
    sup = entry[1]
    if sup is None:
        return 0
    held = sup.tau.nbytes if not sup.uniform else 0 if sup.spectra is None else sup.spectra.nbytes
    return sup.dx.nbytes + held


def base_theta(model: CreepModel) -> np.ndarray:
    """The base model's nonlinear parameters on the fitting scale."""
    return np.array([model.alpha, math.log10(model.fn), math.log10(model.zeta)])


def _optimise(design: Design, theta0: np.ndarray, max_nfev: int = MAX_NFEV, tol: float = 1e-8,
              ftol: float | None = None) -> np.ndarray:
    x0 = np.clip(theta0, design.lo, design.hi)
    span = design.hi - design.lo
    x0 = np.minimum(np.maximum(x0, design.lo + 1e-9 * span), design.hi - 1e-9 * span)
    jac = {"jac": design.jacobian} if design.analytic else {"diff_step": DIFF_STEP}
    try:
        sol = least_squares(design.residual, x0, bounds=(design.lo, design.hi), method="trf",
                            x_scale="jac", max_nfev=max_nfev, ftol=tol if ftol is None else ftol, xtol=tol, **jac)
    except (ValueError, np.linalg.LinAlgError, ModelError):
        return x0
    return sol.x if design.cost(sol.x) <= design.cost(x0) else x0


# --------------------------------------------------------------------------- base fit
def _frf_peaks(data: Prepared, count: int = 3) -> list[float]:
    """Frequencies (Hz) of the largest peaks of |Y/U| * f (uniform records), strongest first (remembered per
    record: the base fit and every restart ask)."""
    if not data.uniform or data.n < 64:
        return []
    peaks = data._cache.get(("frf_peaks", count))       # one look-up: ``release`` may empty the cache meanwhile
    if peaks is None:
        peaks = data._cache[("frf_peaks", count)] = tuple(_frf_peaks_of(data, count))
    return list(peaks)


def _frf_peaks_of(data: Prepared, count: int) -> list[float]:
    """``_frf_peaks`` computed."""
    nper = int(min(data.n, 2 ** int(math.log2(max(64, data.n // 8)))))
    du = np.diff(data.u, prepend=data.u[0])
    dy = np.diff(data.y, prepend=data.y[0])
    f, puu = spectra.welch(du, data.fs, nper)
    _, puy = spectra.csd(du, dy, data.fs, nper)
    ok = (f > 2 * f[1]) & (puu > 1e-12 * puu.max())
    if ok.sum() < 8:
        return []
    mag = np.zeros_like(f)
    mag[ok] = np.abs(puy[ok]) / puu[ok]
    peaks, props = spectra.find_peaks(mag, prominence=0.1 * mag.max())
    order = np.argsort(props["prominences"])[::-1]
    return [float(f[peaks[i]]) for i in order[:count]]


@single_threaded
def fit_base(data: Prepared, start: CreepModel | None = None, max_nfev: int = MAX_NFEV,
             grid: bool = True) -> ExtendedFit:
    """The base creep model (plus offset) by variable projection from several starts.

    Starts: ``start`` (e.g. the result of ``identify``), and (``grid``) a
    small grid over alpha, the resonance frequency (peaks of the empirical
    frequency response, and a default) and the damping. The two best starts
    are polished.
    """
    design = Design(data)
    # long records: choose and pre-polish the starts on a prefix (same experiment, cheaper), finish on all
    explore = design.explored()
    starts: list[np.ndarray] = []
    if start is not None:
        starts.append(base_theta(start))
    fmax = 10 ** design.hi[1] / 2.0
    fns = (_frf_peaks(data) + [fmax / 10.0, fmax / 100.0]) if grid or start is None else []
    for alpha in (0.15, 0.4, 0.7, 0.95):
        for fn in fns:
            for zeta in (0.05, 0.3, 1.0):
                starts.append(np.array([alpha, math.log10(fn), math.log10(zeta)]))
    costs = []
    for th in starts:
        th = np.clip(th, explore.lo, explore.hi)
        try:
            costs.append(explore.cost(th))
        except (ValueError, ModelError, np.linalg.LinAlgError):
            costs.append(np.inf)
    order = np.argsort(costs)
    polished = []
    for i in order[:2]:
        th = _polish(explore, design, starts[i], max_nfev)
        polished.append((design.cost(th), th))
    polished.sort(key=lambda ct: ct[0])
    fit = _result(design, polished[0][1])
    fit.alternatives = [th for _, th in polished[1:]]
    return fit


# --------------------------------------------------------------------------- extended fit
def _grid_starts(design: Design, base: ExtendedFit, peaks: list[float]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(grid starts, priority starts) for the effects' nonlinear parameters.

    Each effect gives, per parameter, grid values covering its range and
    priority values (e.g. a frequency on a residual-spectrum peak; always
    polished, since a narrow resonance or line is found there and almost
    nowhere else). Every start is combined with the base fit, its runner-up
    and the base variants the effects ask for.
    """
    data = design.data
    effects = [get_effect(e) for e in design.effects]
    grids: list[list[float]] = []
    prio: list[list[float]] = []
    for e in effects:
        for grid, priority in e.start_values(data, peaks):
            grids.append(grid)
            prio.append(priority)
    bases = [base.theta[:3]] + [np.asarray(a)[:3] for a in base.alternatives
                                if np.max(np.abs(np.asarray(a)[:3] - base.theta[:3])) > 1e-3]
    for e in effects:
        for b_ in list(bases):
            bases += e.base_variants(b_, (design.lo[0], design.hi[0]))
    if not grids:
        return [b_ for b_ in bases], []

    def mesh(lists: list[list[float]]) -> list[np.ndarray]:
        if any(len(x) == 0 for x in lists):
            return []
        m = np.array(np.meshgrid(*lists, indexing="ij")).reshape(len(lists), -1).T
        return [np.concatenate([b_, row]) for b_ in bases for row in m]

    # a priority start keeps the grid for the parameters that have no priority values
    prio_lists = [p_ if p_ else g for p_, g in zip(prio, grids)] if any(prio) else []
    prio_starts = mesh(prio_lists) if prio_lists else []
    n_effect_params = len(design.names) - 3
    for e in effects:
        if len(e.nonlinear_params(data)) == n_effect_params:  # the only effect with nonlinear parameters
            prio_starts += e.takeover_starts(base.theta)
    return mesh(grids), prio_starts


def _null_start(design: Design, base: ExtendedFit) -> np.ndarray:
    """The base fit inside the extended model (effects switched off): the nested model, never worse than base."""
    tail = _default_tail(design)
    for i, spec in enumerate(design.specs[3:]):
        if spec.off is not None:
            tail[i] = spec.off
    return np.concatenate([base.theta[:3], tail])


def _default_tail(design: Design) -> np.ndarray:
    """Mid-range values of the effects' nonlinear parameters (for quick comparisons)."""
    return 0.5 * (design.lo[3:] + design.hi[3:])


def _merge(design: Design, theta: np.ndarray, warm: ExtendedFit) -> np.ndarray:
    """theta with every parameter that ``warm`` also has replaced by warm's value."""
    out = np.array(theta, dtype=float)
    for name, value in zip(warm.names, warm.theta):
        if name in design.names:
            out[design.index(name)] = value
    return out


def _choose_variants(data: Prepared, effects: tuple[str, ...], base: ExtendedFit, harmonics: int,
                     warm: ExtendedFit | None) -> dict[str, str]:
    """Each effect's discrete variant: the warm fit's when it holds every effect of this fit, else the best
    of all after a short polish on the explore window (from the warm fit's values where it has them).

    (Hysteresis: the operators' state before the record is unknown.) A single
    effect's variant is not kept for a combination: alone, hysteresis chose
    the state that also imitated a drift, and a pair with a drift warm from it
    stopped at 3-14x the noise where the centred state reached it (bench
    hysteresis + drift 10-100x, seeds 4, 9, 19).
    """
    chosen: dict[str, str] = {}
    complete = warm is not None and set(effects) <= set(warm.effects)
    for name in effects:
        effect = get_effect(name)
        if not effect.variants:
            continue
        known = (warm.effect_params.get(name) or {}).get(effect.variant_key) if complete else None
        if known is not None:
            chosen[name] = known
            continue
        small = data.explore_data()
        costs = {}
        for variant in effect.variants:
            d = Design(small, effects, harmonics, {**chosen, name: variant})
            start = np.concatenate([base.theta[:3], _default_tail(d)])
            th = _optimise(d, start if warm is None else _merge(d, start, warm), SHORT_NFEV, 1e-6)
            costs[variant] = d.cost(th)
        chosen[name] = min(costs, key=costs.get)
    return chosen


def residual_peaks(data: Prepared, residual: np.ndarray) -> list[float]:
    """Spectral peaks (Hz) of what a fit left, where an effect's line or ringing would sit: the priority starts of
    effects with a frequency (``fit_extended``) and the pair trigger's points (``pairs.choose_pair``); narrow lines
    (``locate.spectrum_peaks``), then a damped mode's broad humps (``locate.spectrum_humps``); none on a record not
    sampled uniformly."""
    from .locate import spectrum_humps, spectrum_peaks
    if not data.uniform:
        return []
    last = data._cache.get("residual_peaks")     # every fit from the same base asks for its residual's peaks
    if last is not None and last[0] is residual:
        return list(last[1])
    lines = [p["f_hz"] for p in spectrum_peaks(data.t, residual, max_peaks=4, ratio=3.0)]
    # then the broad humps a damped mode leaves, where no line is already
    humps = [f for f in spectrum_humps(data.t, residual, max_peaks=HUMPS + len(lines))
             if all(abs(f - g) > 0.05 * f for g in lines)]
    peaks = lines + humps[:HUMPS]
    data._cache["residual_peaks"] = (residual, tuple(peaks))
    return peaks


@single_threaded
def fit_extended(data: Prepared, effects: tuple[str, ...] | list[str] | str, base: ExtendedFit | None = None,
                 harmonics: int = 1, max_nfev: int = MAX_NFEV, n_starts: int = 2,
                 warm: ExtendedFit | None = None, workers: int = 1, restart: bool = False,
                 screen: bool = False, uncertainty: bool = True) -> ExtendedFit:
    """Fit the base model extended by ``effects``, warm-started from ``base`` (fitted if not given).

    The effects' nonlinear parameters start from a grid (residual-spectrum
    peaks for frequencies); the ``SHORT_STARTS`` most promising grid values
    (each with its best base variant) get a short joint polish, and the
    ``n_starts`` best of those a full one (bounded least squares). ``warm``
    (e.g. the fit of one of the effects alone) seeds further starts with its
    values, so a combination is never worse than that fit. ``workers`` > 1
    runs the short polishes of a long record on that many threads (the
    result does not depend on it, ``_short_polishes``). ``restart``: search the base
    parameters again from a grid (``_restart_base``) whatever the fit's misfit (by default only a fit above
    the floor that explains most of the base's misfit, one whose resonance lies above the Nyquist frequency,
    or one that reports its uncertainty and determines a1 or a2 weakly, is restarted). ``screen``: the fit
    only ranks effects for a fit on a longer record (the pair search on a long record's window, where only the
    chosen pair is fitted to the record, warm from this fit and restarted by the rule there): no restart here.
    ``uncertainty``: the 1-sigma of alpha, a1 and a2 (``base_uncertainty``: a Jacobian and the profile's probes,
    ~20 % of a hysteresis fit's time); diagnose's candidate fits, which rank effects, leave it out.
    """
    if isinstance(effects, str):
        effects = tuple(e.strip() for e in effects.split(",") if e.strip())
    effects = tuple(dict.fromkeys(effects))
    if base is None:
        base = fit_base(data)
    if not effects:
        return base
    variants = _choose_variants(data, effects, base, harmonics, warm)
    design = Design(data, effects, harmonics, variants)
    peaks = residual_peaks(data, base.residual)
    # explore (grids, short polishes) on a prefix of long records: the same experiment, cheaper evaluations
    explore = design.explored()
    grid, prio = _grid_starts(explore, base, peaks)

    def ranked(d: Design, starts: list[np.ndarray]) -> list[tuple[float, np.ndarray]]:
        starts = [np.clip(th, d.lo, d.hi) for th in starts]
        out = list(zip(_costs(d, starts, workers if d is not design else 1), starts))
        out.sort(key=lambda ct: ct[0])
        return out

    # best base variant per effect-parameter value, the most promising few, plus the priority starts
    groups: dict[tuple, np.ndarray] = {}
    for _, th in ranked(explore, grid):
        groups.setdefault(tuple(np.round(th[3:], 9)), th)
    if warm is not None:
        # the priority starts also with warm's values: beside the other effect's misfit, a mode started on its
        # ringing's frequency ranked below starts that imitate the base's resonance (second mode + hysteresis
        # 10-100x seed 9: the mode at 391 Hz from the base, 378x the noise variance, 9.7x with hysteresis' fit)
        prio = prio + [_merge(explore, th, warm) for th in prio]
    chosen = list(groups.values())[:SHORT_STARTS] + [th for _, th in ranked(explore, prio)[:PRIORITY_STARTS]]
    if warm is not None:
        chosen += [_merge(explore, th, warm) for th in list(groups.values())[:2]]
    chosen = list({th.tobytes(): th for th in chosen}.values())    # a priority start may repeat a grid start
    short = _short_polishes(explore, design, chosen, workers)
    finalists = [th for _, th in ranked(explore, short)[:n_starts]]
    further = [_polished_starts(design, [th]) for th in finalists]
    # each finalist's cheapest further start short-polished too: a mode's image across Nyquist starts from the
    # alias fit's damping, and unpolished it ranked below the alias it came from (second mode 3-10x seed 46:
    # the mode at 779 Hz, the alias' fit at 221 Hz, 1.55x the noise; each image, short-polished, reaches 779 Hz).
    # The images compete for the final polish apart: a polished image has its source's sampled poles, and with
    # its unpolished neighbours it crowded the true mode out of the finalists (10-100x seed 75: 60 Hz, its
    # image at 940 Hz polished to 1.51x the noise)
    images = ([th for starts in further for th in starts]
              + [_optimise(explore, ranked(explore, starts)[0][1], SHORT_NFEV, SHORT_XTOL, SHORT_FTOL)
                 for starts in further if starts])
    finalists.append(_null_start(design, base))
    if warm is not None:
        finalists.append(_merge(design, _null_start(design, base), warm))
    if explore is not design:  # some parameters are sharper on the whole record (a line's frequency)
        for e in effects:
            for name, values in get_effect(e).full_record_values(peaks).items():
                i = design.index(name)
                for th in list(finalists):
                    for value in values:
                        v = th.copy()
                        v[i] = value
                        finalists.append(v)
    best, best_cost = None, np.inf
    polished = ranked(design, finalists)[:n_starts if explore is design else 1] + ranked(design, images)[:1]
    for _, th in polished:
        th = (_optimise(design, th, max_nfev, FULL_TOL) if explore is design
              else _optimise(design, th, FULL_NFEV, FULL_TOL, FULL_FTOL))
        c = design.cost(th)
        if c < best_cost:
            best, best_cost = th, c
    fit = _result(design, best)
    above = RESTART_ABOVE_FLOOR * noise_std_estimate(fit.residual) < fit.residual_rms
    restarted = restart or (not screen and ((above and (fit.residual_rms < RESTART_EXPLAINED * base.residual_rms
                                                        or _on_a_bound(design, base.theta[:3])))
                                            or _beyond_nyquist(data, best)))
    if restarted:
        th = _restart_base(design, explore, best, max_nfev, workers)
        cost = design.cost(th)
    if not uncertainty:
        design.release()         # from here asked only for points it has evaluated (its Jacobian aside)
    if restarted and cost < best_cost:
        best, best_cost = th, cost
        fit = _result(design, th)
    # the other variants (hysteresis' start states): for a fit above the floor that explains most of the base
    # misfit, and for every fit for the user (``uncertainty``), since the short polishes that chose the variant
    # rank the start states wrongly at the floor too. A random staircase (compensation bench plant 6, 40,000
    # samples) was reported centred at 1.026x the noise, 2,300 noise variances above the plant's descending start,
    # b 5 % off and its compensation 9x instead of 20x; a staircase with few levels (bench seed 8) ascending at
    # 2.8x, alpha 3.5 % off, where the plant rests centred (1.006x).
    if uncertainty or (above and fit.residual_rms < RESTART_EXPLAINED * base.residual_rms):
        fit, design, best = _other_variants(design, fit, best, best_cost, max_nfev, workers)
    fit, design, best = _reported_variant(design, fit, best, max_nfev)
    if uncertainty:
        fit, design, best = _searched_further(design, fit, best, restarted, max_nfev, workers)
    return fit


def _searched_further(design: Design, fit: ExtendedFit, best: np.ndarray, restarted: bool,
                      max_nfev: int, workers: int) -> tuple[ExtendedFit, Design, np.ndarray]:
    """A fit that reports its uncertainty (one for the user, not one of diagnose's ranking fits) with its
    uncertainty, and searched again from the base parameters (``_restart_base``) when it determines the resonance
    only weakly (``RESTART_UNCERTAIN``), kept only when the cost falls; returns (the fit, its design, its
    parameters)."""
    fit.uncertainty = base_uncertainty(design, best, fit.residual)
    if not restarted and _weakly_determined(fit):
        th = _restart_base(design, design.explored(), best, max_nfev, workers)
        if design.cost(th) < design.cost(best):
            fit, design, best = _reported_variant(design, _result(design, th), th, max_nfev)
            fit.uncertainty = base_uncertainty(design, best, fit.residual)
    return fit, design, best


def _weakly_determined(fit: ExtendedFit) -> bool:
    """Does the fit determine a1 or a2 only to a finite relative 1-sigma above ``RESTART_UNCERTAIN``?"""
    model = fit.model
    rel = [fit.uncertainty.get(name, 0.0) / abs(getattr(model, name)) for name in ("a1", "a2")
           if getattr(model, name)]
    return any(RESTART_UNCERTAIN < r < math.inf for r in rel)


def base_uncertainty(design: Design, theta: np.ndarray, residual: np.ndarray) -> dict[str, float]:
    """1-sigma of alpha, a1 and a2 at the fit's parameters ``theta``: sigma^2 (J^T J)^-1 of the weighted,
    projected residual's Jacobian (variable projection: the linear coefficients profiled out, so this is the
    nonlinear parameters' marginal covariance), sigma^2 the weighted residual's variance over n - parameters,
    inflated for a coloured residual as identify's (``long_run_variance_factor``); a1 and a2 from log10 fn and
    log10 zeta by the delta method (a1 = zeta / (pi fn), a2 = 1 / (2 pi fn)^2). inf for a parameter that leans
    on a direction J^T J is singular in (``UNDETERMINED_CONDITION``: the record does not determine it), and for
    a1 or a2 where the cost's profile leaves them open over a factor of 2-8 (``_profile_open``); empty where the
    design has no exact Jacobian (non-uniform time)."""
    if not design.analytic:
        return {}
    try:
        jac = design.jacobian(theta)
        coef, _, wres = design.project(theta)
    except (ValueError, np.linalg.LinAlgError, ModelError):
        return {}
    dof = max(wres.size - len(theta) - len(coef), 1)
    sigma2 = float(wres @ wres) / dof * long_run_variance_factor(residual)
    scale = np.sqrt(np.einsum("ij,ij->j", jac, jac))
    scale[scale == 0.0] = 1.0
    jn = jac / scale
    eig, vec = np.linalg.eigh(jn.T @ jn)
    kept = eig > UNDETERMINED_CONDITION * max(eig[-1], 1e-300)
    cov = (vec[:, kept] / eig[kept]) @ vec[:, kept].T * sigma2 / np.outer(scale, scale)
    lost = np.sum(vec[:, ~kept] ** 2, axis=1) > 1e-3      # a parameter with a share of a singular direction
    ia, ifn, iz = design.index("alpha"), design.index("log10_fn"), design.index("log10_zeta")
    ln10 = math.log(10.0)
    m = CreepModel.from_resonance(theta[ia], 10 ** theta[ifn], 10 ** theta[iz], 1.0)
    var_ln_a1 = ln10 ** 2 * (cov[iz, iz] + cov[ifn, ifn] - 2.0 * cov[iz, ifn])    # ln a1 = ln10 (log zeta - log fn)
    var_ln_a2 = 4.0 * ln10 ** 2 * cov[ifn, ifn]                                   # ln a2 = -2 ln10 log fn + const
    open_ = _profile_open(design, theta, ifn, iz, float(wres @ wres), sigma2)
    return {"alpha": math.inf if lost[ia] else math.sqrt(max(cov[ia, ia], 0.0)),
            "a1": math.inf if lost[ifn] or lost[iz] or "a1" in open_ else m.a1 * math.sqrt(max(var_ln_a1, 0.0)),
            "a2": math.inf if lost[ifn] or "a2" in open_ else m.a2 * math.sqrt(max(var_ln_a2, 0.0))}


def _profile_open(design: Design, theta: np.ndarray, ifn: int, iz: int, cost: float, sigma2: float) -> set[str]:
    """Which of a1, a2 the cost's profile leaves open: fn or zeta moved by one of PROFILE_FACTORS, up or down (the
    other parameters as fitted, the linear ones projected afresh), and a1 or a2 called poorly determined when the
    cost rises by less than a Gaussian of 1-sigma POORLY_DETERMINED (relative) would for that move of it:
    ``rise <= (|d ln a| / POORLY_DETERMINED)^2`` noise variances (fn x f moves ln a2 by 2 ln f and ln a1 by ln f;
    zeta x f moves ln a1 by ln f). The curvature at the fit describes only its neighbourhood: on slow sines the
    fit's a2 stopped 8-85x off with a 4-8 % 1-sigma where fn x 2-8 cost 13-14 noise variances. Not
    re-optimising the others can only raise the probes' costs, so an open verdict holds."""
    found: set[str] = set()
    for i, moves in ((ifn, {"a1": 1.0, "a2": 2.0}), (iz, {"a1": 1.0})):
        for step in (sign * math.log10(f) for f in PROFILE_FACTORS for sign in (-1.0, 1.0)):
            other = theta.copy()
            other[i] = min(max(theta[i] + step, design.lo[i]), design.hi[i])
            if other[i] == theta[i]:
                continue
            try:
                rise = (design.cost(other) - cost) / sigma2
            except (ValueError, np.linalg.LinAlgError, ModelError):
                continue
            moved = abs(other[i] - theta[i]) * math.log(10.0)
            found |= {name for name, k in moves.items() if not rise > (k * moved / POORLY_DETERMINED) ** 2}
    return found


def _other_variants(design: Design, fit: ExtendedFit, best: np.ndarray, best_cost: float,
                    max_nfev: int, workers: int = 1) -> tuple[ExtendedFit, Design, np.ndarray]:
    """``fit``, or the fit with another variant of an effect (e.g. hysteresis' initial state) polished from its
    parameters if that goes lower: the variant is chosen by short polishes before the fit, which can rank the
    states wrongly (hysteresis + second creep 10-100x seed 1: the descending state stopped at 1.73x the noise,
    the centred one from the same parameters reaches 0.99x). Only for fits above the floor that explain most
    of the base's misfit, as the base's restart, and for every fit for the user (``fit_extended``). Returns
    (fit, its design, its parameters)."""
    chosen, theta = design, best
    others = [Design(design.data, design.effects, design.harmonics, {**design.variants, name: variant})
              for name in design.effects for variant in get_effect(name).variants
              if variant != design.variants.get(name)]
    if not others:
        return fit, chosen, theta
    if design.data.explore_data() is not design.data:
        # a long record: each variant polished on the window, the one that ends lowest there on the record
        small = [other.explored() for other in others]
        done = list(ordered_map(lambda d: _optimise(d, best, max_nfev), small, workers))
        k = int(np.argmin([d.cost(th) for d, th in zip(small, done)]))
        del small                # the window designs' rows and solutions, not needed on the record
        others, done = [others[k]], [_optimise(others[k], done[k], FULL_NFEV, FULL_TOL, FULL_FTOL)]
    else:
        # each variant's own designs: on the fit's workers, the same polishes and counts as one after the other
        done = list(ordered_map(lambda other: _polish(other, other, best, max_nfev), others, workers))
    for other, th in zip(others, done):
        cost = other.cost(th)
        other.release()          # its result at th is remembered; the reported rows are built next
        if cost < best_cost:
            fit, best_cost, chosen, theta = _result(other, th), cost, other, th
    return fit, chosen, theta


def _reported_variant(design: Design, fit: ExtendedFit, theta: np.ndarray,
                      max_nfev: int) -> tuple[ExtendedFit, Design, np.ndarray]:
    """(fit, its design, its parameters): ``fit``, or the fit with another variant of an effect that has a reported
    solution (hysteresis' initial state) when that variant's reported solution reaches a lower objective (residual
    plus the prior's penalty, ``InputEffect.reported_solution``) at the same parameters, polished from there.

    The search ranks the variants with its reduced basis unconstrained, where an operator the record never
    opens still fits the first move of the input (the jump of a centred operator) and stands in for the state
    before the record: centred won there and, with those operators pinned in the reported model, missed by
    2.4x the noise where the true ascending state reaches it (a random staircase at 10 kHz); with the data
    equal, the prior prefers the loop that needs no +-1 weights (the centred state's width 0.02 % of the stroke,
    the true descending one's 14 %)."""
    def objective(rep: tuple) -> float:
        return float(rep[3] @ rep[3]) + sum(f.get("penalty", 0.0) for f in rep[4].values())

    own = _reported(design, theta)
    if own is None:
        return fit, design, theta
    best, best_theta, best_obj = design, theta, objective(own)
    for e, _ in design.inputs:
        if e.name not in own[4]:
            continue
        for variant in e.variants:
            if variant != design.variants[e.name]:
                other = Design(design.data, design.effects, design.harmonics, {**design.variants, e.name: variant})
                other.project(theta)
                other.release()  # its solution remembered, its rows let go before the reported ones are built
                obj = objective(_reported(other, theta))
                if obj < best_obj:
                    best, best_obj = other, obj
    if best is design:
        return fit, design, theta
    th = _polish(best.explored(), best, theta, max_nfev)
    th = th if objective(_reported(best, th)) < best_obj else best_theta
    return _result(best, th), best, th


def _short_polishes(explore: Design, design: Design, chosen: list[np.ndarray], workers: int) -> list[np.ndarray]:
    """The short polishes of the chosen starts on the exploration window, in order; on ``workers`` threads if > 1.

    In parallel each polish runs on its own copy of the exploration design
    (a design's solution cache and counter are not shared between threads);
    a copy only misses the solutions the shared one remembered, which are
    exact reuse, so every polish ends where the serial one does. Only when
    the window is not the record itself: the record's design counts the
    evaluations the fit reports (``ExtendedFit.nfev``), and that count must
    not depend on the threads.
    """
    if workers <= 1 or explore is design or len(chosen) <= 1:
        return [_optimise(explore, th, SHORT_NFEV, SHORT_XTOL, SHORT_FTOL) for th in chosen]
    return list(ordered_map(lambda th: _optimise(explore.copy(), th, SHORT_NFEV, SHORT_XTOL, SHORT_FTOL),
                            chosen, workers))


def _costs(design: Design, thetas: list[np.ndarray], workers: int = 1) -> list[float]:
    """Each theta's cost on ``design`` (inf where the model cannot be evaluated), in order; on ``workers`` threads
    when > 1, each a share of the thetas on its own copy of the design (as ``_short_polishes``: a copy only misses
    remembered solutions, which are exact reuse). Only for an exploration window's design: a copy's evaluations
    are not added to the design's count, which the record's design reports (``ExtendedFit.nfev``)."""
    def each(d: Design, part: list[np.ndarray]) -> list[float]:
        out = []
        for th in part:
            try:
                out.append(d.cost(th))
            except (ValueError, ModelError, np.linalg.LinAlgError):
                out.append(np.inf)
        return out
    if workers <= 1 or len(thetas) <= 1:
        return each(design, thetas)
    size = -(-len(thetas) // workers)
    shares = [thetas[i:i + size] for i in range(0, len(thetas), size)]
    return [c for done in ordered_map(lambda part: each(design.copy(), part), shares, workers) for c in done]


def _on_a_bound(design: Design, base: np.ndarray) -> bool:
    """True when a base parameter (alpha, fn, zeta) sits on its bound: a base fit a strong effect distorted.

    (Strong leakage pushed alpha to 0.001 and zeta to 20, a creep cancelled by
    the high-pass: warm-started there, even the leakage fit explained nothing
    and stopped at 23x the noise; bench leakage 10-100x seed 23.)
    """
    span = design.hi[:3] - design.lo[:3]
    return bool(np.any(np.minimum(base - design.lo[:3], design.hi[:3] - base) < 1e-6 * span))


def _beyond_nyquist(data: Prepared, theta: np.ndarray) -> bool:
    """True when the fitted resonance lies above the record's Nyquist frequency, where the samples cannot show
    it: the fit either lost the plant's resonance or the plant has none in band, and a restart (kept only if it
    lowers the cost) tells which. (Hysteresis, random staircase seed 2: the base fit and the hysteresis fit ended
    at 9.9 kHz for a plant at 481 Hz sampled at 10 kHz, at 1.048x their own noise estimate, under
    ``RESTART_ABOVE_FLOOR``; restarted, 474 Hz and 1.001x the noise.)"""
    return bool(10 ** theta[1] > 0.5 / data.h)


def _restart_base(design: Design, explore: Design, best: np.ndarray, max_nfev: int, workers: int = 1) -> np.ndarray:
    """The best of a grid over alpha, fn, zeta with the effects' parameters of ``best`` kept, polished.

    Global convergence of an extended fit: the warm starts come from the base
    fit, which a strong effect distorts (e.g. strong leakage drives the base
    damping to its bound); with the effect's parameters already near their
    values, the base parameters are searched again. An effect that mirrors a
    base parameter (``Effect.swapped``) is also searched with the two
    exchanged: a strong second creep had put the resonance on the wrong
    creep path and stopped at 10.8x the noise (bench second_creep 10-100x, seed 0).
    """
    data = design.data
    fmax = 10 ** design.hi[1] / 2.0
    fns = _frf_peaks(data) + [fmax / 10.0, fmax / 100.0]
    kept = [best] + _swapped(design, best)
    starts = [np.concatenate([[a, math.log10(fn), math.log10(z)], th[3:]])
              for th in kept for a in RESTART_ALPHAS + (float(th[0]),) for fn in fns for z in RESTART_ZETAS]
    costs = _costs(explore, [np.clip(th, explore.lo, explore.hi) for th in starts],
                   workers if explore is not design else 1)
    out, out_cost = best, design.cost(best)
    # the cheapest start at each frequency: ranked unpolished, with the effects' parameters of a fit in a wrong
    # basin, the starts near the plant's resonance can lose to others that polish elsewhere (hysteresis + second
    # creep 3-10x seed 47: the two cheapest went to 1.066x the noise; each start at 50 Hz, 47.8 Hz in the plant,
    # reaches 0.988x in 0.3-0.6 s)
    per = len(starts) // len(kept)
    picks = [int(i) for i in np.argsort(costs)[:2]]
    for f in range(len(fns)):
        cell = [i for i in range(per) if (i // len(RESTART_ZETAS)) % len(fns) == f]
        g = min(cell, key=lambda i: costs[i])
        if g not in picks:
            picks.append(g)
    for j in range(1, len(kept)):
        # each exchanged set gets its own polish: ranked with the rest, the grid around the fit it left
        # always costs less (second_creep 10-100x seed 95: the best exchanged start ranked 12th of 144,
        # unpolished; polished, it reaches 1.0x the noise from 22.6x)
        g = j * per + int(np.argmin(costs[j * per:(j + 1) * per]))
        if g not in picks:
            picks.append(g)
    for th, c in _polished_apart(explore, design, [starts[i] for i in picks], max_nfev, workers):
        if c < out_cost:
            out, out_cost = th, c
    return out


def _polished_apart(explore: Design, design: Design, starts: list[np.ndarray], max_nfev: int,
                    workers: int) -> list[tuple[np.ndarray, float]]:
    """(polished parameters, cost on the record) of the starts that reach the record, in order; on ``workers``
    threads.

    Where the exploration window is the record, every start is polished (``_polish``) and returned. On a long
    record every start is polished on the window, and only the one that ends lowest there gets the final
    polish on the whole record (``_on_the_record``): the window ranks the starts as it ranks them everywhere
    else in a fit, and the record's evaluations, 5-8x the window's each, go to the one start that can win.
    Each polish runs on its own copies of the designs (as ``_short_polishes``, whatever the threads: a copy
    only misses remembered solutions, which are exact reuse), and their evaluations of the record are added
    to ``design``'s count in the starts' order, so neither the parameters nor the count the fit reports
    depend on the threads.
    """
    if explore is not design:
        done = list(ordered_map(lambda theta: _optimise(explore.copy(), theta, max_nfev), starts, workers))
        return [_on_the_record(explore, design, done)] if done else []

    def one(theta: np.ndarray) -> tuple[np.ndarray, float, int]:
        whole = design.copy()
        th = _polish(whole, whole, theta, max_nfev)
        return th, whole.cost(th), whole.nfev
    done = list(ordered_map(one, starts, workers))
    design.nfev += sum(count for _, _, count in done)
    return [(th, c) for th, c, _ in done]


def _on_the_record(explore: Design, design: Design, polished: list[np.ndarray]) -> tuple[np.ndarray, float]:
    """The window-polished parameters that cost least on the window, given the final polish on the whole record
    (``FULL_NFEV``, as ``_polish``): (parameters, cost on the record)."""
    costs = [explore.cost(th) for th in polished]
    th = _optimise(design, polished[int(np.argmin(costs))], FULL_NFEV, FULL_TOL, FULL_FTOL)
    return th, design.cost(th)


def _polish(explore: Design, design: Design, theta: np.ndarray, max_nfev: int) -> np.ndarray:
    """A full polish from ``theta`` on the exploration window (``Design.explored``), then, where that window is
    not the record, the final polish's few evaluations on the whole record (``FULL_NFEV``)."""
    th = _optimise(explore, theta, max_nfev)
    return th if explore is design else _optimise(design, th, FULL_NFEV, FULL_TOL, FULL_FTOL)


def _polished_starts(design: Design, polished: list[np.ndarray]) -> list[np.ndarray]:
    """The effects' further starts from short-polished ones (``Effect.polished_starts``), inside the bounds."""
    out = []
    for th in polished:
        for e in design.effects:
            out += [np.clip(v, design.lo, design.hi)
                    for v in get_effect(e).polished_starts(th, design.own_indices(e), design.data)]
    return out


def _swapped(design: Design, theta: np.ndarray) -> list[np.ndarray]:
    """``theta`` with each effect's parameters exchanged with the base parameters they mirror (if any)."""
    out = []
    for e in design.effects:
        v = get_effect(e).swapped(theta, design.own_indices(e))
        if v is not None:
            out.append(np.clip(v, design.lo, design.hi))
    return out


# --------------------------------------------------------------------------- refit a model
@single_threaded
def refit(model: ExtendedModel, t: np.ndarray, u: np.ndarray, y: np.ndarray) -> ExtendedFit:
    """Refit ``model``'s structure (base + its effects) to a record, warm-started from its base."""
    data = prepare(t, u, y)
    base = fit_base(data, start=model.base)
    return fit_extended(data, tuple(model.effects), base)


def check_effects(names: str | list[str]) -> tuple[str, ...]:
    """Parse 'a,b' into effect names; ModelError naming the unknown ones (or none named) and the catalogue."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    check_effect_names(names)
    if not names:
        raise ModelError("no effect named; the catalogue is " + ", ".join(effect_names()))
    return tuple(dict.fromkeys(names))


__all__ = ["Prepared", "prepare", "Design", "ExtendedFit", "ExtendedModel", "fit_base", "fit_extended",
           "refit", "with_effects", "check_effects", "DataError"]
