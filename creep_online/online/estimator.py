"""The online estimator: the paper's two-layer scheme (Remark 2, Figure 2) on a live stream.

Phases (``OnlineEstimate.phase``):

``buffering``
    Samples are kept until ``t_c`` seconds after the first input change (the
    output level before it is taken as the sensor offset).
``resonance_fit``
    Layer 2 (a1, a2, b with ``alpha0`` fixed) runs as a resumable job
    (``layer2.Layer2Job``), a slice of at most ``budget_us`` per ``update()``.
    With ``t_c=None`` the job also chooses t_c (1.5 settling times of the fitted
    resonance) and buffers longer if needed. When it ends, the tracker replays
    the buffer exactly (again in slices) and takes over: nothing is lost.
``tracking``
    Layer 1 on a sliding window: the statistics of the SOE state vector
    (``kernels``; exponential forgetting with time constant ``window_s``)
    give the *exact* windowed output-error cost for any alpha, so every
    ``update_every_s`` a few Gauss-Newton steps re-fit (alpha, b) over the whole
    window (the paper's Remark 3, "recompute over the window", at O(P^2) per
    sample instead of O(window x memory)); then the eq. 12 retune is tried and
    kept only if it lowers the windowed cost. ``remark3="carry_on"`` instead
    runs a recursive prediction-error update that never re-evaluates the past.

Guard rails: non-finite samples are skipped and counted; every reported number
is finite; a fit that leaves the bounds, fails, or worsens the live prediction
error is rejected and the last good estimate is kept (``quality="degraded"``,
``divergences`` counts them); the forgetting stops where the window holds too
little information (anti-windup).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ..errors import DataError
from ..model import CreepModel
from . import kernels as K
from .layer2 import Layer2Job, Layer2Result
from .soe import DEFAULT_DX, DEFAULT_HORIZON_S, SoeBasis, pack_coefficients

PHASES = ("buffering", "resonance_fit", "tracking")
#: Relative alpha change since the last layer-2 fit above which a refresh restarts from the grid.
FRESH_REFRESH = 0.3
QUALITIES = ("none", "provisional", "good", "degraded")

#: Default creep exponent guessed for layer 2 (the paper's stage: ~0.01-0.07).
DEFAULT_ALPHA0 = 0.05
#: Largest layer-2 buffer (samples): bounds memory and the duration of the fit.
MAX_LAYER2_SAMPLES = 1 << 15
#: Longest history (samples since the first input change) kept for exact rebuilds after a layer-2 refresh.
MAX_HISTORY = 1 << 18
#: At most this many layer-2 refreshes (alternating with layer 1 until alpha stops moving).
MAX_REFRESH = 3
#: Node above which the SOE lumps the fast modes into a direct term (units 1/h).
SOE_TOP = 3000.0


@dataclass
class OnlineEstimate:
    """The estimator's current answer. Every number is finite."""

    alpha: float
    a1: float
    a2: float
    b: float
    phase: str
    quality: str
    uncertainty: dict = field(default_factory=dict)
    t: float = 0.0
    samples: int = 0
    t_c: float = 0.0
    fn_hz: float = 0.0
    zeta: float = 0.0
    offset: float = 0.0
    skipped: int = 0
    alpha_updates: int = 0
    divergences: int = 0

    def to_dict(self) -> dict:
        """JSON-ready dict (DESIGN.md section 6 keys first)."""
        return asdict(self)


class OnlineEstimator:
    """Fractional creep model b / (s^alpha (1 + a1 s + a2 s^2)) identified sample by sample.

    Parameters (scikit-learn style; defaults from the measurements in docs/online.md):

    dt:             sampling step (s) of the stream.
    t_c:            end of the resonance transient after the first input change (s);
                    None chooses it from the layer-2 fit (1.5 settling times).
    alpha0:         alpha guessed for layer 2.
    window_s:       time constant (s) of the exponential forgetting of layer 1 (default 10 s:
                    follows a 20 %/60 s alpha drift to ~3.5 % and costs ~5 % of accuracy on a
                    stationary plant); None keeps everything since t_c (growing window).
    update_every_s: how often layer 1 re-fits alpha and b (s); default 0.05 s (at least 20 samples).
    memory:         "soe" (full memory, sum of exponentials; the only memory the
                    exact window re-fit needs).
    remark3:        "recompute" (exact re-fit over the window, default) or "carry_on".
    horizon_s:      memory horizon for which the SOE accuracy is guaranteed.
    budget_us:      work per update() spent on the layer-2 job and the replay.
    retune:         try the eq. 12 retune after each layer-1 fit.
    alpha_bounds:   search interval of alpha.
    t_c_max:        upper limit of the automatic t_c (s).
    layer1_from:    "record": layer-1 statistics from the first input change (the model is
                    exact in the transient too, so it carries alpha information; 4x smaller
                    alpha scatter at t_c + 5 s on the load cell), "t_c": the paper's creep
                    regime only.
    """

    def __init__(self, dt: float, *, t_c: float | None = None, alpha0: float = DEFAULT_ALPHA0,
                 window_s: float | None = 10.0, update_every_s: float = 0.05, memory: str = "soe",
                 remark3: str = "recompute", horizon_s: float = DEFAULT_HORIZON_S,
                 soe_dx: float = DEFAULT_DX, budget_us: float = 60.0, retune: bool = True,
                 alpha_bounds: tuple[float, float] = (1e-3, 0.99), t_c_max: float = 10.0,
                 layer1_from: str = "record") -> None:
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise DataError(f"dt must be a positive finite number of seconds, got {dt!r}")
        if t_c is not None and not (math.isfinite(t_c) and t_c > 0):
            raise DataError(f"t_c must be > 0 s or None, got {t_c!r}")
        if not 0.0 < alpha0 < 1.0:
            raise DataError(f"alpha0 must satisfy 0 < alpha0 < 1, got {alpha0!r}")
        if window_s is not None and not window_s > 0:
            raise DataError(f"window_s must be > 0 s or None, got {window_s!r}")
        if memory != "soe":
            raise DataError(f"memory must be 'soe' (got {memory!r}); truncated memory is measured in "
                            "bench/bench_online.py and loses creep (docs/online.md)")
        if layer1_from not in ("record", "t_c"):
            raise DataError(f"layer1_from must be 'record' or 't_c', got {layer1_from!r}")
        if remark3 not in ("recompute", "carry_on"):
            raise DataError(f"remark3 must be 'recompute' or 'carry_on', got {remark3!r}")
        self.dt = float(dt)
        self.t_c = t_c
        self.alpha0 = float(alpha0)
        self.window_s = window_s
        self.update_every = max(20, int(round(update_every_s / self.dt)))
        self.memory = memory
        self.remark3 = remark3
        self.horizon_s = float(horizon_s)
        self.budget_s = budget_us * 1e-6
        self.retune = retune
        self.alpha_bounds = (float(alpha_bounds[0]), float(alpha_bounds[1]))
        self.t_c_max = float(t_c_max)
        self.layer1_from = layer1_from
        self.basis = SoeBasis.build(self.dt, horizon_s=self.horizon_s, dx=soe_dx, top=SOE_TOP)
        _warm_kernels()
        self.reset()

    # ------------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        """Forget everything: back to buffering, counters to zero."""
        self.samples = 0
        self.skipped_nonfinite = 0
        self.gaps = 0
        self._last_u = 0.0
        self.alpha_updates = 0
        self.divergences = 0
        self.retunes_kept = 0
        self.frozen = False
        self._phase = "buffering"
        self._quality = "none"
        self._alpha = self.alpha0
        self._a1 = self._a2 = self._b = 0.0
        self._std: dict[str, float] = {}
        self._model: CreepModel | None = None
        self._last_good: tuple[float, float] | None = None
        self._offset = 0.0
        self._pre_sum = 0.0
        self._pre_n = 0
        self._start: int | None = None      # sample index of the first input change
        self._bu: list[float] = []
        self._by: list[float] = []
        self._tc_used = self.t_c if self.t_c is not None else 0.0
        self._tc_target = self.t_c if self.t_c is not None else max(0.05, 200 * self.dt)
        self._tc_rounds = 0
        self._job: Layer2Job | None = None
        self._replay = 0                     # buffered samples already replayed into the tracker
        self._l2: Layer2Result | None = None
        self._l2_samples = 0
        self._l2_data: tuple[np.ndarray, np.ndarray] | None = None
        self._l2_alpha = self.alpha0
        self._refresh: Layer2Job | None = None
        self.refreshes = 0
        self._bad_streak = 0
        self._blocking = False
        self._keep_hist = self.remark3 == "recompute"
        self._rebuilding = False
        self._hist_u: list[float] = []
        self._hist_y: list[float] = []
        self._last_pred: float | None = None
        self._init_tracker_arrays()

    def freeze(self) -> None:
        """Stop adapting: samples still update the states and predictions, the estimate stays."""
        self.frozen = True

    def unfreeze(self) -> None:
        """Resume adapting."""
        self.frozen = False

    def _init_tracker_arrays(self) -> None:
        p = self.basis.size + 2
        self._st = np.zeros(p)
        self._S = np.zeros((p, p))
        self._sy = np.zeros(p)
        self._sc = np.zeros(K.SC_SIZE)
        self._avg = np.zeros(p)
        self._avg_c: np.ndarray | None = None
        self._y_c = 0.0
        self._v = np.zeros(p)
        self._dv = np.zeros(p)
        self._co = np.zeros(2 * self.basis.size + 6)
        self._sc[K.SC_G] = 1.0
        self._sc[K.SC_FORGET] = 1.0 if self.window_s is None else math.exp(-self.dt / self.window_s)
        self._sc[K.SC_MON] = min(1.0, self.dt / 0.2)      # 0.2 s monitor of the live error
        self._sc[K.SC_AVGK] = min(1.0, self.dt / 0.05)    # 50 ms averages for eq. 12
        self._theta = np.zeros(2)
        self._P = np.eye(2)
        self._counter = np.zeros(1, dtype=np.int64)
        self._pmax = 1e6
        self._tracked = 0          # samples fed to the tracker since the record start
        self._i_c = 0              # record index where layer-1 statistics start (t_c)
        self._next_update = 0
        self._good_e2 = math.inf

    # ------------------------------------------------------------------ public API
    @property
    def phase(self) -> str:
        return "tracking" if self._rebuilding else self._phase

    @property
    def model(self) -> CreepModel | None:
        """The current model (None until layer 2 has produced one)."""
        return self._model

    @property
    def last_prediction(self) -> float | None:
        """Model output (offset included) for the latest sample; None before a model exists."""
        return self._last_pred

    @property
    def estimate(self) -> OnlineEstimate:
        m = self._model
        return OnlineEstimate(
            alpha=_finite(self._alpha), a1=_finite(self._a1), a2=_finite(self._a2), b=_finite(self._b),
            phase=self.phase, quality=self._quality,
            uncertainty={k: _finite(v, math.inf) for k, v in self._std.items()},
            t=self.samples * self.dt, samples=self.samples, t_c=_finite(self._tc_used),
            fn_hz=m.fn if m else 0.0, zeta=m.zeta if m else 0.0, offset=_finite(self._offset),
            skipped=self.skipped_nonfinite, alpha_updates=self.alpha_updates,
            divergences=self.divergences)

    def predict_one(self, u: float) -> float | None:
        """Model output at the next sample if u is applied now (no state change); None without a model."""
        if self._phase != "tracking" or self._model is None:
            return None
        return float(K.predict_next(float(u), self._st, self._co, self._v)) + self._offset

    def learn_one(self, u: float, y: float) -> "OnlineEstimator":
        """river-style alias of update()."""
        self.update(u, y)
        return self

    def update(self, u: float, y: float) -> None:
        """Feed one sample. Bounded work: never waits for the layer-2 fit."""
        u = float(u)
        y = float(y)
        if not (math.isfinite(u) and math.isfinite(y)):
            self.skipped_nonfinite += 1
            return
        n = self.samples
        self.samples = n + 1
        self._last_u = u
        if self._start is None:
            if u == 0.0:
                self._pre_sum += y
                self._pre_n += 1
                return
            self._begin(n)
        if self._phase == "tracking" and self._replay_done():
            if self._keep_hist:
                self._remember(u, y)
            y0 = y - self._offset
            if self.remark3 == "carry_on":
                self._advance(np.array([u]), np.array([y0]))
                return
            acc = self._tracked >= self._i_c
            pred = K.track_one(u, y0, self._st, self._co, self._v, self._S, self._sy, self._sc,
                               self._avg, acc)
            self._last_pred = pred + self._offset
            self._tracked += 1
            if self._tracked == self._next_update:
                self._alpha_update()
            elif self._refresh is not None:
                self._run_refresh(self.budget_s)
                if self._phase != "tracking":
                    self._work(self.budget_s)
            return
        self._bu.append(u)
        self._by.append(y)
        self._work(self.budget_s)

    def update_block(self, u: np.ndarray, y: np.ndarray) -> None:
        """Feed many samples (same semantics as repeated update(), much faster)."""
        u = np.asarray(u, dtype=float).ravel()
        y = np.asarray(y, dtype=float).ravel()
        if u.shape != y.shape:
            raise DataError(f"u and y differ in length ({u.size} vs {y.size})")
        self._blocking = True
        try:
            self._update_block(u, y)
        finally:
            self._blocking = False

    def gap(self, count: int = 1) -> None:
        """``count`` samples were lost (sequence gap): time advances with the input held, no output used."""
        count = int(count)
        if count <= 0:
            return
        self.gaps += count
        if self._start is None:
            self.samples += count
            return
        u = np.full(count, self._last_u)
        y = np.full(count, np.nan)
        self._blocking = True
        try:
            self._update_block(u, y, allow_nan_output=True)
        finally:
            self._blocking = False

    def _update_block(self, u: np.ndarray, y: np.ndarray, allow_nan_output: bool = False) -> None:
        ok = np.isfinite(u) & (allow_nan_output | np.isfinite(y))
        bad = int(u.size - np.count_nonzero(ok))
        if bad:
            self.skipped_nonfinite += bad
            u, y = u[ok], y[ok]
        if u.size:
            self._last_u = float(u[-1])
        i = 0
        while i < u.size and self._start is None:
            nz = np.flatnonzero(u[i:] != 0.0)
            stop = u.size if nz.size == 0 else i + int(nz[0])
            self._pre_sum += float(np.nansum(y[i:stop]))
            self._pre_n += int(np.count_nonzero(np.isfinite(y[i:stop])))
            self.samples += stop - i
            i = stop
            if i < u.size:
                self._begin(self.samples)
        if i >= u.size:
            return
        chunk = 1 << 16
        while i < u.size:
            if self._phase == "tracking" and self._replay_done():
                self.samples += u.size - i
                if self._keep_hist:
                    self._remember_block(u[i:], y[i:])
                self._advance(np.ascontiguousarray(u[i:]), np.ascontiguousarray(y[i:] - self._offset))
                return
            stop = min(u.size, i + chunk)
            self.samples += stop - i
            self._bu.extend(u[i:stop].tolist())
            self._by.extend(y[i:stop].tolist())
            self._work(math.inf)
            i = stop

    # ------------------------------------------------------------------ phase machinery
    def _begin(self, n: int) -> None:
        """First input change at sample n: fix the offset and start the record."""
        self._start = n
        self._offset = self._pre_sum / self._pre_n if self._pre_n >= 5 else 0.0

    def _replay_done(self) -> bool:
        return self._replay >= len(self._bu)

    def _work(self, budget: float) -> None:
        """Advance the phase machine by at most ``budget`` seconds of work (inf: to completion)."""
        deadline = time.perf_counter() + budget
        while True:
            if self._phase == "buffering":
                need = int(math.ceil(self._tc_target / self.dt))
                if len(self._bu) < need:
                    return
                self._start_layer2(min(need, MAX_LAYER2_SAMPLES))
            elif self._phase == "resonance_fit":
                if self._job is not None:
                    if self._job.step():
                        self._layer2_done()
                else:   # replaying the buffer into the tracker
                    self._replay_chunk(deadline)
                    if self._replay_done():
                        self._finish_replay()
                        if self._refresh is not None and budget == math.inf:
                            self._run_refresh(math.inf)
                        if self._phase == "tracking":
                            return
            else:
                return
            if time.perf_counter() >= deadline:
                return

    def _finish_replay(self) -> None:
        """The tracker has caught up: the buffer becomes the history (kept for a rebuild) or is dropped."""
        if self._keep_hist and len(self._bu) <= MAX_HISTORY and self.refreshes < MAX_REFRESH:
            self._hist_u, self._hist_y = self._bu, self._by
        else:
            self._drop_history()
        self._bu = []
        self._by = []
        self._replay = 0
        self._phase = "tracking"
        self._rebuilding = False

    def _drop_history(self) -> None:
        self._keep_hist = False
        self._hist_u = []
        self._hist_y = []

    def _remember(self, u: float, y: float) -> None:
        self._hist_u.append(u)
        self._hist_y.append(y)
        if len(self._hist_u) > MAX_HISTORY:
            self._drop_history()

    def _remember_block(self, u: np.ndarray, y: np.ndarray) -> None:
        if len(self._hist_u) + u.size > MAX_HISTORY:
            self._drop_history()
            return
        self._hist_u.extend(u.tolist())
        self._hist_y.extend(y.tolist())

    def _start_layer2(self, n: int) -> None:
        u = np.asarray(self._bu[:n])
        y = np.asarray(self._by[:n]) - self._offset
        start = None if self._l2 is None else (self._l2.a1, self._l2.a2)
        self._job = Layer2Job(self.basis, u, y, self.alpha0, start=start)
        self._l2_samples = n
        self._l2_data = (u, y)
        self._tc_used = n * self.dt
        self._phase = "resonance_fit"

    def _layer2_done(self) -> None:
        res = self._job.result
        self._job = None
        self._l2 = res
        if self.t_c is None and self._tc_rounds < 4:
            try:
                settle = CreepModel(self.alpha0, res.a1, res.a2, res.b or 1.0).settling_time
            except Exception:
                settle = self._tc_used
            want = float(np.clip(1.5 * settle, 20 * self.dt, self.t_c_max))
            if want > 1.05 * self._tc_used and self._tc_used < MAX_LAYER2_SAMPLES * self.dt * 0.99:
                self._tc_rounds += 1
                self._tc_target = want
                self._phase = "buffering"
                return
        self._a1, self._a2, self._b, self._alpha = res.a1, res.a2, res.b, self.alpha0
        self._set_model(self.alpha0, res.b)
        self._std = {"alpha": math.inf, **res.std}
        self._quality = "provisional"
        self._start_tracker()

    def _start_tracker(self) -> None:
        """Fresh tracker for the current (a1, a2); the buffer is replayed into it from sample 0."""
        self._init_tracker_arrays()
        self._co = pack_coefficients(self.basis, self._a1, self._a2)
        K.model_coefficients(self._alpha, self.basis.lam, self.basis.dx, self._a1, self._a2, self._v, self._dv)
        self._v *= self._b
        self._theta[:] = (self._alpha, self._b)
        noise2 = max(self._l2.cost / max(self._l2_samples, 1), 1e-30) if self._l2 else 1.0
        self._P[:] = np.diag([0.02**2, (0.1 * self._b) ** 2 + 1e-30]) / noise2
        self._pmax = 100.0 * float(np.trace(self._P))
        self._i_c = 0 if self.layer1_from == "record" else int(round(self._tc_used / self.dt))
        self._next_update = self._i_c + self.update_every
        self._replay = 0

    def _replay_chunk(self, deadline: float) -> None:
        chunk = 64
        while self._replay < len(self._bu):
            i0 = self._replay
            i1 = min(i0 + chunk, len(self._bu))
            u = np.asarray(self._bu[i0:i1])
            y = np.asarray(self._by[i0:i1]) - self._offset
            self._advance(u, y)
            self._replay = i1
            if time.perf_counter() >= deadline:
                return

    def _advance(self, u: np.ndarray, y: np.ndarray) -> None:
        """Tracker over a block of (offset-free) samples, splitting at t_c and at the alpha updates."""
        i = 0
        n = u.size
        none = np.empty(0)
        while i < n:
            pos = self._tracked
            if pos < self._i_c:
                stop = min(n, i + self._i_c - pos)
                acc = False
            else:
                stop = min(n, i + self._next_update - pos)
                acc = True
            if self.remark3 == "carry_on" and acc:
                th_before = self._theta.copy()
                K.rpem_block(u[i:stop], y[i:stop], self._st, self._co, self.basis.lam, self.basis.dx,
                             self._a1, self._a2, self._theta, self._P, float(self._sc[K.SC_FORGET]),
                             self.alpha_bounds[0], self.alpha_bounds[1], 16, self._counter, self._pmax)
                if self.frozen:
                    self._theta[:] = th_before
            else:
                K.track_block(u[i:stop], y[i:stop], self._st, self._co, self._v, self._S, self._sy,
                              self._sc, self._avg, acc, none)
            self._tracked += stop - i
            i = stop
            if acc and self._tracked == self._next_update:
                self._alpha_update()
            if self._refresh is not None and self._phase == "tracking" and self._replay_done():
                self._run_refresh(math.inf if self._blocking else self.budget_s)
                if self._phase != "tracking":     # rebuilding: the history (this block included) is replayed
                    self._work(math.inf if self._blocking else self.budget_s)
                    return
        if self.remark3 != "carry_on":
            self._last_pred = float(self._sc[K.SC_LAST]) + self._offset

    # ------------------------------------------------------------------ layer 1 + guards
    def _alpha_update(self) -> None:
        """Layer 1 over the window (Gauss-Newton on exact statistics), eq. 12 retune, guards."""
        self._next_update = self._tracked + self.update_every
        if self._avg_c is None:
            self._avg_c = self._avg.copy()
            self._y_c = float(self._sc[K.SC_YAVG])
        if self.frozen:
            return
        lo, hi = self.alpha_bounds
        if self.remark3 == "carry_on":
            alpha, b = float(self._theta[0]), float(self._theta[1])
            var_a = float(self._P[0, 0]) * float(self._sc[K.SC_E2])
            var_b = float(self._P[1, 1]) * float(self._sc[K.SC_E2])
            ok = True
            cost = float(self._sc[K.SC_E2])
        else:
            out = np.empty(8)
            K.gauss_newton_alpha(self._alpha, self._b, self._S, self._sy, float(self._sc[K.SC_SYY]),
                                 self.basis.lam, self.basis.dx, self._a1, self._a2, lo, hi, 6, out)
            alpha, b, cost = float(out[0]), float(out[1]), float(out[2])
            neff = float(self._sc[K.SC_NEFF])
            sigma2 = max(cost, 0.0) / max(neff - 2.0, 1.0)
            var_a, var_b = sigma2 * out[3], sigma2 * out[4]
            ok = bool(out[7]) and math.isfinite(alpha) and math.isfinite(b) and b != 0.0
            if ok and self.retune:
                alpha, b, cost = self._eq12(alpha, b, cost)
        self.alpha_updates += 1
        if not ok or not (lo < alpha < hi) or not math.isfinite(var_a) or b == 0.0:
            self._diverged()
            return
        self._alpha, self._b = alpha, b
        self._set_model(alpha, b)
        if self.remark3 != "carry_on":
            K.model_coefficients(alpha, self.basis.lam, self.basis.dx, self._a1, self._a2, self._v, self._dv)
            self._v *= b
        std_a, std_b = math.sqrt(max(var_a, 0.0)), math.sqrt(max(var_b, 0.0))
        self._std = {**self._std, "alpha": std_a, "b": std_b}
        if self.remark3 == "recompute":   # window cost per effective sample, in true scale
            resid2 = cost / (float(self._sc[K.SC_G]) * max(float(self._sc[K.SC_NEFF]), 1.0))
        else:
            resid2 = cost
        self._judge(std_a, resid2)
        if (self._quality == "good" and self.refreshes < MAX_REFRESH and self._refresh is None
                and self._l2_data is not None and abs(self._alpha / self._l2_alpha - 1.0) > 0.01
                and (self.refreshes == 0 or self._keep_hist)):
            u, y = self._l2_data
            # far from the alpha layer 2 used, its resonance may be a wrong local fit: search afresh
            fresh = abs(self._alpha / self._l2_alpha - 1.0) > FRESH_REFRESH
            self._refresh = Layer2Job(self.basis, u, y, self._alpha,
                                      start=None if fresh else (self._a1, self._a2))

    def _run_refresh(self, budget: float) -> None:
        """Layer 2 again with the tracked alpha (the guess alpha0 biases a1, a2); swapped in whole."""
        deadline = time.perf_counter() + budget
        while not self._refresh.step():
            if time.perf_counter() >= deadline:
                return
        res = self._refresh.result
        self._refresh = None
        self.refreshes += 1
        self._l2_alpha = self._alpha
        if not (math.isfinite(res.a1) and math.isfinite(res.a2) and res.a1 > 0 and res.a2 > 0):
            return
        self._a1, self._a2 = res.a1, res.a2
        self._std = {**self._std, "a1": res.std["a1"], "a2": res.std["a2"]}
        if self._keep_hist and self.remark3 == "recompute":
            # rebuild the tracker exactly for the new resonance: replay the whole history
            self._bu, self._by = self._hist_u, self._hist_y
            self._hist_u, self._hist_y = [], []
            self._start_tracker()
            self._phase = "resonance_fit"
            self._rebuilding = True
            self._set_model(self._alpha, self._b)
            return
        self._co[:] = pack_coefficients(self.basis, self._a1, self._a2)
        K.model_coefficients(self._alpha, self.basis.lam, self.basis.dx, self._a1, self._a2, self._v, self._dv)
        self._v *= self._b
        self._set_model(self._alpha, self._b)

    def _eq12(self, alpha: float, b: float, cost: float) -> tuple[float, float, float]:
        """Eq. 12: alpha *= (y*_f - y*_c) / (y_hat_f - y_hat_c); kept only if the window cost drops."""
        v = np.empty_like(self._v)
        dv = np.empty_like(self._v)
        K.model_coefficients(alpha, self.basis.lam, self.basis.dx, self._a1, self._a2, v, dv)
        den = b * float((self._avg - self._avg_c) @ v)
        num = float(self._sc[K.SC_YAVG]) - self._y_c
        if den == 0.0 or not math.isfinite(num / den):
            return alpha, b, cost
        cand = alpha * num / den
        lo, hi = self.alpha_bounds
        if not lo < cand < hi:
            return alpha, b, cost
        j, b2 = K.window_cost(cand, self._S, self._sy, float(self._sc[K.SC_SYY]), self.basis.lam,
                              self.basis.dx, self._a1, self._a2)
        if j < cost and b2 != 0.0:
            self.retunes_kept += 1
            return cand, float(b2), float(j)
        return alpha, b, cost

    def _judge(self, std_alpha: float, resid2: float) -> None:
        """Quality flag from the alpha uncertainty; fall back when the window's mean squared residual jumps.

        ``resid2`` is the window cost per effective sample (exact, from the
        statistics): it stays put through input steps, unlike the live error,
        and jumps on outliers or a model that no longer fits.
        """
        if self._last_good is not None and resid2 > 25.0 * self._good_e2:
            self._bad_streak += 1
            if self._bad_streak < 20:   # after 20 in a row the plant has changed: accept
                self._diverged()
                return
        self._bad_streak = 0
        rel = std_alpha / max(abs(self._alpha), 1e-12)
        self._quality = "good" if rel < 0.05 else "provisional"
        self._last_good = (self._alpha, self._b)
        self._good_e2 = min(self._good_e2 * 1.5, resid2) if math.isfinite(self._good_e2) else resid2
        self._good_e2 = max(self._good_e2, 1e-300)

    def _diverged(self) -> None:
        """Reject the new estimate: back to the last good one (or the layer-2 start)."""
        self.divergences += 1
        self._quality = "degraded"
        alpha, b = self._last_good if self._last_good is not None else (self.alpha0, self._l2.b)
        self._alpha, self._b = alpha, b
        self._theta[:] = (alpha, b)
        self._set_model(alpha, b)
        K.model_coefficients(alpha, self.basis.lam, self.basis.dx, self._a1, self._a2, self._v, self._dv)
        self._v *= b

    def _set_model(self, alpha: float, b: float) -> None:
        try:
            self._model = CreepModel(alpha, self._a1, self._a2, b)
        except Exception:
            pass

    # ------------------------------------------------------------------ helpers for tests / bench
    def window_cost(self, alpha: float) -> tuple[float, float]:
        """(J, b) of the current window for this alpha (exact, gain projected out)."""
        return K.window_cost(alpha, self._S, self._sy, float(self._sc[K.SC_SYY]), self.basis.lam,
                             self.basis.dx, self._a1, self._a2)


_WARM = False


def _warm_kernels() -> None:
    """Call every kernel once on tiny data so that no update() pays numba's load/compile time."""
    global _WARM
    if _WARM:
        return
    basis = SoeBasis.build(1e-3, horizon_s=1.0, dx=1.0, top=10.0)
    u = np.ones(64)
    y = np.ones(64)
    est = OnlineEstimator.__new__(OnlineEstimator)
    _WARM = True
    p = basis.size + 2
    v, dv = np.zeros(p), np.zeros(p)
    K.model_coefficients(0.1, basis.lam, basis.dx, 1e-3, 1e-6, v, dv)
    co = pack_coefficients(basis, 1e-3, 1e-6)
    st, S, sy, sc, avg = np.zeros(p), np.zeros((p, p)), np.zeros(p), np.zeros(K.SC_SIZE), np.zeros(p)
    sc[K.SC_G] = sc[K.SC_FORGET] = 1.0
    K.track_block(u, y, st, co, v, S, sy, sc, avg, True, np.empty(0))
    K.track_one(1.0, 1.0, st, co, v, S, sy, sc, avg, True)
    K.predict_next(1.0, st, co, v)
    K.window_cost(0.1, S, sy, 1.0, basis.lam, basis.dx, 1e-3, 1e-6)
    K.gauss_newton_alpha(0.1, 1.0, S, sy, 1.0, basis.lam, basis.dx, 1e-3, 1e-6, 1e-3, 0.99, 1, np.zeros(8))
    K.rpem_block(u, y, st, co, basis.lam, basis.dx, 1e-3, 1e-6, np.array([0.1, 1.0]), np.eye(2), 1.0,
                 1e-3, 0.99, 16, np.zeros(1, dtype=np.int64), 1e6)
    Layer2Job(basis, u, y, 0.1, start=(1e-3, 1e-6), max_iter=1).run()
    del est


def _finite(x: float, default: float = 0.0) -> float:
    x = float(x)
    return x if math.isfinite(x) else default
