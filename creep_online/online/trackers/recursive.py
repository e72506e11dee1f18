"""The recursive tracker (Remark 3, "carry on with the newest estimate"): a Gauss-Newton RPEM, no replay.

docs/online.md, "Remark 3: window vs recursive": the fractional recursion depends on alpha, so when
alpha (or the resonance) changes one either recomputes over the window
(``tracker.WindowTracker``) or carries on with the newest estimate. This module
is the second strategy. It uses the window tracker's regressor ``phi``
(``window.py``: SOE nodes of the input, the resonance states ``x`` at a
linearization point ``(a1l, a2l)`` with their a1/a2 sensitivity states, the
offset, the free responses) and its coefficient maps, but instead of
statistics and re-fits it runs a recursive prediction-error method on

    theta = [alpha, ln a1, ln a2, b, offset, free-response weights...]

Per sample, in one numba call (``sample``), at a constant cost:

1. prediction ``phi . m`` and its gradient ``psi = C^T phi`` (``C`` the
   Jacobian coefficients of ``window.jacobian_coefficients``: the output error's
   exact gradient, through the sensitivity states for a1 and a2 and the analytic
   SOE-weight derivative for alpha);
2. the shared output gate and monitors (``window.gate``: outliers, stuck output);
3. the Gauss-Newton / Kalman form of the update with exponential forgetting
   ``lambda = 1 - dt/window_s``: ``K = P psi / (psi' P psi + s^2)``,
   ``theta += K e``, ``P = (P - K psi' P) / lambda``, with ``s`` the robust
   innovation scale; the model coefficients follow to first order,
   ``m += C dtheta`` (exact in the linear parameters);
4. bounded forgetting: ``P`` is divided by lambda only while
   ``trace(P / P_reset) < n``, so a direction the input stops exciting does
   not wind up (its variance stops at its reset prior);
5. change detection, a generalised likelihood-ratio test for a jump of the
   parameters (Willsky-Jones) on the normalised innovations: over blocks of
   ``block_s`` the score ``z = sum psi e / s^2`` and the information
   ``I = sum psi psi' / s^2`` are accumulated (n^2 per sample); every
   ``check_s`` ``LR = z' I^-1 z`` (chi-square with n degrees of freedom under no
   change) and the jump estimate ``I^-1 z``. A change is declared when LR
   exceeds its threshold and jump factor times the median of the recent blocks (a
   model that is slightly off raises the statistic evenly, a change makes it
   jump) and the jump moves a1, a2 or b by more than the rule's ``move`` and
   ``CHANGE_SIGMAS`` of its own sigma. Then the estimate restarts from the
   block's start (before the change; alpha held: creep does not jump with a
   payload), the covariance is reset in the directions that jumped, and flag 8
   makes the Python side record an event;
6. every ``refresh_s`` (1 ms), if theta moved more than the refresh tolerances
   since the last refresh: the linearization point moves to the current
   resonance and the states are carried on to first order,
   ``x(a_new) = x(a_old) + dx/da1 (a1 - a1l) + dx/da2 (a2 - a2l)``
   (measured against the exact simulator: for a 0.5 % move it removes 91 % of
   the prediction jump; the sensitivity states grow with the cycles rung since
   the last input step, hence small, frequent moves; the rest decays with the
   resonance's settling time, the states being stable filters of the input); the
   resonance step, ``C`` and ``m`` are recomputed exactly (a few us, inside
   the same numba call).

Python runs on the sample path only at an alarm (to record the event) and
then every ``refit_every`` samples until the event has settled: in settled
tracking ``update()`` is the numba call and nothing else (a Python slow path
once every 1000 samples, measured, cost 30-70 us there with cold caches).
The fit (``fit``: 1-sigma from ``P``, an absolute covariance because the gain
uses the innovation variance) is built when the estimate is read. Drift: with
forgetting the estimate follows slow drift by itself (lagging by about rate x
window_s); ``b_rate`` and ``alpha_rate`` are 0. Measured against the window
tracker: docs/online.md, "Remark 3: window vs recursive".
"""
from __future__ import annotations

import math

import numpy as np

from .._kernels import window as W
from .._kernels.recursive import (R_ALARMN, R_ALARMS, R_CHECKN, R_COSTK, R_COST, R_COSTW, R_DX, R_EVERY,
                                  R_EVLR, R_FORGET, R_HI, R_JUMPK, R_LIMIT, R_LNA2MIN, R_LO, R_NP, R_QUIETN, R_RELIN,
                                  R_MOVE_A1, R_MOVE_A2, R_MOVE_B, R_SIGMAS, R_TESTN, R_TOLA, R_TOLLN,
                                  R_UPDATES, block, layout, refresh, sample)
from ..checkpoint import Checkpointable
from ..soe import SoeBasis
from .settings import DEFAULT, TrackerSettings
from .common import Fit, LiveMonitors, ParameterView, largest_move as _largest_move, settled_moves


class RecursiveTracker(ParameterView, LiveMonitors, Checkpointable):
    """Gauss-Newton RPEM on the window tracker's regressor: constant work per sample, no replay.

    The estimator reads the same names as from ``WindowTracker``: ``alpha``,
    ``a1``, ``a2``, ``b``, ``offset``, ``fit`` (theta, cost, neff, 1-sigma,
    sample), ``events``, ``sc`` (the shared monitors and counters),
    ``phi``/``co``/``m`` for ``predict_one``.
    """

    def __init__(self, basis: SoeBasis, theta: np.ndarray, *, window_s: float | None, free: bool,
                 gate: float, burst: int, stuck: int, alpha_bounds: tuple[float, float], refit_every: int,
                 detect: bool, scale: float, settings: TrackerSettings | None = None) -> None:
        self.settings = s = DEFAULT if settings is None else settings
        glr = s.recursive_change
        self.basis = basis
        self.h = h = basis.h
        self.q = q = basis.size
        self.n_free = len(s.free_rates) if free else 0
        self.n_rate = 0
        self.hysteresis = None           # (no hysteresis columns: ``OnlineEstimator`` allows them with the window only)
        self.lay = lay = layout(q, self.n_free)
        self.p = lay["p"]
        self.refit_every = refit_every
        self.detect = detect
        self.forget = 1.0 if window_s is None else 1.0 - h / window_s
        #: samples per unit when the estimator replays its start-up buffer into the tracker (~6 us)
        self.feed_chunk = max(4, 6000 // (2 * self.p * (5 + self.n_free)))
        self.fitting = True
        self.drift_on = False
        self.events: list[dict] = []
        self.researches: list[dict] = []   # the window tracker's re-searches of the resonance; none here
        self.disagreement: dict | None = None   # the window tracker's change-test disagreement; none here
        self.rejected = 0                # never: the recursion has no fits to reject
        self._jobs: list = []            # no background jobs: the interface the estimator polls
        self._alarms = 0
        n = lay["n"]
        st = np.zeros(lay["size"])
        theta0 = np.zeros(n)
        theta0[:len(theta)] = theta
        a1, a2 = math.exp(theta0[1]), math.exp(theta0[2])
        W.start_state(st, basis.decay, basis.gain, np.exp(-np.asarray(s.free_rates[:self.n_free]) * h),
                      self.forget, h, a1, a2, 0)
        W.set_monitors(st[:W.SC_SIZE], h, gate, burst, stuck)
        st[W.SC_DUE] = math.inf          # Python is called only at an alarm (and until its event settles)
        co = st[lay["co"]:lay["ztail"]]
        phi = st[lay["phi"]:lay["m"]]
        r = st[lay["r"]:lay["theta"]]
        lo, hi = alpha_bounds
        check = max(1, round(glr.check_s / h))
        r[[R_FORGET, R_TESTN, R_CHECKN, R_JUMPK, R_LIMIT, R_QUIETN, R_EVERY, R_LO, R_HI, R_DX, R_COSTK, R_LNA2MIN,
           R_NP, R_TOLA, R_TOLLN, R_MOVE_A1, R_MOVE_A2, R_MOVE_B, R_SIGMAS]] = [
            self.forget, check * max(1, round(glr.block_s / (check * h))), check, glr.jump,
            glr.threshold if detect else math.inf, round(glr.quiet_s / h), max(1, round(s.refresh_s / h)), lo, hi,
            basis.dx, min(1.0, h / (window_s or 30.0)), 2.0 * math.log(h / math.pi), n, s.tol_alpha, s.tol_ln,
            *glr.kernel_parameters()]
        st[lay["theta"]:lay["ref"]] = theta0
        st[lay["snap"]:lay["prior"]] = theta0
        st[lay["lam"]:lay["z"]] = basis.lam
        b, sc_out = abs(theta0[3]), max(abs(scale), 1e-150)
        alpha0 = float(theta0[0])
        start = np.full(n, (s.start_sd["offset_rel"] * sc_out) ** 2)
        start[:4] = [(s.start_sd["alpha"] + s.start_sd["alpha_rel"] * alpha0) ** 2, s.start_sd["ln_a"] ** 2,
                     s.start_sd["ln_a"] ** 2, (s.start_sd["b_rel"] * b) ** 2]
        prior = start.copy()
        prior[1:4] = [s.reset_sd["ln_a"] ** 2, s.reset_sd["ln_a"] ** 2, (s.reset_sd["b_rel"] * b) ** 2]
        st[lay["prior"]:lay["psi"]] = prior
        self.st = st
        self.sc = st[:W.SC_SIZE]
        self.r = r
        self.theta = st[lay["theta"]:lay["ref"]]
        self.phi = phi
        self.m = st[lay["m"]:lay["sy"]]
        self.co = co
        self.S = self.P = np.diag(start)     # S: the name the estimator's shared code passes
        self.ring = self.CT = np.zeros((n, self.p))
        refresh(st, self.CT)
        self._check = self.theta[:4].tolist()     # the estimate at the last settle check
        self._fit: Fit | None = None

    # ------------------------------------------------------------------ parameters
    b_rate = 0.0                         # drift is followed by the forgetting, not modelled
    alpha_rate = 0.0

    @property
    def n(self) -> int:
        """Samples fed."""
        return int(self.sc[W.SC_N])

    @property
    def prediction(self) -> float:
        return float(self.sc[W.SC_PRED])

    @property
    def relinearizations(self) -> int:
        """Moves of the linearization point (states carried on, never replayed)."""
        return int(self.r[R_RELIN])

    # ------------------------------------------------------------------ per sample
    def feed(self, u: float, y: float) -> int:
        """One sample (u as applied, y measured; NaN y = missing). Returns the kernel's status."""
        status = sample(u, y, self.st, self.P, self.CT)
        if status >= 8:
            self._schedule()
        return status

    def advance(self, u: float, y: float, units: int, work: bool = True) -> bool:
        """One live sample (no background work here: ``units`` and ``work`` are the window tracker's). Returns False
        only when the check at an alarm or a settle check finds the state non-finite."""
        status = sample(u, y, self.st, self.P, self.CT)
        if status >= 8:
            self._schedule()
            return self.state_finite()
        return True

    #: no first re-fit to wait for: the updates are per sample
    first_fit_pending = False

    def begin_fitting(self) -> None:
        """The start-up buffer replayed: the per-sample updates on."""
        self.fitting = True

    def go_live(self, outlier_gate: float) -> None:
        """The start-up buffer replayed: the outlier gate open at ``outlier_gate`` (no jobs: updates are per sample)."""
        self.sc[W.SC_GATE] = float(outlier_gate)
        self.fitting = True

    def drain(self) -> None:
        """Nothing queued (a checkpoint's drain)."""

    def report_events(self) -> list[dict]:
        """The detected changes as reported (complete when they settle: ``_settle_events``)."""
        return self.events

    def drop_failed_jobs(self) -> list[str] | None:
        """No background jobs: a fault is never confined to one (None)."""
        return None

    remembered_window = 0                # no samples are remembered: a restart starts from new ones

    def copy_recent(self, u: np.ndarray, y: np.ndarray) -> None:
        """Nothing remembered (``remembered_window`` is 0)."""

    def feed_block(self, u: np.ndarray, y: np.ndarray, status: np.ndarray, start: int = 0, stop: int = -1) -> int:
        """Samples ``start`` to ``stop`` (-1: the end) up to the next publication or alarm; returns how many were
        consumed."""
        used = block(u, y, self.st, self.P, self.CT, status, start, stop)
        if status[used - 1] >= 8:
            self._schedule()
        return used

    def feed_pending(self, u: np.ndarray, y: np.ndarray, status: np.ndarray, units: int) -> tuple[int, bool]:
        """One sample through ``advance`` (the protocol's block step while work is under way; never pending here)."""
        return 1, self.advance(float(u[0]), float(y[0]), units)

    def work(self, units: int = 1) -> bool:
        """No background work: everything is done per sample (the estimator's polling interface)."""
        return True

    def finish(self) -> None:
        """Nothing queued (block mode)."""

    busy = False
    pending = False                      #: no background work: block mode feeds whole runs (``feed_block``)

    # ------------------------------------------------------------------ publication and events
    def _schedule(self) -> None:
        """Record a new alarm; while an event is open check every ``refit_every`` samples whether it settled."""
        alarms = int(self.r[R_ALARMS])
        if alarms > self._alarms:
            self._alarms = alarms
            self._record_alarm()
        elif self.events and not self.events[-1]["settled"]:
            self._settle_events(self._check)
        self._check = self.theta[:4].tolist()
        self.sc[W.SC_DUE] = self.n + self.refit_every if self.events and not self.events[-1]["settled"] else math.inf

    @property
    def refits(self) -> int:
        """Parameter updates (one per accepted sample)."""
        return int(self.r[R_UPDATES])

    @property
    def fit(self) -> Fit:
        """The current estimate as a fit: theta, mean squared innovation over the window times its effective
        length, the 1-sigma from P (built when read, cached per sample)."""
        n = self.n
        if self._fit is not None and self._fit.sample == n:
            return self._fit
        new = self.theta.tolist()
        sd = [math.sqrt(v) if v >= 0.0 else math.inf for v in self.P.diagonal().tolist()]
        a1, a2 = math.exp(new[1]), math.exp(new[2])
        std = {"alpha": sd[0], "a1": sd[1] * a1, "a2": sd[2] * a2, "b": sd[3], "offset": sd[4]}
        neff = min(float(self.r[R_UPDATES]), 1.0 / max(1.0 - self.forget, 1e-300))
        mean = float(self.r[R_COST]) / float(self.r[R_COSTW]) if self.r[R_COSTW] > 0.0 else 0.0
        self._fit = Fit(theta=self.theta.copy(), cost=mean * neff, neff=neff, std=std, sample=n)
        return self._fit

    def _record_alarm(self) -> None:
        """The change test fired (covariance already reset by the kernel): open an event, or restart the last
        one when it is open or was detected less than ``merge_s`` ago (the same change seen again while the
        resonance re-converges: one event, whose moves are measured from before it once all has settled)."""
        g = float(self.r[R_EVLR])
        last = self.events[-1] if self.events else None
        now = self.n * self.h
        if last is not None and (not last["settled"] or now - last["_last_t"] < self.settings.merge_s):
            last["restarts"] += 1
            last["lr"] = max(last["lr"], g)
            last["settled"] = False
            last["_last_t"] = now
            last.pop("settled_t", None)
            return
        snap = self.st[self.lay["snap"]:self.lay["prior"]]
        self.events.append({"t": float(self.r[R_ALARMN]) * self.h, "detected_t": self.n * self.h, "moved": [],
                            "relative_change": {}, "lr": g, "settled": False, "restarts": 1,
                            "estimate_settled": None,     # (not judged here: see tracker._settled_before)
                            "_before": snap[:4].copy(), "_last_t": self.n * self.h})

    def _settle_events(self, previous: list[float]) -> None:
        """Once the estimate has stopped moving after a change, record what moved; an alarm after which
        nothing moved beyond the rule's ``move`` was a false alarm and leaves no event."""
        ev = self.events[-1]
        now = self.theta[:4].tolist()
        if _largest_move(now, previous) < 0.002 and self.n * self.h - ev["_last_t"] > 1.0:
            relative_change, moved = settled_moves(ev["_before"], now, self.settings.recursive_change.move)
            if not moved:
                self.events.pop()
                return
            ev.update(relative_change=relative_change, moved=moved, settled=True, settled_t=self.n * self.h)


def warm() -> None:
    """Compile (or load from numba's cache) the recursive kernels."""
    basis = SoeBasis.build(1e-3, horizon_s=10.0)
    tr = RecursiveTracker(basis, np.array([0.1, math.log(2e-3), math.log(1e-6), 1.0, 0.0]), window_s=1.0, free=True,
                          gate=8.0, burst=2, stuck=10, alpha_bounds=(0.005, 0.9), refit_every=50, detect=True,
                          scale=1.0)
    u = np.r_[np.zeros(10), np.ones(200)]
    tr.feed_block(u, 0.5 * u, np.empty(u.size, dtype=np.int64))
    tr.feed(1.0, 0.5)
    tr.feed(1.0, math.nan)
