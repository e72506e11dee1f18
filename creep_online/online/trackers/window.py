"""The window tracker: all four parameters from one set of exponentially forgotten statistics.

Per sample (``feed``): one numba call predicts, gates the output on its
innovation, accumulates the statistics of the regressor (``window.py``),
remembers the sample and advances the states. Heavy work is a queue of
resumable jobs, one small unit per ``work()`` call:

* **refit** every ``refit_every`` samples: Levenberg-Marquardt steps on the
  exact window cost over (alpha, ln a1, ln a2, b, offset, free responses and,
  with drift columns, the rates b'/b and alpha'); the drift columns' time
  origin moves to the newest sample first, so alpha and b are the values now.
  The rates are fitted only while a score test (on) / Wald test (off) says
  the data show drift (``settings.drift_on``, ``drift_off``). Its steps keep the resonance near the
  linearization point, where the statistics are the model (``settings.trust``). The fit itself is a numba
  state machine that the per-sample kernel advances in ~1 us slices
  (``_kernels/fit_machine.py``, ``fit_machine.sample_work``);
* **relinearize** when a1 or a2 moved more than ``settings.relinearize`` from the point
  the resonance states were computed at: the remembered samples are replayed
  into fresh statistics (the nodes fast-forwarded, the resonance states
  started a settling time early), then swapped in whole;
* **change test** every ``test_every`` samples: the statistics of the last
  second are the difference of two snapshots (exact for exponential
  forgetting); a fit on them against the window's estimate (on the same
  state machine; with the drift rates while the window does not fit them) is a
  likelihood-ratio test. A significant, physically large move that is also
  a jump against the recent tests' level restarts the window at the change
  (the event names the parameters and their moves);
* **re-search** when the window's error stays above the noise floor or the
  fit breaks down (``Researcher.watch``): the local re-fits never leave a wrong
  resonance basin, so the resonance is searched again on the recent samples
  with the live estimate competing, and replaces it only when clearly better
  (a likelihood ratio; ``researches`` records each one and what moved).

Where each part lives: this class holds the state and the per-sample path; its collaborators run the jobs
on it (none keeps state of its own): ``scheduler.Scheduler`` (the job queue, the re-fit jobs),
``replay.Replayer`` (replays), ``detection.ChangeDetection`` (snapshots, the change test, events, the restart;
its verdict from ``policy.change``), ``research.Researcher`` (the misfit watch and the searches; its verdicts
from ``policy.research``), ``workspace`` (the arrays). Every tunable is a field of ``settings.TrackerSettings``;
the numba kernels and the state layout are in ``online._kernels``.
"""
from __future__ import annotations

import math
from typing import Generator

import numpy as np

from ...effects.hysteresis import threshold_fractions
from .._kernels import fit_machine as RF
from .._kernels import hysteresis as HK
from ..rest import REST_LEAD
from .._kernels import window as W
from ..checkpoint import Checkpointable
from ..soe import SoeBasis
from . import workspace as WS
from .common import (LiveMonitors, KEPT_SNAPSHOTS, MACHINE_REFIT, MACHINE_TEST, PERIODIC_JOBS, SNAP_SLOTS, WAIT,  # noqa: F401
                     ZETA_BOUNDS, Fit, ParameterView)
from .detection import ChangeDetection
from .replay import Replayer
from .research import Researcher
from .scheduler import Scheduler
from .settings import DEFAULT, TrackerSettings

#: The defaults' free-response rates and "determined" limits (the estimator's start-up search and quality).
FREE_RATES = DEFAULT.free_rates
DETERMINED = DEFAULT.determined
#: The play operators' thresholds follow the input's recent range (``follow_input_range``) once it is this much
#: wider than the one they were set for ...
HYSTERESIS_WIDEN = 1.05
#: ... or this many times narrower: a controller's commands can leave a range for good (the reference passed through
#: before the first model, a brief excursion at a model's handover), and thresholds set on it leave the range the
#: input now moves in to one or two operators. Each move of the thresholds is a replay of the remembered samples.
HYSTERESIS_NARROW = 2.0
#: A stream that held its first input this long (s) before moving started at rest (``settle_loop``).
HYSTERESIS_REST_S = 0.1


class WindowTracker(ParameterView, LiveMonitors, Checkpointable):
    """Exponentially forgotten output-error statistics and the jobs that fit them."""

    def __init__(self, basis: SoeBasis, theta: np.ndarray, *, window_s: float | None, free: bool,
                 ring: np.ndarray, gate: float, burst: int, stuck: int, alpha_bounds: tuple[float, float],
                 refit_every: int, test_every: int, detect: bool, work: np.ndarray | None = None,
                 drift: int = 0, hysteresis: int = 0, settings: TrackerSettings | None = None) -> None:
        self.settings = DEFAULT if settings is None else settings
        #: the collaborators that run the jobs (no state of their own: they work on this tracker)
        self.scheduler, self.replayer = Scheduler(), Replayer()
        self.detection, self.researcher = ChangeDetection(), Researcher()
        self.basis = basis
        self.h = basis.h
        self.q = basis.size
        self.n_free = len(self.settings.window_free_rates) if free else 0
        self._free_rates = np.asarray(self.settings.window_free_rates[:self.n_free], dtype=float)    # the window's columns
        self._free_decay = np.exp(-self._free_rates * self.h)   # per sample (``workspace.fresh``)
        #: the free responses' rates, also what a search's judge projects out (``ResonanceSearch.judged_cost``)
        self._free_decays = self.settings.free_rates if free else ()
        #: hysteresis columns: play operators filtered by the plant, their weights linear parameters of the window's
        #: fit beside the offset (``_kernels/hysteresis.py``); their thresholds from the input's span (``start_state``)
        self.n_plays = int(hysteresis)
        self.n_hyst = HK.columns_for(self.n_plays)     # (the plays' and the start columns)
        #: drift columns: 0 none, 1 gain rate, 2 gain and alpha rates. None with the hysteresis columns: a drift column
        #: is the model's output times the time, and the loop's part is not in it (with it, the rates took up the
        #: loop's misfit: a false change and the resonance lost within 10 s on a plain 1 Hz triangle)
        self.n_rate = 0 if self.n_hyst else int(drift)
        self.hyst_r = np.zeros(self.n_plays)
        #: the weights' variances (times sigma^2) at the last accepted re-fit (``fit_machine.weight_variances``)
        self.hyst_var = np.full(self.n_plays, np.inf)
        self._hyst_span = 0.0            # the input range the thresholds are set for
        #: after a rest at the start, the first sample whose plays do not depend on their state at the stream's start
        #: (``settle_loop``): replays leave the samples before it out of the window's statistics
        self.loop_from = 0
        self._loop_swept = 0.0           # the last sweep found (2 r of the largest opened play) and its sample
        self._loop_swept_at = 0
        self.lay = W.layout(self.q, self.n_free, self.n_rate, self.n_hyst)
        self.p = self.lay["p"]
        #: samples per light unit of a replay (each costs the P^2 statistics update, which runs as blocked
        #: matrix products at about twice the rate of the per-sample update, and the states)
        self.replay_chunk = max(2, self.settings.unit_macs // (self.p * self.p // 2 + 4 * self.q * (1 + self.n_hyst)))
        #: samples per unit fed live (``feed_block``: a rank-one update each, with the gate and the prediction)
        self.feed_chunk = max(2, self.settings.unit_macs // (self.p * self.p + 4 * self.q * (1 + self.n_hyst)))
        self.alpha_bounds = alpha_bounds
        self.refit_every = refit_every
        self.test_every = test_every
        self._refit_period = refit_every   # now (``settings.calm_move``): refit_every, doubled while the window is calm
        self._next_refit = refit_every     # sample of the next re-fit
        self._refit_n = 0                  # sample the re-fit under way started at
        self.detect = detect
        self._lr_recent: list[float] = []   # statistics of the last change tests (no change found)
        self.drift_on = False            # the rates are fitted (switched by the score and Wald tests)
        self.drift_stat = 0.0            # the last test statistic (score when off, Wald when on)
        self.theta = np.zeros(5 + self.n_free + self.n_hyst + self.n_rate)     # (its values: ``start``)
        self.forget = 1.0 if window_s is None else math.exp(-self.h / window_s)
        #: samples per epoch of the operators' ``opened`` flags (``hysteresis.set_memory``): the forgetting time
        self._hyst_epoch = 0.0 if window_s is None else window_s / self.h
        self.ring = ring                 # (2, H) history, owned by the caller (pre-faulted)
        self.work_memory = work          # (N, Q) scratch for the post-change search (pre-faulted)
        self.events: list[dict] = []
        self.researches: list[dict] = []   # re-searches of the resonance (``Researcher.research_again_job``)
        self.disagreement: dict | None = None   # the last change test, if the last second disagreed
        self._misfit_since: int | None = None   # first re-fit of the current run of misfits
        self._misfit_sudden = False             # ... and it came suddenly after a window at the floor (settings.research.sudden_ratio)
        self._floor_at: int | None = None       # the last re-fit that found the converged window at the noise floor
        self._floor_raw: tuple | None = None    # ... its accepted fit (``fit_machine.accept``'s tuple)
        self._misfit_floor_raw: tuple | None = None  # ... that fit when the current misfit run began
        self._first_fit: int | None = None      # first re-fit of the current window (start, change, re-search)
        self._fit_raw: tuple | None = None      # the last accepted re-fit (``fit_machine.accept``'s tuple, drift on)
        self._research_wait = int(self.settings.research.after_s / self.h)
        self._next_research = 0            # earliest sample of the next re-search (backoff)
        self._fine_wait = int(self.settings.fine_wait_s / self.h)
        self._next_fine = 0                # earliest sample of the next fine relinearization (backoff)
        self.relinearizations = 0
        self.adoptions = 0               # live states adopted (``_adopt``: the start, each replay's swap, restarts)
        self.refits = 0
        self.rejected = 0                # refits discarded (non-finite or zero gain)
        self.window_start = 0            # first sample in the statistics (moved by a detected change)
        #: alpha is the plant's (held after a change) unless the last restart corrected a start-up estimate
        #: that had not settled (``ChangeDetection.settled_before``): then the re-fits and re-searches free it at once
        self._alpha_known = True
        self.fitting = True              # False while the start-up buffer is replayed: no refits yet
        self.converged = False           # a refit has barely moved since the start: the change test may judge
        self._jobs: list[Generator] = []
        self._draining = False             # a checkpoint runs the jobs to their end: no job waits (``drain``)
        self.eager = False                 # the jobs run to their end now (``Scheduler.finish``: a checkpoint)
        #: the re-fit or change test under way (``fit_machine.sample_work`` advances it): its index among the
        #: context's work arrays (``MACHINE_REFIT``, ``MACHINE_TEST``), or None
        self.machine: int | None = None
        self._snaps: list[tuple] = []
        self._shift = np.zeros((self.q + W.ONE, max(self.n_rate, 1)))   # total drift-origin move (W.since_statistics)
        WS.allocate_work(self)
        self._theta_at: dict[int, np.ndarray] = {}
        self._monitors = (gate, burst, stuck)
        self._blank: tuple | None = None
        self.start(theta)
        self._blank = self._blank_state()

    def start(self, theta: np.ndarray) -> None:
        """Linearize at ``theta`` and start from empty statistics: the part of the construction that needs the
        estimate. The rest (``__init__``: allocations, ~0.3-0.4 ms with cold caches) can run before the estimate
        is known: ``OnlineEstimator`` builds its trackers before the stream, so the update() that ends the
        start-up search does not pay it (it would be that call's largest cost). Of the fresh
        state, only the linearization point and theta's coefficients are set here (one kernel,
        ``window.start_at``): the rest was built ahead (``_blank_state``)."""
        self.start_state(theta)
        self.start_adopt()

    def start_state(self, theta: np.ndarray, u_span: float | None = None) -> None:
        """``start``'s first half: the fresh state linearized at ``theta`` (one kernel). The estimator calls the two
        halves on two calls: together, with cold caches, they were ~35-40 us. ``u_span``: the input's range so far,
        which sets the play operators' thresholds (the batch fit's rule, ``threshold_fractions``; None: as they were)."""
        if self._blank is None:
            self._blank = self._blank_state()
        st, fit = self._blank[0], self._blank[3]
        W.start_at(np.asarray(theta, dtype=float), self.theta, fit.theta, st, self.basis.lam, self.basis.dx)
        if self.n_hyst:                  # (the operators start at the first sample fed, centred on it)
            if u_span is not None:
                self.hyst_r[:] = threshold_fractions(self.n_plays) * float(u_span)
                self._hyst_span = float(u_span)
            HK.set_thresholds(st, self.lay["hyst"], self.hyst_r)
            HK.set_start_form(st, self.lay["hyst"], float(REST_LEAD))   # (a start-up's lead-in is no rest)
            HK.set_memory(st, self.lay["hyst"], self._hyst_epoch)

    @property
    def r0(self) -> int:
        """Index in theta of the first drift rate (after the offset, free responses and hysteresis weights)."""
        return 5 + self.n_free + self.n_hyst

    @property
    def hysteresis_weights(self) -> np.ndarray:
        """The play operators' weights w_i (relative to b, as the batch fit's: theta holds b w_i), thresholds
        ascending."""
        return self.theta[5 + self.n_free:5 + self.n_free + self.n_plays] / self.theta[3]

    @property
    def hysteresis_coefficients(self) -> np.ndarray:
        """The weights w_i, then the start columns' sigma_s (ascending, descending): every hysteresis column's
        coefficient over b (``_kernels/hysteresis.py``)."""
        return self.theta[5 + self.n_free:self.r0] / self.theta[3]

    def follow_input_range(self) -> bool:
        """The thresholds for the input's recent range (``hysteresis.recent_span``: this epoch of the ``opened`` flags
        and the one before), if it is HYSTERESIS_WIDEN wider or HYSTERESIS_NARROW times narrower than the one they were
        set for (the batch fit's rule on that range): the new thresholds and tails in the live block
        (``hysteresis.rethreshold``); the caller then replays the remembered samples. An input at rest (no range)
        keeps them. True if they moved."""
        if not self.n_hyst:
            return False
        o = self.lay["hyst"]
        span = HK.recent_span(self.st, o)
        if not span > 0.0 or self._hyst_span / HYSTERESIS_NARROW <= span <= HYSTERESIS_WIDEN * self._hyst_span:
            return False
        self._hyst_span = span
        self.hyst_r[:] = threshold_fractions(self.n_plays) * span
        oldest = self.ring[0, self._ring_position(int(self.sc[W.SC_RSTART]))]
        HK.rethreshold(self.st, o, self.n_hyst, self.q, self.hyst_r, float(oldest), self.ztail)
        return True

    def settle_loop(self, rms: float, floor: float) -> bool:
        """After a rest at the stream's start (HYSTERESIS_REST_S or longer), once the input has swept the opened plays
        free of their start (a rise or fall of 2 r_i, ``hysteresis.sweep``): does the window misfit (after a re-fit:
        its rms error ``rms``, the noise floor ``floor``, ``ResearchRule.misfits``)? Then ``loop_from`` moves to the
        sweep and the caller replays the remembered samples without the ones before it.

        The start columns (``_kernels/hysteresis.py``) model the plays' unknown start as a difference that begins
        with the stream (the input and the plays are zero before it, the window's reading of its start); a device
        at rest has sat in its start long before, so its rest's output is not that difference's creeping step. On
        the real 150 V record (3 s at rest on the ascending branch, then a 1 Hz sine) the rest's samples kept the
        window at 2.7x the noise floor; without the samples before the sweep, 1.5x. Streams that move from their
        first samples keep them, and so does a window that fits them (a plant resting centred): there they tell
        the weights apart best (the first branch of a periodic input). A start in equilibrium's columns stay (the
        window from the sweep on holds the creep they set off): a re-fit that fits frees them
        (``hysteresis.free_start``)."""
        o = self.lay["hyst"]
        if self.n_hyst and not self.settings.research.misfits(rms, floor):
            HK.free_start(self.st, o, self.n_hyst)
        if not self.n_hyst or self.st[o + HK.REST] * self.h < HYSTERESIS_REST_S:
            return False
        opened = HK.opened(self.st, o, self.n_hyst)
        if opened.any():
            need = 2.0 * float(self.hyst_r[opened].max())
            if need > self._loop_swept and HK.sweep(self.st, o) >= need:
                self._loop_swept, self._loop_swept_at = need, self.n
        if self._loop_swept_at <= self.loop_from or not self.settings.research.misfits(rms, floor):
            return False
        self.loop_from = self._loop_swept_at
        return True

    @property
    def hysteresis(self) -> dict | None:
        """The live loop as an ``effects["hysteresis"]`` dict (thresholds r, weights w, ``initial`` "centred"), or
        None: no hysteresis columns, no window re-fit yet, or weights not finite. (The start columns only say how
        the stream's first samples differ from a centred start: not part of the loop.) ``w_std``: each weight's
        1-sigma from the last re-fit's covariance (``fit_machine.weight_variances``), None where the window does
        not determine it (a pinned operator, a covariance that failed)."""
        w = self.hysteresis_weights
        if not self.n_hyst or self.refits == 0 or not np.all(np.isfinite(w)):
            return None
        sigma2 = WS.noise_variance(self, RF.Accepted._make(self._fit_raw[0]))
        std = [math.sqrt(v * sigma2) if math.isfinite(v) else None for v in self.hyst_var.tolist()]
        return {"r": self.hyst_r.tolist(), "w": w.tolist(), "initial": "centred", "w_std": std}

    def start_adopt(self) -> None:
        """``start``'s second half: the state of ``start_state`` becomes the live one."""
        st, S, views, fit = self._blank
        self._blank = None
        self.fit = fit
        self._adopt(st, S, views)
        self._node_mark_at.fill(-1)                     # (marks of another stream's nodes: none)
        self._next_node_mark = self.n + self._node_mark_every
        self.scheduler.set_due(self, self.n)              # (``Scheduler.schedule`` at sample 0: no re-fit or test is due yet)

    def _blank_state(self) -> tuple:
        """A fresh state array (linearized at the current estimate), its empty statistics and their views, with the
        monitors set, and the start's ``Fit`` (its theta is filled by ``start``): ``start`` re-linearizes the state
        at its theta. Built ahead: the numpy calls and the ``Fit`` from Python here cost ~90 us cold in the
        update() that ends the start-up search."""
        st, S = WS.fresh(self, self.a1, self.a2)
        W.set_monitors(st[:W.SC_SIZE], self.h, *self._monitors)
        return st, S, WS.views(self, st), Fit(theta=np.empty(self.theta.size))

    @property
    def b_rate(self) -> float:
        """Drift of b (per second) at the last fit; 0 without drift columns."""
        return float(self.theta[self.r0] * self.theta[3]) if self.n_rate > 0 else 0.0

    @property
    def free_wide(self) -> bool:
        """A stream in operation: the window fits all its free responses (self.settings.window_free_rates), not only the four it
        starts with (self.settings.window_free_start; switched by the wide test, ``fit_machine._plan``)."""
        return self.n_free > 0 and self._wk[RF.RF_WIDE] != 0.0

    @property
    def alpha_rate(self) -> float:
        """Drift of alpha (per second) at the last fit; 0 without the alpha drift column."""
        return float(self.theta[self.r0 + 1]) if self.n_rate > 1 else 0.0

    @property
    def n(self) -> int:
        """Samples fed."""
        return int(self.sc[W.SC_N])

    # ------------------------------------------------------------------ state arrays
    def _adopt(self, st: np.ndarray, S: np.ndarray, views: tuple) -> None:
        """Make (st, S) with their ``views`` the live state and statistics (their coefficients already set)."""
        self.st, self.S = st, S
        self.adoptions += 1
        self.sc, self.phi, self.m, self.sy, self.co, self.ztail, self.md = views
        self.a1l, self.a2l = float(st[W.SC_A1L]), float(st[W.SC_A2L])
        self._snaps = []

    def _coefficients(self) -> None:
        """The model coefficients for theta, and what the gate needs to know of the estimate."""
        W.set_estimate(self.theta, self.st, self.basis.lam, self.basis.dx)

    def _take_resonance(self) -> None:
        """A search's resonance was written into theta: predict with it at once if the live states represent it
        (within ``settings.trust`` of their linearization point, as a re-fit's move); otherwise the prediction keeps the
        last estimate's coefficients until the replay at the new point is swapped in (``Replayer.relinearize_job``).
        The states hold the resonance to first order around their point only: a prediction with a resonance
        far from it is no model at all (a1 x900 beyond the point predicted 1e5 times the output's span)."""
        if self.predicts_estimate():
            self._coefficients()

    def predicts_estimate(self) -> bool:
        """Do the live states represent the estimate's resonance (within ``settings.trust`` of their linearization
        point)? If not, the prediction keeps the last coefficients until a replay at the new point is swapped in."""
        return max(abs(self.theta[1] - math.log(self.a1l)), abs(self.theta[2] - math.log(self.a2l))) <= self.settings.trust

    # ------------------------------------------------------------------ per sample
    def feed(self, u: float, y: float, slices: int = 1) -> int:
        """One sample (u as applied, y measured; NaN y = missing), and ``slices`` slices of the re-fit or
        change test under way. Returns the kernel's status (``window.sample``'s)."""
        if self.machine is None:
            status = W.sample(u, y, self.st, self.S, self.ring)
        else:
            status = RF.sample_work(u, y, self.st, self.S, self.ring, self._ctx, self.machine, slices)
            if status >= RF.MACHINE_DONE:
                self.machine = None
                status -= RF.MACHINE_DONE
        if status >= 8:
            self.scheduler.schedule(self)
        return status

    def advance(self, u: float, y: float, units: int, work: bool = True) -> bool:
        """One live sample with its share of the background work: the re-fit or change test under way takes
        ``units`` slices in the per-sample kernel (and is then this call's work), else, if ``work``, the queued jobs
        take ``units`` units. Returns False only when a check at a scheduled re-fit or test finds the state
        non-finite (the snapshot's kernel checks it when it takes one)."""
        if self.machine is None:
            status = W.sample(u, y, self.st, self.S, self.ring)
        else:
            status = RF.sample_work(u, y, self.st, self.S, self.ring, self._ctx, self.machine, units)
            if status >= RF.MACHINE_DONE:
                self.machine = None
                status -= RF.MACHINE_DONE
            if status < 8:
                return True
        if status >= 8:
            finite = self.scheduler.schedule(self)
            return self.state_finite() if finite is None else finite
        if work and self._jobs:
            self.work(units)
        return True

    def begin_fitting(self) -> None:
        """The start-up buffer replayed: fitting on, the first re-fit of the replayed window queued."""
        if not self.fitting:
            self.fitting = True
            self._jobs.append(self.scheduler.refit_job(self))

    @property
    def first_fit_pending(self) -> bool:
        """Is the first re-fit after the replay still queued or running? The start-up search's estimate is a grid's
        refinement on the search window; the window's own fit is what the live predictions should come from."""
        return self.fitting and self._first_fit is None and self.scheduler.queued(self, "refit_job")

    def go_live(self, outlier_gate: float) -> None:
        """The start-up buffer replayed: the outlier gate open at ``outlier_gate``, fitting on (``begin_fitting``)."""
        self.sc[W.SC_GATE] = float(outlier_gate)
        self.begin_fitting()

    def feed_block(self, u: np.ndarray, y: np.ndarray, status: np.ndarray, start: int = 0, stop: int = -1) -> int:
        """Samples ``start`` to ``stop`` (-1: the end) up to the next scheduled job or shift; returns how many
        were consumed."""
        used = W.block(u, y, self.st, self.S, self.ring, status, start, stop)
        if status[used - 1] >= 8:
            self.scheduler.schedule(self)
        return used

    def feed_pending(self, u: np.ndarray, y: np.ndarray, status: np.ndarray, units: int) -> tuple[int, bool]:
        """Block mode while background work is under way (``pending``): update()'s course on the leading samples of
        u, y, the machine's run in one kernel call (``feed_machine``), else one sample through ``advance``. Returns
        (samples consumed, whether the state is finite)."""
        if self.machine is not None:
            return self.feed_machine(u, y, status, units), self.state_finite()
        return 1, self.advance(float(u[0]), float(y[0]), units)

    def feed_machine(self, u: np.ndarray, y: np.ndarray, status: np.ndarray, units: int) -> int:
        """Block mode while a re-fit or change test runs in the per-sample kernel: what ``advance`` does sample by
        sample with ``units`` slices each (``fit_machine.block_work``), up to the sample where the machine finishes or
        work is due; returns how many samples were consumed."""
        used = RF.block_work(u, y, self.st, self.S, self.ring, self._ctx, self.machine, units, status, 0)
        last = status[used - 1]
        if last >= RF.MACHINE_DONE:
            self.machine = None
            last -= RF.MACHINE_DONE
        if last >= 8:
            self.scheduler.schedule(self)
        return used

    @property
    def prediction(self) -> float:
        return float(self.sc[W.SC_PRED])

    # ------------------------------------------------------------------ background work (``Scheduler``)
    @property
    def busy(self) -> bool:
        return bool(self._jobs)

    @property
    def pending(self) -> bool:
        """Is background work under way (a queued job, or a re-fit or change test in the per-sample kernel)? Block
        mode then feeds sample by sample, as update() does, so that the work lands at the same sample."""
        return self.machine is not None or bool(self._jobs)

    def work(self, units: int = 1) -> bool:
        """Run up to ``units`` units of the queued jobs (``Scheduler.work``)."""
        return self.scheduler.work(self, units)

    def finish(self) -> None:
        """Run the queued jobs to completion or until the head waits for samples (``Scheduler.finish``)."""
        self.scheduler.finish(self)

    def drain(self) -> None:
        """Run every queued job to its end now (``Scheduler.drain``)."""
        self.scheduler.drain(self)

    def _schedule(self) -> bool | None:
        """Queue the jobs due at this sample (``Scheduler.schedule``; the estimator calls it at status flag 8)."""
        return self.scheduler.schedule(self)

    def _refit_job(self) -> Generator:
        """A re-fit job (``Scheduler.refit_job``; the estimator queues one when the start-up replay ends)."""
        return self.scheduler.refit_job(self)

    def _checkpoint(self) -> None:
        if self._jobs or self.machine is not None:
            self.scheduler.drain(self)

    @property
    def fit(self) -> Fit:
        """The window's last accepted fit with its 1-sigma (built on first access after a re-fit)."""
        if self._fit is None:
            raw, drift_on = self._fit_raw
            r = RF.Accepted._make(raw)
            sigma2 = WS.noise_variance(self, r)
            var = (r.var_alpha, r.var_ln_a1, r.var_ln_a2, r.var_b, r.var_offset, r.var_rate0, r.var_rate1)
            sd = [math.sqrt(abs(v) * sigma2) if math.isfinite(v) else math.inf for v in var]
            a1, a2 = math.exp(r.ln_a1), math.exp(r.ln_a2)
            std = {"alpha": sd[0], "a1": sd[1] * a1, "a2": sd[2] * a2, "b": sd[3], "offset": sd[4]}
            for k, name in enumerate(("b_rate", "alpha_rate")[:self.n_rate]):
                std[name] = (sd[5 + k] * abs(r.b) if k == 0 else sd[5 + k]) if drift_on else math.inf
            self._fit = Fit(theta=[r.alpha, r.ln_a1, r.ln_a2, r.b], cost=r.cost, neff=r.neff, std=std,
                            sample=self._fit_sample)
        return self._fit

    @fit.setter
    def fit(self, value: Fit) -> None:
        self._fit, self._fit_sample = value, value.sample

    def report_events(self) -> list[dict]:
        """The detected changes as reported (``ChangeDetection.report_events``: a settled change's moves filled in)."""
        return self.detection.report_events(self)

    def drop_failed_jobs(self) -> list[str] | None:
        """After a fault inside the background work: if only periodic jobs (re-fit, snapshot, change test) failed
        and no slice is under way, drop them and return their names; else None (the tracker cannot go on)."""
        dead = [job for job in self._jobs if job.gi_frame is None]     # (a generator that raised is closed)
        if not (dead and self.machine is None and all(job.__name__ in PERIODIC_JOBS for job in dead)):
            return None
        for job in dead:
            self._jobs.remove(job)
        return [job.__name__.strip("_").replace("_", " ") for job in dead]

    # ------------------------------------------------------------------ remembered samples
    @property
    def remembered_window(self) -> int:
        """Samples of the current window still remembered (after a detected change: the post-change ones)."""
        return max(0, min(int(self.sc[W.SC_RCOUNT]), self.n - self.window_start))

    def copy_recent(self, u: np.ndarray, y: np.ndarray) -> None:
        """u, y = the newest remembered inputs (as applied) and outputs, as many as u holds."""
        W.ring_copy(self.ring, self._ring_position(self.n - u.shape[0]), u, y)

    def _ring_position(self, index: int) -> int:
        """Ring slot of the sample with this index (must be remembered). A sample keeps its slot while it is
        remembered (the oldest slot and index advance together), so jobs compute it once and count on."""
        size = self.ring.shape[1]
        count = int(self.sc[W.SC_RCOUNT])
        oldest = (int(self.sc[W.SC_RPOS]) - count) % size
        return (oldest + index - int(self.sc[W.SC_RSTART])) % size
