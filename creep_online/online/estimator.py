"""The online estimator: all four parameters of b / (s^alpha (1 + a1 s + a2 s^2)), live, with bounded work.

Phases (``OnlineEstimate.phase``):

``buffering``
    Samples are kept until the input has moved and the buffer spans the
    search window (``t_c``; chosen from the data when None).
``searching``
    A global search over (alpha, fn, zeta) on the buffer (``search.py``), in
    small slices: no starting guess is needed. If the resonance found needs a
    longer window, the buffer grows and the search runs again.
``tracking``
    The tracker replays the buffer and follows the plant. Two strategies
    (docs/online.md, "Remark 3: window vs recursive"; ``refit``): ``"window"`` (default,
    ``tracker.py``) recomputes over the window; ``"recursive"``
    (``recursive.py``) carries on with the newest estimate (a Gauss-Newton
    recursive prediction-error method with a CUSUM change detector, constant
    work per sample, no replay, no drift model). The window tracker: a Levenberg-Marquardt re-fit of all four parameters on the exact
    exponentially forgotten window cost every ``update_every_s``, a
    likelihood-ratio change test every half second (a change restarts the
    window; ``estimate.events`` lists them), and a re-linearization by replay
    when the resonance moves. With ``track_drift`` the window model also has a
    linear drift of b and alpha, switched on when the data show it
    (``estimate.b_rate``, ``alpha_rate``); alpha and b are then the values now.

Work per ``update()``: one sample of O(P^2) statistics (~1 us) plus at most
``work_units`` units of background work (up to ~15 us each: a unit's Python
costs ~3 us, so few large units keep the calls over 5 us rare). The default
unit count is ``max(1, floor(dt / 100 us))``: one unit at 10 kHz, 10 at 1 kHz,
50 at 200 Hz, i.e. at most ~15 % of the sample period.

Robustness: an output whose innovation exceeds ``outlier_gate`` robust scales
is not used (a run longer than ``burst_s`` is accepted: a shift is a change, not
an outlier); an input sample far outside the range seen so far is a glitch
candidate: the samples are kept back until the input either returns (a glitch:
they are fed with the last plausible input) or stays for longer than
``burst_s`` (a move: they are fed as they came, the model never sees a real
step late), then fed a few per call; an output frozen while
the model says it should move is reported (``quality="degraded"``).

Error contract: bad input raises ``DataError`` (non-numbers) or is skipped and
counted (NaN, inf). Any other exception raised inside ``update()``,
``update_block()``, ``gap()`` or ``estimate`` is the library's own fault
(a numerical bug): it is counted (``internal_faults``), recorded as an event
of kind ``"internal_fault"``, and recovered from (``_recover``), never raised
into the caller's loop; so is a non-finite estimate or statistic (checked at
every scheduled re-fit or test and at every ``estimate``). Until the
estimator has re-converged the quality reads ``degraded`` with the fault as
reason.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass, field, replace
from typing import Generator

import numpy as np

from ..checks import count, is_real, number, real_array
from ..errors import DataError, one_line
from ..model import ONLINE_ALPHA_BOUNDS, ONLINE_REFITS, CreepModel
from ._kernels import fit_machine as RF
from ._kernels import window as W
from .search import ResonanceSearch, SearchScratch, frequency_steps, grid_ends
from .soe import DEFAULT_DX, DEFAULT_HORIZON_S, SOE_TOP, SoeBasis
from .trackers import recursive as R      # (its kernels: R.sample)
from .trackers.recursive import RecursiveTracker
from . import rest
from .trackers.window import DETERMINED, FREE_RATES, PERIODIC_JOBS, WindowTracker
from .checkpoint import Checkpointable
from .stored_params import StoredParams

PHASES = ("buffering", "searching", "tracking")
QUALITIES = ("none", "provisional", "good", "changing", "degraded")
#: Largest search buffer (samples): bounds memory and the duration of the search.
MAX_SEARCH_SAMPLES = 1 << 15
#: Start-up buffer (samples): the search window plus what arrives while the search runs.
BUFFER_SAMPLES = 1 << 17
#: Longest run of lost samples gap() replays (held input, no output; ~1.6 us each); a longer outage restarts the
#: tracker in constant time (``_outage``): the plant's state after it is unknown anyway.
GAP_REPLAY_MAX = 4096
#: Fewest samples a forgetting window may hold: a shorter one cannot determine the four parameters.
MIN_WINDOW_SAMPLES = 50
#: Largest history kept for replays (samples).
MAX_HISTORY = 1 << 19
#: alpha within this relative distance of an end of ``alpha_bounds`` is held by the bound, not determined.
BOUND_TOL = 1e-3
#: Live error (window rms) above this multiple of the noise floor is "degraded": the model misses part of the data.
FLOOR_RATIO = 2.0
#: ... and above this one the estimate is not "good" but "provisional" (the model misses a little of the data:
#: unmodeled dynamics, or parameters moving within the window faster than it follows), its determined parameters
#: still named. 1.2 is a model error of 0.66 noise levels (sqrt(1.2^2 - 1)); with the right model the window sits
#: at 0.95-1.05x (the final ratios of every scenario family without unmodeled dynamics, 40 and 80 dB). With
#: FLOOR_RATIO alone (a model error of up to 1.7 noise levels) estimates read "good" beside close unmodeled modes
#: at 1.2-1.9x (40 dB) and on a drifting plant at 80 dB at 1.6x with a1 37 % off.
GOOD_RATIO = 1.2
#: Default ``input_gate``: an input further than this many input ranges from the last accepted one is a glitch
#: candidate (``OnlineEstimator._classify``).
INPUT_GATE = 20.0
#: Samples kept back by the input gate are fed this many per update() once decided (with the new sample's, at
#: most this many kernel calls and one unit of background work per call): the estimate catches up ~burst_s later.
DRAIN_PER_UPDATE = 2
#: Drift columns with ``track_drift``: 1 the gain's rate, 2 the gain's and alpha's.
DRIFT_COLUMNS = 2
#: Exceptions the error contract lets through to the caller: the caller's own errors (bad input: a one-line
#: ``DataError``) and exhaustion of memory. Every other exception inside update(), update_block(), gap() and
#: estimate is an internal fault: counted, recorded and recovered from (``OnlineEstimator._fault``).
PASS_THROUGH = (DataError, MemoryError)
#: Internal-fault events kept (the newest); ``internal_faults`` counts them all.
MAX_FAULT_EVENTS = 50
#: Consecutive faults of the start-up (search, tracker start, replay of the buffer) after which its buffer is
#: dropped: a fault that the buffered samples cause every time is not searched on again and again.
STARTUP_FAULTS = 3
#: Before the input's first move the start-up buffer keeps at most IDLE_BUFFER samples: then only the latest IDLE_KEEP
#: (nothing to identify yet; a stream in operation's distant past only adds its creep to the free responses' load).
IDLE_BUFFER = 4096
IDLE_KEEP = 1024
#: A ready buffer waits at most this many calls for the start-up search's plan (``_plan_pending``; it takes ~4).
PLAN_WAITS = 8
#: A start-up search whose result sits on its box's edge searches again on this many times the window (at most three
#: rounds, ``t_c_max``): the resonance did not show in it.
BOX_GROWTH = 4.0
#: Buffered inputs moved to another frame per unit of work (``OnlineEstimator._reframe``: ~5 us of numpy).
REFRAME_CHUNK = 4096
#: The two Remark-3 strategies (``refit``): recompute over the window, or carry on recursively.
REFITS = ONLINE_REFITS


@dataclass
class OnlineEstimate:
    """The estimator's current answer. Every number is finite; a value not yet estimated is None (JSON null).

    Before the first model (phases ``buffering`` and ``searching``) alpha, a1, a2, b, fn_hz, zeta, offset,
    noise_rms, residual_rms, b_rate and alpha_rate are None, and so is t_c until the start-up search has begun;
    residual_rms also until the first window fit. ``frozen`` is True after ``freeze()``: the estimate then stays
    while the samples still run through the model, and ``quality`` says so and judges the frozen model against the
    new samples (``reason`` names the misfit). ``start`` says how the stream was read to start: ``"rest"`` (its first
    input zero), ``"step"`` (its input at a non-zero level from the first sample, read as a step from rest there:
    the input 0 before it), ``"operation"`` (taken in operation: the plant moving from an unknown past input), None
    while the data do not tell yet (``rest.py``).

    With drift tracking (``track_drift``) alpha and b are the values at the
    newest re-fit (not window averages); ``b_rate`` and ``alpha_rate`` are their
    drift per second, 0 while the data show no significant drift, and
    ``rate_uncertainty`` their 1-sigma (empty while they are 0).
    ``researches`` lists the re-searches of the resonance the tracker ran
    (why, the likelihood ratio, whether it switched and what moved).
    ``determined`` names the parameters the data determine now (relative
    1-sigma within ``DETERMINED``), and is empty unless the window is at the
    noise floor with no change, degradation or long constant input pending:
    ``quality`` is ``good`` exactly when it holds all four and the window's
    error is within ``GOOD_RATIO`` of the noise floor. A ``provisional``
    estimate with alpha and b in it has a trustworthy creep part and an
    undetermined resonance (``online.gate``: what a compensator may take).
    ``internal_faults`` counts the library's own numerical faults that the
    estimator caught and recovered from (each one also an event of kind
    ``"internal_fault"`` in ``events``; module docstring: error contract).
    """

    alpha: float | None
    a1: float | None
    a2: float | None
    b: float | None
    phase: str
    quality: str
    uncertainty: dict = field(default_factory=dict)
    t: float = 0.0
    samples: int = 0
    t_c: float | None = None
    fn_hz: float | None = None
    zeta: float | None = None
    offset: float | None = None
    skipped: int = 0
    alpha_updates: int = 0
    divergences: int = 0
    reason: str = ""
    noise_rms: float | None = None
    residual_rms: float | None = None
    outliers: int = 0
    input_outliers: int = 0
    shifts: int = 0
    relinearizations: int = 0
    events: list = field(default_factory=list)
    b_rate: float | None = None
    alpha_rate: float | None = None
    rate_uncertainty: dict = field(default_factory=dict)
    researches: list = field(default_factory=list)
    determined: list = field(default_factory=list)
    internal_faults: int = 0
    frozen: bool = False
    start: str | None = None

    def to_dict(self) -> dict:
        """JSON-ready dict."""
        return asdict(self)


@dataclass
class _GridPlan:
    """The start-up search prepared on idle buffering calls (``OnlineEstimator._plan_grid``): the buffer's rows it
    will take, its grid frequencies' steps, the frequencies once computed, the search once built."""
    span: tuple[int, int]
    steps: Generator
    freqs: np.ndarray | None = None
    search: ResonanceSearch | None = None


class OnlineEstimator(StoredParams, Checkpointable):
    """Fractional creep model identified sample by sample (scikit-learn / river style).

    Every constructor argument is stored verbatim (``get_params``); derived
    values are built in ``reset()``.

    dt:             sampling step (s).
    window_s:       time constant (s) of the exponential forgetting (None: keep everything).
    update_every_s: period (s) of the window re-fit of all four parameters (doubled while re-fits move
                    nothing, up to the change test's 0.5 s; any move, misfit or change restores it).
    t_c:            search window after the first input change (s); None: from the data.
    alpha0:         optional hint: an extra starting candidate for the search (None: none needed).
    horizon_s:      memory horizon of the SOE fractional integral (s).
    soe_dx:         SOE node spacing in ln(lambda).
    alpha_bounds:   search interval of alpha (default ``model.ONLINE_ALPHA_BOUNDS``).
    t_c_max:        upper limit of the automatic search window (s); the tracker refines slower resonances.
    outlier_gate:   innovation gate in robust scales (0 disables the gate).
    burst_s:        longest run of gated outputs treated as outliers (s); longer is a shift.
    input_gate:     an input sample further than this many input ranges (seen so far) from the last
                    accepted one is a glitch candidate: kept back until the input returns within
                    ``burst_s`` (a glitch: fed with the last accepted input, counted in
                    ``input_outliers``) or stays (a move: fed as it came); the estimate then lags by
                    those samples for a few calls. 0 disables it: inputs the caller computed itself,
                    e.g. a compensator's commands, whose step transients legitimately jump far beyond
                    what came before and return.
    detect_changes: run the change test (likelihood ratio every 0.5 s).
    work_units:     background units per update() (None: max(1, floor(dt / 100 us))).
    track_drift:    model a linear drift of b and alpha inside the window (two more linear parameters);
                    the estimate is then the value at the newest sample, with ``b_rate``, ``alpha_rate``
                    (window tracker only: the recursive one follows drift through its forgetting).
    refit:          Remark 3's strategy: ``"window"`` re-fits over the forgetting window (replays when the
                    resonance moves), ``"recursive"`` carries on with the newest estimate (RPEM, constant
                    work per sample; docs/online.md, "Remark 3: window vs recursive").
    """

    def __init__(self, dt: float, *, window_s: float | None = 10.0, update_every_s: float = 0.1,
                 t_c: float | None = None, alpha0: float | None = None,
                 horizon_s: float = DEFAULT_HORIZON_S, soe_dx: float = DEFAULT_DX,
                 alpha_bounds: tuple[float, float] = ONLINE_ALPHA_BOUNDS, t_c_max: float = 2.0,
                 outlier_gate: float = 8.0, burst_s: float = 0.002, input_gate: float = INPUT_GATE,
                 detect_changes: bool = True,
                 work_units: int | None = None, track_drift: bool = True, refit: str = "window") -> None:
        self.dt = dt
        self.window_s = window_s
        self.update_every_s = update_every_s
        self.t_c = t_c
        self.alpha0 = alpha0
        self.horizon_s = horizon_s
        self.soe_dx = soe_dx
        self.alpha_bounds = alpha_bounds
        self.t_c_max = t_c_max
        self.outlier_gate = outlier_gate
        self.burst_s = burst_s
        self.input_gate = input_gate
        self.detect_changes = detect_changes
        self.work_units = work_units
        self.track_drift = track_drift
        self.refit = refit
        self._validate()
        self.reset()

    # ------------------------------------------------------------------ parameters
    def _validate(self) -> None:
        def positive(name: str, value, allow_none: bool = False) -> None:
            if value is None and allow_none:
                return
            if not is_real(value) or not _finite_float(value) or value <= 0:
                raise DataError(f"{name} must be a positive finite number{' or None' if allow_none else ''}, "
                                f"got {value!r}")
        positive("dt", self.dt)
        positive("window_s", self.window_s, allow_none=True)
        positive("update_every_s", self.update_every_s)
        positive("t_c", self.t_c, allow_none=True)
        positive("horizon_s", self.horizon_s)
        positive("soe_dx", self.soe_dx)
        positive("t_c_max", self.t_c_max)
        positive("burst_s", self.burst_s)
        if self.alpha0 is not None and not (is_real(self.alpha0) and 0 < self.alpha0 < 1):
            raise DataError(f"alpha0 must satisfy 0 < alpha0 < 1 or be None, got {self.alpha0!r}")
        try:
            lo, hi = (float(v) for v in self.alpha_bounds)
        except (TypeError, ValueError):
            raise DataError(f"alpha_bounds must be two numbers (lo, hi), got {self.alpha_bounds!r}") from None
        if not 0 < lo < hi < 1:
            raise DataError(f"alpha_bounds must satisfy 0 < lo < hi < 1, got {self.alpha_bounds!r}")
        if self.alpha0 is not None and not lo <= self.alpha0 <= hi:
            raise DataError(f"alpha0 ({self.alpha0:g}) must lie within alpha_bounds ({lo:g}, {hi:g})")
        if not is_real(self.outlier_gate) or not _finite_float(self.outlier_gate) or not self.outlier_gate >= 0:
            raise DataError(f"outlier_gate must be >= 0 (0 disables it), got {self.outlier_gate!r}")
        if not is_real(self.input_gate) or not _finite_float(self.input_gate) or not self.input_gate >= 0:
            raise DataError(f"input_gate must be >= 0 (0 disables it), got {self.input_gate!r}")
        if self.work_units is not None and not (isinstance(self.work_units, (int, np.integer))
                                                and not isinstance(self.work_units, bool) and 1 <= self.work_units <= 1 << 20):
            raise DataError(f"work_units must be a positive integer or None, got {self.work_units!r}")
        if not isinstance(self.track_drift, bool):
            raise DataError(f"track_drift must be True or False, got {self.track_drift!r}")
        if not (isinstance(self.refit, str) and self.refit in REFITS):
            raise DataError(f"refit must be one of {', '.join(REFITS)}, got {self.refit!r}")
        if self.horizon_s <= self.dt:
            raise DataError(f"horizon_s ({self.horizon_s}) must exceed dt ({self.dt})")
        if self.window_s is not None and self.window_s < MIN_WINDOW_SAMPLES * self.dt:
            raise DataError(f"window_s ({self.window_s:g} s) must hold at least {MIN_WINDOW_SAMPLES} samples "
                            f"({MIN_WINDOW_SAMPLES * self.dt:g} s at dt = {self.dt:g} s)")
        if self.t_c is not None and self.t_c > (BUFFER_SAMPLES // 2) * self.dt:
            raise DataError(f"t_c ({self.t_c:g} s) is longer than the start-up buffer holds "
                            f"({(BUFFER_SAMPLES // 2) * self.dt:g} s at dt = {self.dt:g} s)")

    # ------------------------------------------------------------------ lifecycle
    def reset(self) -> "OnlineEstimator":
        """Forget everything: derived settings rebuilt, back to buffering, counters to zero."""
        h = float(self.dt)
        self._h = h
        self.basis = SoeBasis.build(h, horizon_s=float(self.horizon_s), dx=float(self.soe_dx), top=SOE_TOP)
        self._units = self.work_units or max(1, int(h / 100e-6))
        self._bounds = tuple(float(v) for v in self.alpha_bounds)     # alpha's (lo, hi) as floats
        self._refit_every = max(5, int(round(self.update_every_s / h)))
        self._test_every = max(10, int(round(0.5 / h)))
        self._history = int(min(MAX_HISTORY, max(1024, 3 * (self.window_s or 30.0) / h)))
        self.samples = 0
        self.skipped_nonfinite = 0
        self.internal_faults = 0
        self._faults: list[dict] = []      # the internal-fault events (``_fault``), the newest MAX_FAULT_EVENTS
        self._fault_open: dict | None = None   # the last fault while the estimator re-converges (``_fault_reason``)
        self._fault_fit_after = 0          # ... a window fit after this tracker sample is one after the recovery
        self._startup_faults = 0           # consecutive faults of the start-up (``STARTUP_FAULTS``)
        self._restarted = False            # restarted in operation after a fault: the plant was not at rest
        self._kept: OnlineEstimate | None = None   # the estimate before a long outage (``_outage``), until live again
        self._hint: tuple | None = None    # (alpha, a1, a2) before a fault's restart: a candidate of the search
        self._n_shift = 0                  # stream samples before the tracker's first (a restart's; 0 otherwise)
        self._past_events: list[dict] = []     # events and re-searches of trackers a restart dropped, in stream time
        self._past_researches: list[dict] = []
        self._block_progress: tuple | None = None   # update_block()'s tracker loop (``_block_resync``)
        self.gaps = 0
        self.input_outliers = 0
        self.frozen = False
        self._frozen_t = 0.0               # stream time of freeze()
        self._phase = "buffering"
        self._u_ref: float | None = None
        self._u_lo = self._u_hi = 0.0
        self._u_last = 0.0
        self._held: list[tuple[float, float]] = []           # glitch candidates (u, y) not yet decided
        self._backlog: deque[tuple[float, float]] = deque()   # decided samples (du, y) the live tracker awaits
        self._deferred = False                               # either is non-empty: update()'s slow path
        self._first_change: int | None = None
        #: how the stream starts (``rest.py``): "rest" (its first input zero), "step" (a step from rest at its first
        #: sample), "operation" (taken in operation), None while the data do not tell yet
        self._start: str | None = None
        self._competing = False            # both readings of the start are being searched (``_compete``)
        self._move_a: int | None = None    # the input's first move (buffer index) in operation's reading
        self._jump = 0.0                   # the first input level (the step's size in the step's reading)
        self._reframing: Generator | None = None   # the buffer moving to the step's frame (``_read_start``)
        self._lead: int | None = None      # rest samples replayed before the buffer (``_lead_in``; None: not yet)
        self._lead_u = np.zeros(rest.REST_LEAD)           # ... their inputs (0) and outputs (the rest level)
        self._lead_y = np.zeros(rest.REST_LEAD)
        self._start_wait = max(64, min(int(rest.WAIT_S / h), BUFFER_SAMPLES // 2))   # (``rest.WAIT_S``)
        self._bu = np.empty(BUFFER_SAMPLES)
        self._by = np.empty(BUFFER_SAMPLES)
        self._nbuf = 0
        # pre-faulted work memory: page faults would otherwise land inside update()
        self._bu.fill(0.0)
        self._by.fill(0.0)
        self._hist_work = np.zeros((MAX_SEARCH_SAMPLES, self.basis.size))
        self._hist_work.fill(0.0)
        self._noise_scratch = np.zeros(W.NOISE_SEED_ROWS)
        self._noise_seed = 0.0             # the start-up buffer's noise level (``_start_tracking``)
        self._ring = np.zeros((2, self._history))
        self._ring.fill(0.0)
        self._burst = max(2, int(round(self.burst_s / h)))
        self._t_need = max(0.05, 200 * h)
        self._search: ResonanceSearch | None = None
        self._search_scratch = SearchScratch(self.basis.size)
        self._search_scratch.prepare_judge(FREE_RATES, self.basis.h)   # (a start-up search in operation's)
        self._grid_plan: _GridPlan | None = None
        self._search_rounds = 0
        self._search_end = 0                # end (buffer index) of the last start-up search's rows
        self._plan_waits = 0                # ready calls spent on the plan (``_plan_pending``)
        self._tc_used = 0.0
        self._tracker: WindowTracker | RecursiveTracker | None = None
        self._starting: Generator | None = None     # the tracker's start under way (``_start_steps``)
        self._recursive = self.refit == "recursive"
        self._catchup = 0
        # the window trackers for a stream from rest and one taken in operation, built now (``WindowTracker.start``)
        self._spares = {} if self._recursive else {free: self._window_tracker(free) for free in (False, True)}
        #: the catch-up's status buffer (``_catch_up``), allocated ahead for the window trackers
        self._status = np.empty(max([t.feed_chunk for t in self._spares.values()] or [0]), dtype=np.int64)
        return self

    def freeze(self) -> None:
        """Stop adapting: samples still advance the states and the predictions; the estimate stays, and its quality
        judges it against the new samples (``_frozen_quality``)."""
        if not self.frozen:
            self._frozen_t = self.samples * self._h
        self.frozen = True
        if self._tracker is not None:
            self._tracker.sc[W.SC_ACC] = 0.0

    def unfreeze(self) -> None:
        """Resume adapting."""
        self.frozen = False
        if self._tracker is not None:
            self._tracker.sc[W.SC_ACC] = 1.0

    # ------------------------------------------------------------------ checkpoint (pickle, deepcopy)
    def _checkpoint(self) -> None:
        """Finish the background work under way now (``checkpoint``: generators cannot be pickled): the grid's
        frequencies, the start-up search with all its rows in and the tracker's start and replay, the tracker's
        queued jobs. The prepared search of a buffer still filling is dropped (it is built again, the same, when
        the buffer is ready). An internal fault meanwhile is caught and recovered from as in update()."""
        try:
            plan = self._grid_plan
            if plan is not None:
                if plan.freqs is None and plan.steps is not None:
                    try:
                        while True:
                            next(plan.steps)
                    except StopIteration as done:
                        plan.freqs = done.value
                plan.steps = None
                plan.search = None
            if self._phase == "searching" or self._starting is not None or self._catchup:
                self._advance_start(1 << 30)
            tr = self._tracker
            if isinstance(tr, WindowTracker):
                tr.drain()
        except PASS_THROUGH:
            raise
        except Exception as exc:  # noqa: BLE001 - the error contract, as in update()
            self._fault(exc, "checkpoint")

    # ------------------------------------------------------------------ public API
    @property
    def phase(self) -> str:
        return self._phase

    @property
    def model(self) -> CreepModel | None:
        """The current model (None before the first search has ended)."""
        tr = self._tracker
        if tr is None:
            return None
        try:
            return CreepModel(tr.alpha, tr.a1, tr.a2, tr.b)
        except Exception:  # noqa: BLE001 - a transient out-of-range fit: no model object
            return None

    @property
    def last_prediction(self) -> float | None:
        """Model output for the latest sample (offset included); None before a model exists."""
        tr = self._live
        return None if tr is None or tr.fit.sample == 0 and tr.n == 0 else tr.prediction

    @property
    def alpha_updates(self) -> int:
        """Window re-fits done (``refit="recursive"``: parameter updates, one per accepted sample)."""
        return 0 if self._tracker is None else self._tracker.refits

    @property
    def divergences(self) -> int:
        """Window re-fits rejected (non-finite or zero gain): the previous estimate was kept."""
        return 0 if self._tracker is None else self._tracker.rejected

    @property
    def events(self) -> list[dict]:
        """Detected abrupt changes (kind ``"change"``: time, parameters that moved, relative moves) and internal
        faults (kind ``"internal_fault"``: time, where, the exception's type and message, the recovery), by time.
        Times are stream times (``samples`` x dt) once a fault has restarted the tracker."""
        shift = self._n_shift * self._h
        live = [] if self._tracker is None else [_shifted(ev, shift, "change") for ev in self._tracker.events]
        events = self._past_events + live
        if self._faults:
            events = sorted(events + self._faults, key=lambda ev: ev["t"])
        return events

    @property
    def researches(self) -> list[dict]:
        """The tracker's re-searches of the resonance (and those of trackers a fault's restart dropped)."""
        shift = self._n_shift * self._h
        live = [] if self._tracker is None else [_shifted(r, shift) for r in self._tracker.researches]
        return self._past_researches + live

    @property
    def estimate(self) -> OnlineEstimate:
        """The current answer. Never raises: a fault while it is built (or a non-finite state found) is an internal
        fault (error contract), and the answer is then the bare one (no model's details, quality degraded)."""
        try:
            tr = self._tracker
            if tr is not None and not self._state_finite(tr):
                self._fault(None, "estimate")
            return self._estimate()
        except PASS_THROUGH:
            raise
        except Exception as exc:  # noqa: BLE001 - the error contract: an internal fault never reaches the caller
            self._fault(exc, "estimate")
            return self._bare_estimate(*self._fault_reason())

    def _bare_estimate(self, quality: str, reason: str) -> OnlineEstimate:
        """The estimate without a model (before the first search has ended, or when building it failed)."""
        return OnlineEstimate(alpha=None, a1=None, a2=None, b=None, phase=self._phase, quality=quality,
                              reason=reason, t=self.samples * self._h, samples=self.samples,
                              t_c=self._tc_used or None, skipped=self.skipped_nonfinite,
                              input_outliers=self.input_outliers, events=self.events,
                              internal_faults=self.internal_faults, frozen=self.frozen, start=self._start)

    def _estimate(self) -> OnlineEstimate:
        tr = self._tracker
        if self._kept is not None and self._live is None:   # after a long outage, until the new tracker is live
            return replace(self._kept, phase=self._phase, t=self.samples * self._h, samples=self.samples,
                           skipped=self.skipped_nonfinite, input_outliers=self.input_outliers, events=self.events,
                           internal_faults=self.internal_faults)
        quality, reason, determined = self._assess()
        if tr is None:
            return self._bare_estimate(quality, reason)
        a1, a2 = _known(tr.a1), _known(tr.a2)
        wn = 1.0 / math.sqrt(a2) if a2 is not None and a2 > 0.0 else None
        std = {k: _finite(tr.fit.std[k], math.inf) for k in ("alpha", "a1", "a2", "b") if k in tr.fit.std}
        rate_std = {k: _finite(tr.fit.std[k], math.inf) for k in ("b_rate", "alpha_rate")
                    if tr.drift_on and k in tr.fit.std}
        return OnlineEstimate(
            alpha=_known(tr.alpha), a1=a1, a2=a2, b=_known(tr.b), phase=self._phase,
            quality=quality, reason=reason, uncertainty=std, t=self.samples * self._h, samples=self.samples,
            t_c=self._tc_used or None, fn_hz=None if wn is None else _known(wn / (2 * math.pi)),
            zeta=None if wn is None or a1 is None else _known(a1 * wn / 2),
            offset=_known(tr.offset), skipped=self.skipped_nonfinite,
            alpha_updates=self.alpha_updates, divergences=self.divergences,
            noise_rms=_known(self._noise()),
            residual_rms=self._residual(), outliers=int(tr.sc[W.SC_OUTLIERS]),
            shifts=int(tr.sc[W.SC_SHIFTS]), relinearizations=tr.relinearizations,
            input_outliers=self.input_outliers, events=self.events, b_rate=_known(tr.b_rate),
            alpha_rate=_known(tr.alpha_rate), rate_uncertainty=rate_std,
            researches=self.researches, determined=determined, internal_faults=self.internal_faults,
            frozen=self.frozen, start=self._start)

    def predict_one(self, u: float) -> float | None:
        """Model output at the next sample if u is applied now (no state change); None without a model."""
        tr = self._tracker
        if tr is None or self._phase != "tracking":
            return None
        phi = tr.phi.copy()
        W.advance(phi, tr.co, tr.q, float(u) - (self._u_ref or 0.0))
        return float(phi @ tr.m)

    def learn_one(self, u: float, y: float) -> "OnlineEstimator":
        """river-style alias of update()."""
        self.update(u, y)
        return self

    # ------------------------------------------------------------------ feeding
    def update(self, u: float, y: float) -> None:
        """Feed one sample. Bounded work: never waits for a search or a re-fit.

        Raises only ``DataError`` (u or y not a number); NaN and inf are skipped and counted. Any internal fault
        is caught, counted and recovered from (module docstring: error contract): the guard is one ``try``
        around the whole body, free in Python 3.11 while nothing is raised."""
        if u.__class__ is not float or y.__class__ is not float:   # (the common case costs two type checks)
            u, y = number(u, "update(): u"), number(y, "update(): y")
        if u - u != 0.0 or y - y != 0.0:          # NaN or inf
            self.skipped_nonfinite += 1
            return
        self.samples += 1
        try:
            tr = self._live
            if tr is None:
                self._buffer_sample(u, y)
                self._advance_start(self._units)
                return
            if self._u_lo <= u <= self._u_hi and not self._deferred:
                self._u_last = u
                du = u - self._u_ref
            elif not self._deferred and not self._glitch_candidate(u):
                du = self._accept(u)           # the range grows (no glitch candidate): still the direct path
            else:
                self._update_deferred(tr, u, y)
                return
            # tr.feed() inlined: one Python call less on the per-sample path
            if self._recursive:
                status = R.sample(du, y, tr.st, tr.P, tr.CT)
            elif tr.machine is None:
                status = W.sample(du, y, tr.st, tr.S, tr.ring)
            else:                             # a re-fit or change test under way: its slices run in the kernel
                status = RF.sample_work(du, y, tr.st, tr.S, tr.ring, tr._ctx, tr.machine, self._units)
                if status >= RF.MACHINE_DONE:
                    tr.machine = None         # its job reads the result at the next sample (this call has done
                    status -= RF.MACHINE_DONE   # the machine's last slice: with the job's visit it was over 25 us)
                if status < 8:                # the slice was this call's background work: no job runs while the
                    return                    # machine does (``work``; its call cost ~0.4 us on every slice)
            if status >= 8:                   # jobs queued (and the change test's snapshot taken): their first
                finite = tr._schedule()       # unit waits for the next sample, this call has done enough
                if not (self._state_finite(tr) if finite is None else finite):   # (a snapshot checks it)
                    self._fault(None, "update")
            elif tr._jobs:
                tr.work(self._units)
        except PASS_THROUGH:
            raise
        except Exception as exc:  # noqa: BLE001 - the error contract: an internal fault never reaches the loop
            self._fault(exc, "update")

    def update_block(self, u: np.ndarray, y: np.ndarray) -> None:
        """Feed many samples (same semantics as repeated update(); background work runs to completion).

        Raises only ``DataError`` (arrays that cannot be used). An internal fault is caught, counted and recovered
        from, and the block goes on from the sample after the one it came in (``_block_from``)."""
        u = _array(u, "u")
        y = _array(y, "y")
        if u.shape != y.shape:
            raise DataError(f"update_block(): u and y differ in length ({u.size} vs {y.size})")
        ok = np.isfinite(u) & np.isfinite(y)
        if not ok.all():
            self.skipped_nonfinite += int(u.size - np.count_nonzero(ok))
            u, y = u[ok], y[ok]
        k = 0
        while k < u.size:
            k = self._block_from(u, y, k)

    def _block_from(self, u: np.ndarray, y: np.ndarray, k: int) -> int:
        """Feed u[k:], y[k:]; returns where it stopped: the end, or after an internal fault the first sample not
        taken (at least k + 1: a fault that a sample causes every time cannot stall the block)."""
        done = [k]                           # samples taken so far (``_feed_block`` keeps it current)
        try:
            self._feed_block(u, y, done)
            return u.size
        except PASS_THROUGH:
            raise
        except Exception as exc:  # noqa: BLE001 - the error contract: an internal fault never reaches the loop
            self._fault(exc, "update_block")
        return max(done[0], k + 1)

    def _feed_block(self, u: np.ndarray, y: np.ndarray, done: list[int]) -> None:
        """update_block()'s work from ``done[0]`` on. ``done[0]``: samples taken (counted in ``samples``); in the
        tracker's loop it is advanced by the tracker's own sample count, which its kernel moves per sample, so a
        fault inside ``feed_block`` or ``finish`` leaves it exact."""
        i = done[0]
        n = u.size
        while i < n and self._live is None:
            self.samples += 1
            done[0] = i + 1
            self._buffer_sample(float(u[i]), float(y[i]))
            i += 1
            self._advance_start(1 << 30)
        if i == n:
            return
        du, yy, exact = self._inputs(u[i:], y[i:])
        status = np.empty(du.size, dtype=np.int64)
        tr = self._live
        n0, s0, j = tr.n, self.samples, 0
        # the arrays are the samples as they came unless the input gate kept some back or had some waiting: then
        # all of u[i:] is taken (decided or held), and a fault leaves the rest of du, yy waiting (``_block_resync``)
        self._block_progress = (tr, n0, s0, i, done, None if exact else (du, yy, n))
        while j < du.size:
            j += tr.feed_block(du[j:], yy[j:], status[j:])
            self.samples = s0 + (j if exact else n - i)
            done[0] = i + j if exact else n
            tr.finish()
            if not self._state_finite(tr):
                self._fault(None, "update_block")
                tr = self._live
                if tr is None or not exact:  # restarted: the rest of the block goes through the start-up (what
                    self._block_progress = None   # the gate had decided waits: ``_block_resync``)
                    return self._feed_block(u, y, done)
        self._block_progress = None
        if not exact:                        # (every sample of the block may still be held)
            self.samples = s0 + (n - i)
            done[0] = n

    def gap(self, n: int) -> None:
        """n samples were lost (sequence counter): time advances with the input held, no output used.

        Internal faults are caught as in update() (one per lost sample at most)."""
        n = count(n, "gap(): n (lost samples)", minimum=0, maximum=1 << 62)
        if n == 0:
            return
        if n > GAP_REPLAY_MAX:
            self._outage(n)
            return
        self.gaps += n
        if self._deferred:
            self._settle_inputs()
        du = self._u_last - (self._u_ref or 0.0)
        for _ in range(n):
            self.samples += 1
            try:
                if self._live is not None:
                    self._live.feed(du, math.nan)
                else:
                    self._buffer(du, math.nan)
            except PASS_THROUGH:
                raise
            except Exception as exc:  # noqa: BLE001 - the error contract: an internal fault never reaches the loop
                self._fault(exc, "gap")

    def _outage(self, n: int) -> None:
        """A stretch of ``n`` > GAP_REPLAY_MAX lost samples: a restart, not a replay (work independent of n).

        The plant's state after a long outage is unknown, so the tracker is dropped and the search starts again
        on new samples, in operation, with the estimate before the outage as a candidate; until the new tracker
        is live that estimate is reported (quality provisional, the reason says why)."""
        self.gaps += n
        self.samples += n
        if self._held:                       # glitch candidates before the outage: the input went on unknown
            self.input_outliers += len(self._held)
            self._held = []
        self._backlog.clear()
        self._deferred = False
        kept = self._estimate() if self._tracker is not None and self._phase == "tracking" else self._kept
        tr = self._tracker
        if tr is not None:
            hint = (tr.alpha, tr.a1, tr.a2)
            if all(math.isfinite(v) for v in hint) and hint[1] > 0.0 and hint[2] > 0.0:
                self._hint = hint
        self._drop_tracker()
        self._restarted = self._restarted or self._first_change is not None or tr is not None
        self._nbuf = 0
        self._first_change = None
        self._n_shift = self.samples
        self._startup_faults = 0
        if kept is not None:
            why = (f"restarting after {n} lost samples ({n * self._h:.3g} s): the estimate before the outage, "
                   f"until the search on new samples ends")
            self._kept = replace(kept, quality="provisional" if kept.quality != "none" else "none", reason=why,
                                 determined=[])

    @property
    def _live(self) -> WindowTracker | RecursiveTracker | None:
        """The tracker once it is fed directly (after the start-up buffer has been replayed)."""
        return self._tracker if self._catchup == 0 else None

    # ------------------------------------------------------------------ input handling
    def _classify(self, u: float, y: float) -> list[tuple[float, float]]:
        """The input gate: the samples (input to apply, y) decided by this one, in order (often just this one).

        An input further than ``input_gate`` ranges (seen so far) from the last accepted one is a glitch candidate
        and is kept back with its output. If the input returns before more than ``burst_s`` of them, they were a
        glitch: fed with the last accepted input (and counted in ``input_outliers``). If the input stays, it was a
        move: they are fed as they came. (Held and fed at once, as before, a real step taken early in a stream,
        30 of its first step's size, reached the model 2 ms late: the states kept the delayed step, the window sat
        at 150-390x the noise floor for seconds and a re-search took a wrong resonance: payload seed 3004 at 80 dB.)
        """
        if self._u_ref is None:
            self._u_ref = u
            self._u_lo = self._u_hi = u
            self._u_last = u
            # a first input of zero is a start at rest; a non-zero one at the stream's first sample is read from the
            # data (``_read_start``); after a start over in mid-stream the plant is in operation
            self._start = "rest" if u == 0.0 else (None if self.samples == 1 else "operation")
        if self._glitch_candidate(u):
            self._held.append((u, y))
            if len(self._held) <= self._burst:
                self._deferred = True
                return []
            held, self._held = self._held, []
            self._deferred = bool(self._backlog)
            return held
        if not self._held:
            return [(u, y)]
        held, self._held = self._held, []
        self._deferred = bool(self._backlog)
        self.input_outliers += len(held)
        return [(self._u_last, w) for _, w in held] + [(u, y)]

    def _glitch_candidate(self, u: float) -> bool:
        """Is u further than ``input_gate`` input ranges (seen so far; none before the input has moved) from the
        last accepted input?"""
        rng = self._u_hi - self._u_lo
        return rng > 0 and self.input_gate > 0 and abs(u - self._u_last) > self.input_gate * rng

    def _accept(self, u: float) -> float:
        """Take u as the input applied (the range seen so far, the first input change); its deviation from the
        first level. Called per sample in stream order, just before the sample is fed or buffered."""
        if u != self._u_last and self._first_change is None:
            self._first_change = self._nbuf
        self._u_last = u
        self._u_lo = min(self._u_lo, u)
        self._u_hi = max(self._u_hi, u)
        return u - self._u_ref

    def _inputs(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """Vector form of ``_classify`` and ``_accept`` for the live tracker: (du, y, exact). Exact: the arrays
        are the block's samples one for one (every input within the range seen so far, nothing waiting: the
        fast path); otherwise the samples that waited come first and glitch candidates at the end stay held."""
        if not self._deferred and self._u_lo <= u.min() and u.max() <= self._u_hi:
            self._u_last = float(u[-1])
            return u - self._u_ref, y, True
        ready = list(self._backlog)
        self._backlog.clear()
        for k in range(u.size):
            ready.extend((self._accept(v), w) for v, w in self._classify(float(u[k]), float(y[k])))
        self._deferred = bool(self._held)
        out = np.array(ready, dtype=float).reshape(-1, 2)
        return np.ascontiguousarray(out[:, 0]), np.ascontiguousarray(out[:, 1]), False

    def _buffer_sample(self, u: float, y: float) -> None:
        """A sample into the start-up buffer through the input gate, after any the live tracker had waiting (a
        fault's restart leaves them: ``_update_deferred``, ``_block_resync``)."""
        self._backlog_to_buffer()
        for v, w in self._classify(u, y):
            self._buffer(self._accept(v), w)
        self._deferred = bool(self._held)

    def _update_deferred(self, tr: WindowTracker | RecursiveTracker, u: float, y: float) -> None:
        """update()'s slow path: an input outside the range seen so far, or samples waiting. The sample goes
        through the input gate; of the decided ones at most ``DRAIN_PER_UPDATE`` are fed now, in order."""
        self._backlog.extend((self._accept(v), w) for v, w in self._classify(u, y))
        for k in range(min(DRAIN_PER_UPDATE, len(self._backlog))):
            du, w = self._backlog.popleft()
            self._feed_live(tr, du, w, work=k == DRAIN_PER_UPDATE - 1 or not self._backlog)
            if self._live is not tr:       # a fault restarted the tracker: the rest goes to the start-up buffer
                self._backlog_to_buffer()
                break
        self._deferred = bool(self._held or self._backlog)

    def _feed_live(self, tr: WindowTracker | RecursiveTracker, du: float, y: float, work: bool) -> None:
        """One sample into the live tracker with its slice of a re-fit under way and, if ``work``, a share of the
        queued jobs (the per-sample path of update(), for the samples the input gate kept back)."""
        machine = not self._recursive and tr.machine is not None
        status = tr.feed(du, y) if self._recursive else tr.feed(du, y, self._units)
        if status >= 8:
            if not self._state_finite(tr):
                self._fault(None, "update")
        elif work and not machine and tr._jobs:
            tr.work(self._units)

    def _settle_inputs(self) -> None:
        """Before a gap: glitch candidates still held count as a glitch (the input is unknown past them) and every
        sample waiting is fed (or buffered) now."""
        if self._held:
            self.input_outliers += len(self._held)
            self._backlog.extend((self._u_last - self._u_ref, w) for _, w in self._held)
            self._held = []
        while self._backlog and self._live is not None:
            du, w = self._backlog.popleft()
            self._feed_live(self._live, du, w, work=True)
        self._backlog_to_buffer()
        self._deferred = False

    def _backlog_to_buffer(self) -> None:
        """The decided samples the live tracker has not taken, in order, into the start-up buffer (the tracker was
        restarted by a fault: the start-up takes them first)."""
        while self._backlog:
            self._buffer(*self._backlog.popleft())

    # ------------------------------------------------------------------ start-up
    def _buffer(self, du: float, y: float) -> None:
        """Append to the start-up buffer (before any input change only the last samples are kept)."""
        k = self._nbuf
        if self._first_change is None and k >= IDLE_BUFFER and self._start is not None:  # no excitation: the latest
            keep = IDLE_KEEP
            self._bu[:keep] = self._bu[k - keep:k]
            self._by[:keep] = self._by[k - keep:k]
            k = keep
        if k == self._bu.size:
            if self._first_change is None:
                if self._start is None:      # (a held input whose output never showed a step: the first sample goes)
                    self._start = "operation"
                keep = IDLE_KEEP
                self._bu[:keep] = self._bu[k - keep:k]
                self._by[:keep] = self._by[k - keep:k]
                k = keep
            else:                            # the search cannot keep up: finish it now
                self._advance_start(1 << 30)
                if self._live is not None:
                    self._live.feed(du, y)
                    return
                raise DataError("start-up buffer overflow: the stream is too fast for the search")
        self._bu[k] = du
        self._by[k] = y
        self._nbuf = k + 1

    def _ready_to_search(self) -> bool:
        if self._first_change is None:
            return False
        return self._nbuf - self._first_change >= self._t_search() / self._h

    def _t_search(self) -> float:
        if self.t_c is not None:
            return float(self.t_c)
        return self._t_need

    def _advance_start(self, units: int) -> None:
        """Buffering and searching: start the search when ready, give it ``units``, start the tracker.

        Sample by sample the search's end, the tracker's start steps and the replay's first unit each take
        a call of their own (``_start_steps``): together they were one update() of ~80-120 us. The estimate
        reads "searching" until the tracker has started, a few samples later. With ``units`` >= 2^29 (block
        mode, a full buffer) everything runs in this call."""
        eager = units >= 1 << 29
        while self._reframing is not None:     # (the step's reading's buffer moving to its frame, a chunk per call)
            if next(self._reframing, _DONE) is _DONE:
                self._reframing = None
            if not eager:
                return
        if self._lead is None and self._first_change is not None and not self._in_operation:
            self._lead_in()
            if not eager:
                return
        if self._phase == "buffering":
            if self._start is None and not self._competing and self._read_start():
                return
            if not self._ready_to_search() or self._plan_pending():
                self._plan_grid()
                return
            self._start_search()
            units -= 1
        if self._phase == "searching":
            if self._starting is None:
                s = self._search
                while units > 0 and not s.step():
                    units -= 1
                if s.result is None or self._longer_window_needed(s.result):
                    return
                self._starting = self._compete_and_start(s.result) if self._competing else \
                    self._start_steps(s.result)
                if not eager:
                    return
            for _ in self._starting:
                if not eager:
                    return
            if not eager:                  # started in this call: the replay from the next
                return
        if self._catchup:
            self._catch_up(max(units, 1))

    def _read_start(self) -> bool:
        """A stream whose input is at a non-zero level from its first sample: a step from rest there, or taken in
        operation (``rest``)? Read when the search in operation is ready (the input has moved: if the output may show
        a step, both readings compete, ``_compete``), or every ``rest.WAIT_S`` while the input holds (the step's
        reading once the output shows one; until then the buffer keeps the first sample). Returns whether this call
        read it."""
        n = self._nbuf
        moved = self._first_change is not None
        if not (self._ready_to_search() if moved else n % self._start_wait == 0):
            return False
        near, step = rest.reading(self._by[:n])
        if not near:
            self._start = "operation"
            self._keep_latest_before_move()
            return True
        if not (moved or step):
            return True                    # (near rest, not moved yet: read again after another WAIT_S)
        self._competing = moved
        if not moved:
            self._start = "step"
        self._move_a = self._first_change
        self._jump = self._u_ref
        self._u_lo, self._u_hi = min(self._u_lo, 0.0), max(self._u_hi, 0.0)
        self._reframing = self._reframe(0.0)   # (in the next calls)
        next(self._reframing)              # (the frame itself now: samples from the next call on are in it)
        self._first_change = 0
        self._grid_plan = None
        return True

    def _keep_latest_before_move(self) -> None:
        """A stream read in operation after its input moved: of the samples before the move, the latest ``IDLE_KEEP``
        only if there were ``IDLE_BUFFER`` of them, as ``_buffer`` drops them while the input holds (the reading kept
        them all). A held input's are dropped by ``_buffer`` itself."""
        fc = self._first_change
        if fc is None or fc < IDLE_BUFFER:
            return
        drop = fc - IDLE_KEEP
        n = self._nbuf - drop
        self._bu[:n] = self._bu[drop:drop + n]
        self._by[:n] = self._by[drop:drop + n]
        self._nbuf = n
        self._first_change = fc - drop
        self._grid_plan = None

    def _lead_in(self) -> None:
        """A stream read from rest: the rest it implies before its first sample, if it shows too little of it
        (``rest.lead_in``): input 0, output at the mean of its rest outputs (those up to its first input change),
        replayed into the tracker before the buffer (``_catch_up``; the searches start at the first change and need
        no more rest). The tracker's time then runs that many samples ahead of the stream's (``_n_shift``)."""
        fc = self._first_change
        lead = rest.lead_in(fc + 1)
        outputs = [v for v in self._by[:min(fc + 1, self._nbuf)].tolist() if v == v] if lead else []
        self._lead = lead if outputs else 0     # (plain Python on <= REST_LEAD values: numpy's nanmean was ~100 us cold)
        if self._lead:
            self._lead_y[:lead] = sum(outputs) / len(outputs)
            self._n_shift -= lead

    def _reframe(self, u_ref: float) -> Generator:
        """The buffered inputs as deviations from ``u_ref`` (0: the step's reading, the input 0 before the first
        sample; the first level: the stream in operation), ``REFRAME_CHUNK`` per unit; samples that arrive meanwhile
        are buffered in the new frame."""
        shift, self._u_ref = self._u_ref - u_ref, u_ref
        n = self._nbuf
        yield                              # (the frame is set: the caller's next samples are buffered in it)
        for k in range(0, n, REFRAME_CHUNK):
            self._bu[k:min(k + REFRAME_CHUNK, n)] += shift
            yield

    def _compete(self, step) -> Generator:
        """Both readings of the start on the samples the step's search had (``rest``, stage 2): the buffer in the
        in-operation frame, its search (the step's result a candidate), the costs compared; the buffer in the frame
        taken. In units; returns the search result to start the tracker at.

        The in-operation search refines the step's search's candidates (its ``starts``) instead of running a grid of
        its own: both readings share the plant's resonance, only the start's free responses differ. A grid of its own
        takes 2200-7400 units (one per sample) on the real CubeSpec multisines whatever the rows, more than a 2.56 s
        record leaves after a 1.37 s window; refined from the step's candidates, 400-2300 units, costs within
        0.04 % of the grid's and the same reading taken on all six."""
        rows = self._search_end            # (the step's search: from the first sample)
        starts = [c[1:] for c in self._search.candidates] or None
        yield from self._reframe(self._jump)
        search = ResonanceSearch(self.basis, self._bu[:rows], self._by[:rows], extra=((step.alpha, step.a1, step.a2),),
                                 work=self._hist_work, scratch=self._search_scratch, free=FREE_RATES, starts=starts)
        while not search.step():
            yield
        operation = search.result
        self._competing = False
        if rest.prefer_step(step.cost, operation.cost, rows, 2 + len(FREE_RATES)):
            self._start = "step"
            yield from self._reframe(0.0)
            return step
        self._start = "operation"
        self._n_shift += self._lead or 0   # (no rest to replay in operation)
        self._lead = 0
        self._first_change = self._move_a
        return operation

    @property
    def _in_operation(self) -> bool:
        """Does the buffer start with the plant not at rest? A stream whose first input is not zero, and every
        buffer after a fault's restart (``_restart``): the searches and the tracker then fit free responses."""
        return self._restarted or bool(self._u_ref)

    def _search_span(self, nbuf: int) -> tuple[int, int]:
        """(start, end) in the buffer of the search that starts with ``nbuf`` samples buffered: from rest, the search
        window after the first change (a step read at the first sample after a held second has a whole second
        buffered: searched at a stride, a 1.7 kHz mode's transient fell between the rows and the search took a
        resonance 4x slower); in operation, and for the step's reading in a competition (``_compete``: it must
        meet the input's moves that the in-operation reading is searched on), everything buffered."""
        if self._in_operation:
            return 0, min(nbuf, MAX_SEARCH_SAMPLES)
        start = max(0, self._first_change - 1)
        end = nbuf if self._competing else self._first_change + math.ceil(self._t_search() / self._h)
        return start, min(nbuf, end, start + MAX_SEARCH_SAMPLES)

    def _plan_grid(self) -> None:
        """On an idle buffering call, one step of the search that starts when the buffer is ready: its grid
        frequencies (``search.frequency_steps``, a few numpy calls), then its construction (the buffer's rows
        to come are views of memory already there). Its first unit, in the update() that fills the buffer,
        then does neither (~35 us of cold numpy; the construction alone ~10 us of cold Python on top of that
        update()'s own work: 27 us). Only the first search has a grid (later ones refine its candidates); the
        plan is used only if its rows are the search's (``_start_search``)."""
        plan = self._grid_plan
        if self._first_change is None or self._search is not None or plan is not None and plan.search is not None:
            return
        if plan is None:
            start, end = self._search_span(self._first_change + math.ceil(self._t_search() / self._h))
            self._grid_plan = _GridPlan((start, end), frequency_steps(*grid_ends(end - start, self._h)))
            return
        if plan.freqs is None:
            try:
                next(plan.steps)
            except StopIteration as done:
                plan.freqs = done.value
            return
        plan.search = self._new_search(*plan.span, plan.freqs)

    def _plan_pending(self) -> bool:
        """Is the first search's plan (``_plan_grid``) still being prepared although the buffer is ready? A step read
        at the first sample finds its buffer full at once: the few calls of the plan come first (unplanned, the
        search's construction and first unit were ~170 us in one update()). Not in a competition of the start's
        readings (its search takes every buffered sample, not the plan's rows)."""
        plan = self._grid_plan
        if (self._search is not None or self._competing or self._first_change is None
                or plan is not None and plan.search is not None or self._plan_waits >= PLAN_WAITS):
            return False
        self._plan_waits += 1
        return True

    def _start_search(self) -> None:
        start, end = self._search_span(self._nbuf)
        self._search_end = end
        plan, self._grid_plan = self._grid_plan, None
        planned = plan is not None and plan.span == (start, end)
        if planned and plan.search is not None:
            self._search = plan.search
        else:
            self._search = self._new_search(start, end, plan.freqs if planned else None)
        self._tc_used = (end - start) * self._h
        self._phase = "searching"

    def _new_search(self, start: int, end: int, freqs: np.ndarray | None) -> ResonanceSearch:
        """The search over the buffer's rows [start, end) (some may be still to come), with the grid's
        frequencies ``freqs`` if computed ahead; after a first search it refines that one's candidates."""
        prev = self._search
        starts = [c[1:] for c in prev.candidates] if prev is not None and prev.candidates else None
        alphas = () if self.alpha0 is None else (float(self.alpha0),)
        # in operation the buffer starts in the fading memory of an unknown past input: the search projects it
        # out (the tracker's free responses), as it does the unknown resonance state (``ResonanceSearch`` free)
        extra = () if self._hint is None else (self._hint,)     # (a fault's restart: the estimate before it)
        return ResonanceSearch(self.basis, self._bu[start:end], self._by[start:end], alphas=alphas,
                               extra=extra, work=self._hist_work, starts=starts, scratch=self._search_scratch,
                               freqs=freqs, free=FREE_RATES if self._in_operation else None)

    def _longer_window_needed(self, res) -> bool:
        """After a search: grow the buffer to 1.5 settling times of the resonance found and search again; or, if the
        result sits on the search box's edge (``ResonanceSearch.at_bound``: held by the box, not shown by the data),
        to ``BOX_GROWTH`` times the window (a 2 Hz mode searched on 0.05 s came out at zeta 3 and alpha 0.95: a settling
        time of 4 ms, no longer window, the tracker started there and still missed by 40 % in alpha 4 s later)."""
        if self.t_c is not None or self._search_rounds >= 3:
            return False
        settle = 8.0 * res.a2 / res.a1
        held = BOX_GROWTH * self._t_need if self._search.at_bound(res) else 0.0
        want = min(max(1.5 * settle, held, 0.05, 200 * self._h), float(self.t_c_max),
                   MAX_SEARCH_SAMPLES * self._h * 0.95)
        if want <= 1.05 * self._t_need:
            return False
        self._search_rounds += 1
        self._t_need = want
        self._phase = "buffering"
        return True

    def _window_tracker(self, free: bool) -> WindowTracker:
        """A window tracker with this estimator's settings, linearized at a placeholder resonance (fs / 20,
        zeta 0.5) until ``WindowTracker.start`` gives it the start-up search's estimate."""
        lo, hi = self._bounds
        wn = 2.0 * math.pi / (20.0 * self._h)
        theta = np.array([0.5 * (lo + hi), math.log(1.0 / wn), math.log(1.0 / wn ** 2), 1.0, 0.0])
        return WindowTracker(
            self.basis, theta, window_s=self.window_s, free=free, ring=self._ring, work=self._hist_work,
            gate=0.0, burst=self._burst, stuck=max(10, int(round(0.05 / self._h))), alpha_bounds=(lo, hi),
            refit_every=self._refit_every, test_every=self._test_every, detect=bool(self.detect_changes),
            drift=DRIFT_COLUMNS if self.track_drift else 0)

    def _compete_and_start(self, step) -> Generator:
        """``_compete``, then ``_start_steps`` at the reading taken."""
        res = yield from self._compete(step)
        yield from self._start_steps(res)

    def _start_steps(self, res) -> Generator:
        """Start the tracker at the search's result, in steps (one per call sample by sample, ``_advance_start``):
        the window tracker's fresh state (``WindowTracker.start_state``), then its adoption; the replay of the
        buffer (``_catch_up``) follows."""
        lo, hi = self._bounds
        theta = np.array([min(max(res.alpha, lo), hi), math.log(res.a1), math.log(res.a2), res.b, res.c])
        if self._recursive:
            self._tracker = RecursiveTracker(
                self.basis, theta, window_s=self.window_s, free=self._in_operation, gate=0.0, burst=self._burst,
                stuck=max(10, int(round(0.05 / self._h))), alpha_bounds=(lo, hi), refit_every=self._refit_every,
                detect=bool(self.detect_changes), scale=res.b * (self._u_hi - self._u_lo))
        else:
            yield                          # (theta above, the fresh state below: ~30 us cold in one call)
            # (the other spare stays until reset(): freeing its arrays here cost ~35 us of this update())
            key = self._in_operation
            if key not in self._spares:    # (used by a tracker that a fault's restart dropped: ``_restart``)
                self._spares[key] = self._window_tracker(key)
            tracker = self._spares[key]
            tracker.start_state(theta)
            yield
            self._buffer_noise()           # (a median of 2048 second differences: in a call of its own)
            yield
            self._tracker = self._spares.pop(key)
            self._tracker.start_adopt()
        self._starting = None
        self._start_tracking()

    def _buffer_noise(self) -> None:
        """The start-up buffer's noise level (``window.noise_seed``; a lead-in's still outputs left out)."""
        self._noise_seed = W.noise_seed(self._by, self._nbuf, self._noise_scratch)

    def _start_tracking(self) -> None:
        """The tracker has started: its noise monitor at the buffer's noise level (``_buffer_noise``, computed by the
        window tracker's start a call before), the replay of the buffer (``_catch_up``) follows."""
        if self._recursive:
            self._buffer_noise()
        self._tracker.sc[W.SC_NOISE] = self._noise_seed
        if self.frozen:
            self._tracker.sc[W.SC_ACC] = 0.0
        self._tracker.fitting = False
        self._catchup = 1
        self._replayed = 0
        self._phase = "tracking"

    def _catch_up(self, units: int) -> None:
        """Feed the buffer into the new tracker, a few samples per unit, then go live (gate open)."""
        tr = self._tracker
        per_unit = tr.feed_chunk
        if self._status.size < per_unit:
            self._status = np.empty(per_unit, dtype=np.int64)
        status = self._status
        lead = self._lead or 0
        total = lead + self._nbuf          # (the lead-in's rest first, then the buffer)
        while units > 0 and self._replayed < total:
            units -= 1
            k = self._replayed
            # (the first unit a quarter: the new tracker's statistics and the block kernel are cold, ~27 us whole)
            n = min(per_unit if k else max(per_unit // 4, 1), total - k)
            if k < lead:
                n = min(n, lead - k)
                used = tr.feed_block(self._lead_u, self._lead_y, status, k, k + n)
            else:
                used = tr.feed_block(self._bu, self._by, status, k - lead, k - lead + n)
            self._replayed += used
            if k < lead <= self._replayed:   # the lead-in's still outputs are no sample of the sensor's noise
                W.restart_monitors(tr.sc, self._noise_seed)
            if tr._jobs and units > 0:     # the tracker's own jobs share the budget
                units -= 1
                tr.work(1 if units < (1 << 29) else 1 << 30)
        if self._replayed >= total:
            self._kept = None
            self._startup_faults = 0
            self._catchup = 0
            self._nbuf = 0
            tr.sc[W.SC_GATE] = float(self.outlier_gate)
            tr.fitting = True
            if not self._recursive:        # the recursive tracker has no jobs: its estimate is always current
                tr._jobs.append(tr._refit_job())

    # ------------------------------------------------------------------ internal faults (error contract)
    @staticmethod
    def _state_finite(tr: WindowTracker | RecursiveTracker) -> bool:
        """Can the tracker's state be trusted: its estimate, its statistics' diagonal (a non-finite regressor
        poisons it) and its live prediction all finite? One kernel (``window.state_finite``, a few us): checked at
        each scheduled re-fit or test (``update``), after each block unit and at each ``estimate``, not per sample."""
        return W.state_finite(tr.theta, tr.S, tr.sc)

    def _fault(self, exc: BaseException | None, where: str) -> None:
        """An internal fault in ``where`` (``exc``; None: a non-finite state found): counted, recorded as an event,
        recovered from (``_recover``). Never raises but ``PASS_THROUGH``: if the recovery itself fails, the
        estimator starts over from nothing (``_start_over``), its counters and events kept."""
        self.internal_faults += 1
        error, message = ("NonFiniteState", "non-finite estimate, statistics or prediction") if exc is None \
            else (type(exc).__name__, one_line(exc))
        self._block_resync()
        try:
            recovery = self._recover(exc is None, where)
        except PASS_THROUGH:
            raise
        except Exception as again:  # noqa: BLE001 - the recovery's own fault: the last resort
            recovery = self._start_over(again)
        t = self.samples * self._h
        event = {"kind": "internal_fault", "t": t, "detected_t": t, "where": where, "error": error,
                 "message": message, "recovery": recovery, "moved": [], "relative_change": {}, "settled": True}
        self._faults = (self._faults + [event])[-MAX_FAULT_EVENTS:]
        self._fault_open = event

    def _block_resync(self) -> None:
        """After a fault inside update_block()'s tracker loop: ``samples`` and the block's position from the
        tracker's own count (its kernel moves it per sample taken), so no sample is lost or fed twice."""
        progress, self._block_progress = self._block_progress, None
        if progress is None:
            return
        tr, n0, s0, i, done, classified = progress
        try:
            taken = tr.n - n0
        except (TypeError, ValueError, OverflowError):     # (a non-finite count: the position stays)
            return
        if classified is None:
            self.samples = s0 + taken
            done[0] = i + taken
            return
        du, yy, n = classified           # all of the block was taken: what the tracker has not, waits
        self._backlog.extendleft(reversed(list(zip(du[taken:].tolist(), yy[taken:].tolist()))))
        self._deferred = bool(self._held or self._backlog)
        self.samples = s0 + (n - i)
        done[0] = n

    def _recover(self, nonfinite: bool, where: str) -> str:
        """Back to a safe state; returns what was done (the event's ``recovery``).

        * while the report was built (``estimate``) with a finite state: nothing to repair;
        * during the start-up (search, tracker start, replay of the buffer): the search again (``_restart_startup``);
        * a live tracker with a finite state whose fault ended a periodic job (re-fit, snapshot, change test):
          the job is dropped, the next one is scheduled as usual;
        * otherwise (a non-finite state, a fault in the per-sample kernel or a long job: replay, re-search):
          the tracker is dropped and the estimator restarts from a search of the remembered samples (``_restart``).
        """
        tr = self._tracker
        if where == "estimate" and not nonfinite:
            return "estimate reported without the model's details"
        if tr is None or self._starting is not None or self._catchup:
            return self._restart_startup()
        if nonfinite or not self._state_finite(tr):
            return self._restart()
        dead = [job for job in tr._jobs if job.gi_frame is None]     # (a generator that raised is closed)
        if dead and tr.machine is None and all(job.__name__ in PERIODIC_JOBS for job in dead):
            for job in dead:
                tr._jobs.remove(job)
            self._fault_fit_after = tr.n
            return "dropped the " + ", ".join(job.__name__.strip("_").replace("_", " ") for job in dead)
        return self._restart()

    def _restart_startup(self) -> str:
        """A fault before the tracker went live: the search starts again on the buffered samples; after
        ``STARTUP_FAULTS`` in a row, on new ones (the buffer dropped; the plant is then not at rest)."""
        self._startup_faults += 1
        self._drop_tracker()
        self._fault_fit_after = 0
        if self._startup_faults < STARTUP_FAULTS and not self._competing:   # (competing: between two frames)
            return "the start-up search starts again on the buffered samples"
        self._restarted = self._restarted or self._first_change is not None
        if self._start is None:            # (the stream's first samples are gone: a step there can no longer show)
            self._start = "operation"
            self._competing = False
        self._lead = 0
        self._nbuf = 0
        self._first_change = None
        self._n_shift = self.samples
        self._startup_faults = 0
        return f"the start-up buffer dropped after {STARTUP_FAULTS} faults: the search starts again on new samples"

    def _restart(self) -> str:
        """The tracker is not trustworthy: dropped, and the newest remembered samples of its window (its ring, up
        to the search's ``MAX_SEARCH_SAMPLES``) become the start-up buffer of a stream in operation: a fresh search,
        a fresh tracker (built here if its spare is used: ~0.4 ms once), the replay of the buffer. The recursive
        tracker remembers no samples: it starts from new ones."""
        tr = self._tracker
        k = 0
        hint = (tr.alpha, tr.a1, tr.a2)
        if all(math.isfinite(v) for v in hint) and hint[1] > 0.0 and hint[2] > 0.0:
            self._hint = hint              # the estimate before the fault competes in the new search
        if isinstance(tr, WindowTracker):
            # the newest samples of the window (after a detected change, the post-change ones only)
            k = max(0, min(int(tr.sc[W.SC_RCOUNT]), tr.n - tr.window_start, MAX_SEARCH_SAMPLES))
            W.ring_copy(tr.ring, tr._ring_position(tr.n - k), self._bu[:k], self._by[:k])
        self._drop_tracker()
        self._restarted = True
        self._lead = 0                     # (in operation: no rest to replay)
        self._nbuf = k
        self._n_shift = self.samples - k
        moves = np.flatnonzero(self._bu[1:k] != self._bu[:k - 1]) if k > 1 else ()
        self._first_change = int(moves[0]) + 1 if len(moves) else None
        self._fault_fit_after = 0
        return (f"tracker restarted: a new search on the {k} remembered samples ({k * self._h:.3g} s)" if k else
                "tracker restarted: a new search on new samples")

    def _drop_tracker(self) -> None:
        """Forget the tracker and any start-up under way (their events and re-searches kept, in stream time)."""
        tr, self._tracker = self._tracker, None
        if tr is not None:
            shift = self._n_shift * self._h
            self._past_events += [_shifted(ev, shift, "change") for ev in tr.events]
            self._past_researches = (self._past_researches + [_shifted(r, shift) for r in tr.researches])[-50:]
        self._starting = None
        self._search = None
        self._grid_plan = None
        self._catchup = 0
        self._phase = "buffering"

    def _start_over(self, again: BaseException) -> str:
        """The last resort when a recovery itself fails: ``reset()``, the fault record and counters kept."""
        keep = (self.samples, self.skipped_nonfinite, self.gaps, self.input_outliers, self.internal_faults,
                self._faults, self._past_events, self._past_researches)
        self.reset()
        (self.samples, self.skipped_nonfinite, self.gaps, self.input_outliers, self.internal_faults,
         self._faults, self._past_events, self._past_researches) = keep
        self._n_shift = self.samples
        return f"the recovery failed ({type(again).__name__}: {one_line(again)}): started over from nothing"

    def _fault_reason(self) -> tuple[str, str]:
        """("degraded", the open fault named) while the estimator re-converges after it."""
        ev = self._fault_open or (self._faults[-1] if self._faults else None)
        if ev is None:
            return "degraded", "internal fault"
        return "degraded", (f"internal fault at t={ev['t']:.4g} s ({ev['error']} in {ev['where']}: {ev['message']}); "
                            f"{ev['recovery']}; re-converging")

    def _fault_cleared(self, quality: str) -> bool:
        """Has the estimator re-converged after the open fault? A window fit after the recovery, and every check
        passed (or a whole window of stream since: what is wrong then is the checks' to say)."""
        tr = self._tracker
        if tr is None or self._catchup or tr.fit.sample <= self._fault_fit_after:
            return False
        since = self.samples * self._h - self._fault_open["t"]
        return not quality or since > (self.window_s or 30.0)

    # ------------------------------------------------------------------ monitoring
    def _noise(self) -> float:
        tr = self._tracker
        return 0.0 if tr is None else float(tr.sc[W.SC_NOISE])

    def _residual(self) -> float | None:
        """The window fit's rms error (None before the first window fit)."""
        tr = self._tracker
        if tr is None or not math.isfinite(tr.fit.cost) or tr.fit.neff <= 0:
            return None
        return math.sqrt(max(tr.fit.cost, 0.0) / tr.fit.neff)

    def _floor_ratio(self) -> float:
        """The window's error over the noise floor (the floor at least 1e-9 of the output's span, for noiseless data;
        0 before the first window fit)."""
        tr = self._tracker
        floor = max(self._noise(), 1e-9 * abs(tr.b) * max(self._u_hi - self._u_lo, 1e-300))
        return (self._residual() or 0.0) / floor if floor > 0 else math.inf

    def _assess(self) -> tuple[str, str, list[str]]:
        """(quality, reason, determined): good only at the noise floor (``GOOD_RATIO``) with every parameter determined.

        ``determined`` lists the parameters within their ``DETERMINED`` limit once every other check has
        passed (empty before): the estimate's creep part can be trusted while its resonance is not.
        """
        quality, reason, ratio = self._checks()
        if self._fault_open is not None and self._fault_cleared(quality):
            self._fault_open = None
        if self._fault_open is not None:
            return (*self._fault_reason(), [])
        if self.frozen and self._tracker is not None and not self._catchup:
            return (*self._frozen_quality(), [])
        if quality:
            return quality, reason, []
        tr = self._tracker
        values = {"alpha": tr.alpha, "b": tr.b, "a1": tr.a1, "a2": tr.a2}
        rel = {name: tr.fit.std.get(name, math.inf) / max(abs(values[name]), 1e-300) for name in DETERMINED}
        lo, hi = self._bounds
        pinned = not lo * (1 + BOUND_TOL) < tr.alpha < hi * (1 - BOUND_TOL)
        determined = [name for name, limit in DETERMINED.items()
                      if rel[name] < limit and not (name == "alpha" and pinned)]
        for name in DETERMINED:
            if name == "alpha" and pinned:
                return "provisional", \
                    f"alpha at its bound {tr.alpha:.4g}: the search interval holds it, not the data", determined
            if name not in determined:
                return "provisional", f"{name} not yet determined by the data ({100 * rel[name]:.2g} % 1-sigma)", \
                    determined
        if ratio > GOOD_RATIO:
            return "provisional", (f"window error {ratio:.2f}x the noise floor: the model misses a little of the data "
                                   "(unmodeled dynamics, or parameters moving within the window)"), determined
        return "good", "", determined

    def _waiting_reason(self) -> str:
        """What the estimator waits for before its first estimate."""
        if self._competing:
            return ("searching the resonance and creep: the input's first level as a step from rest at the first "
                    "sample, against a stream in operation")
        if self._start is None and self._u_ref is not None:
            return (f"reading the start: the input is at {self._u_ref:.4g} from the first sample; waiting for the "
                    "output to move from its first value (a step from rest) or for the input to move (a stream in "
                    "operation)")
        if self._first_change is None:
            return "waiting for the input to move" + (
                " (the stream is in operation: its output did not start at rest)" if self._start == "operation" else "")
        return "searching the resonance and creep"

    def _frozen_quality(self) -> tuple[str, str]:
        """A frozen estimate's quality: never "good" (it no longer follows the plant); "degraded" when the live
        prediction error of the last ~0.2 s (``window.SC_E2``) exceeds ``FLOOR_RATIO`` of the noise floor, else
        "provisional"; the reason says it is frozen and how well it still predicts."""
        tr = self._tracker
        floor = max(self._noise(), 1e-9 * abs(tr.b) * max(self._u_hi - self._u_lo, 1e-300))
        live = math.sqrt(max(float(tr.sc[W.SC_E2]), 0.0)) / floor if floor > 0 else math.inf
        held = f"frozen since t={self._frozen_t:.4g} s: the estimate is held, not adapted"
        if live > FLOOR_RATIO:
            return "degraded", f"{held}; it misses the data now (live error {live:.3g}x the noise floor)"
        return "provisional", f"{held} (live error {live:.3g}x the noise floor)"

    def _checks(self) -> tuple[str, str, float]:
        """(quality, reason, the window's error over the noise floor) from every check but the parameters'
        determination; ("", "", ratio) if all pass (the ratio NaN before the tracker is live)."""
        tr = self._tracker
        if tr is None:
            return "none", self._waiting_reason(), math.nan
        if self._catchup:
            return "provisional", "replaying the start-up buffer", math.nan
        ratio = self._floor_ratio()
        if tr.sc[W.SC_STUCK]:
            return "degraded", "output frozen or clipped while the model says it moves", ratio
        shift = self._n_shift * self._h    # the tracker's time to stream time (non-zero after a fault's restart)
        now = self.samples * self._h - shift
        # an unsettled change holds "changing" past its first 1.5 s only while the window is below "degraded": a
        # change whose fit never settles is a window that misses the data (seen for 9 s at 115x the floor)
        if tr.events and (now - tr.events[-1]["detected_t"] < 1.5
                          or (not tr.events[-1]["settled"] and ratio <= FLOOR_RATIO)):
            ev = tr.events[-1]
            if ev.get("estimate_settled") is False:
                return "provisional", (f"estimate corrected at t={ev['t'] + shift:.3g} s "
                                       f"({', '.join(ev['moved'])} moved; "
                                       "it had not settled: a change of the estimate, maybe not of the plant)"), ratio
            return "changing", f"change detected at t={ev['t'] + shift:.3g} s ({', '.join(ev['moved'])} moved)", ratio
        dis = tr.disagreement
        if dis is not None and now - dis["t"] < 1.5:
            moves = ", ".join(f"{k} {100 * v:+.0f} %" for k, v in dis["moves"].items())
            return "changing", (f"the last second disagrees with the window's estimate ({moves}, likelihood ratio "
                                f"{dis['lr']:.3g}): the plant may be changing"), ratio
        if tr.fit.sample == 0:
            rs = tr.researches[-1] if tr.researches and tr.researches[-1]["switched"] else None
            return "provisional", ("first window fit pending" if rs is None else
                                   f"resonance re-searched at t={rs['t'] + shift:.3g} s "
                                   f"({', '.join(rs['moved'])} moved)"), ratio
        held = tr.sc[W.SC_SINCE] * self._h
        if self.window_s is not None and held > 3.0 * self.window_s:    # < 5 % of the last step's weight left
            return "provisional", (f"input constant for {held:.3g} s: the window no longer holds an input change "
                                   "(the estimate is the last one the data determined)"), ratio
        if ratio > FLOOR_RATIO:
            return "degraded", f"window error {ratio:.1f}x the noise floor: the model misses part of the data", ratio
        return "", "", ratio


#: A generator's end (``next(gen, _DONE)``).
_DONE = object()


def _finite_float(x) -> bool:
    """Is the real number ``x`` finite as a float (a huge int is not)?"""
    try:
        return math.isfinite(float(x))
    except OverflowError:
        return False


def _array(x, name: str) -> np.ndarray:
    return real_array(x, f"update_block(): {name}")


def _shifted(item: dict, shift: float, kind: str | None = None) -> dict:
    """A tracker's event or re-search for the caller: private keys dropped, its times moved by ``shift`` (s) to
    stream time (non-zero after a fault's restart), and its ``kind`` if given."""
    out = {} if kind is None else {"kind": kind}
    out.update((k, v) for k, v in item.items() if not k.startswith("_"))
    if shift:
        for key in ("t", "detected_t", "settled_t", "done_t"):
            if key in out:
                out[key] += shift
    return out


def _finite(x: float, default: float = 0.0) -> float:
    x = float(x)
    return x if math.isfinite(x) else default


def _known(x: float) -> float | None:
    """x as a float, or None (not estimated) when it is not finite."""
    x = float(x)
    return x if math.isfinite(x) else None


def warm_kernels() -> None:
    """Compile (or load from numba's cache) every kernel that Python calls, so no update() pays for it."""
    from .trackers import window as T
    est = OnlineEstimator(1e-3, horizon_s=10.0, t_c=0.05)
    t = np.arange(3000) * 1e-3
    u = np.floor(t * 4) % 2
    est.update_block(u, u * 0.5 + 0.01 * np.sin(t * 50))
    for k in range(20):
        est.update(1.0, 0.5)
    est.predict_one(1.0)
    tr = est._tracker
    # what the tracker's Python calls; the re-fit's stages (their kernels compiled into the machine's) run
    # once, through begin, run and accept, and once through the per-sample kernel
    W.replay(tr.ring, 0, 4, 1, tr.st.copy(), tr.S.copy(), *W.replay_scratch(tr.p))
    W.drift_coefficients(tr.theta, tr.a1l, tr.a2l, tr.basis.lam, tr.basis.dx, np.empty(tr.q + W.ONE))
    st, S, shift = tr.st.copy(), tr.S.copy(), tr._shift.copy()
    W.set_estimate(tr.theta.copy(), st, tr.basis.lam, tr.basis.dx)
    W.snapshot(st, S, shift, tr.theta, S.copy(), np.empty(tr.p), shift.copy(), tr.theta.copy())
    RF.queue_test(tr._test_wk.copy(), 0, 1.0, True)
    RF.snapshot(st, S, tr._ctx.copy(), T.MACHINE_TEST, 0, 1.0)
    wk = tr._wk.copy()
    RF.begin(st, S, shift, wk, 1, False, True, 0, True)
    RF.run(st, S, shift, tr.theta.copy(), wk, tr.basis.lam, tr.basis.dx)
    RF.accept(st, tr.theta.copy(), wk, tr.basis.lam, tr.basis.dx)
    RF.test_outcome(wk, tr.theta)
    # the drift score test's LAPACK calls (eigvalsh, solve) bind their routines on first use, inside the
    # first score test's slice otherwise: 0.6 ms in one update() at 5.4 s of the latency stream
    k = tr.theta.size
    W.drift_score(np.eye(k) + 0.1, np.ones(k), np.ones(k), k - 2)
    RF.begin(tr.st, tr.S, tr._shift, tr._wk, 1, False, True, 0, True)      # (this estimator is thrown away)
    RF.sample_work(0.0, 0.0, tr.st, tr.S, tr.ring, tr._ctx, T.MACHINE_REFIT, 1)
    W.ring_copy(tr.ring, 0, np.empty(4), np.empty(4))
    W.swap_into(tr.st.copy(), tr.st.copy(), tr.theta, tr.basis.lam, tr.basis.dx)
    W.replay_origin(tr.st.copy(), tr.ztail, tr._free_rates, 0, 0.0)
    # a post-change search (alpha fixed) and its judged costs: their kernels otherwise load at the first change
    search = ResonanceSearch(tr.basis, u[:300] - u[0], u[:300] * 0.5, fixed_alpha=0.1,
                             extra=((0.1, 2e-3, 1e-6),), work=None)
    search.run()
    for decays in ((), T.FREE_RATES):
        for _ in search.judged_cost(0.1, 2e-3, 1e-6, decays):
            pass
    # a search of a stream taken in operation (its costs by ``search._free_fit``): the start-up search's kernels
    search = ResonanceSearch(tr.basis, u[:300] - u[0], u[:300] * 0.5, fixed_alpha=0.1, free=T.FREE_RATES,
                             starts=[(0.1, 20.0, 0.5)], work=None)
    search.run()
    for _ in search._free_gram(0.1, 2e-3, 1e-6, search.free, 2):     # (the strided rows: ``_rows_free_sparse``)
        pass
    T.WindowTracker  # noqa: B018 - imported for its kernels
    R.warm()
    rest.reading(np.linspace(0.0, 1.0, 64))          # the start's reading (a stream whose first input is not 0)
    W.noise_seed(t, t.size, np.empty(W.NOISE_SEED_ROWS))
