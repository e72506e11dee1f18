"""The online estimator: all four parameters of b / (s^alpha (1 + a1 s + a2 s^2)), live, with bounded work.

Phases (``OnlineEstimate.phase``):

``buffering``
    Samples are kept until the input has moved and the buffer spans the
    search window (``t_c``; chosen from the data when None).
``searching``
    A global search over (alpha, fn, zeta) on the buffer (``search.py``), in
    small slices: no starting guess is needed. If the resonance found needs a
    longer window, the buffer grows and the search runs again (``startup.py``).
``tracking``
    The tracker replays the buffer and follows the plant. Two strategies
    (docs/online.md, "Remark 3: window vs recursive"; ``refit``): ``"window"`` (default, ``tracker.py``)
    recomputes over the window; ``"recursive"`` (``recursive.py``) carries on with the newest estimate (a
    Gauss-Newton recursive prediction-error method with a CUSUM change detector, constant work per sample, no
    replay, no drift model). The window tracker: a Levenberg-Marquardt re-fit of all four parameters on the exact
    exponentially forgotten window cost every ``update_every_s``, a likelihood-ratio change test every half second
    (a change restarts the window; ``estimate.events`` lists them), and a re-linearization by replay when the
    resonance moves. With ``track_drift`` the window model also has a linear drift of b and alpha, switched on
    when the data show it (``estimate.b_rate``, ``alpha_rate``); alpha and b are then the values now.
    The estimator uses a tracker only through ``trackers.Tracker`` (``trackers/protocol.py``).

Work per ``update()``: one sample of O(P^2) statistics (~1 us) plus at most
``work_units`` units of background work (up to ~15 us each: a unit's Python
costs ~3 us, so few large units keep the calls over 5 us rare). The default
unit count is ``max(1, floor(dt / 100 us))``: one unit at 10 kHz, 10 at 1 kHz,
50 at 200 Hz, i.e. at most ~15 % of the sample period.

Robustness: an output whose innovation exceeds ``outlier_gate`` robust scales
is not used (a run longer than ``burst_s`` is accepted: a shift is a change, not
an outlier); an input sample far outside the range seen so far is held by the input gate
(``policy/input_gate.py``, ``inputs.py``) until it is known as a glitch or a move; an output frozen while
the model says it should move is reported (``quality="degraded"``; the quality rule: ``policy/quality.py``).

Error contract: bad input raises ``DataError`` (non-numbers) or is skipped and
counted (NaN, inf). Any other exception raised inside ``update()``,
``update_block()`` or ``gap()`` is the library's own fault (a numerical bug): it is counted
(``internal_faults``), recorded as an event of kind ``"internal_fault"``, and recovered from
(``recovery.py``), never raised into the caller's loop; so is a non-finite estimate or statistic (checked at
every scheduled re-fit or test). Reading ``estimate`` never raises and never changes the estimator's
course: a fault it finds is reported at once (quality ``degraded``) and recorded and recovered from at the next
sample fed. Until the estimator has re-converged the quality reads ``degraded`` with the fault as reason.

The rules' thresholds are ``settings.OnlineSettings`` (the ``settings`` argument); docs/ARCHITECTURE.md maps each
rule to its module.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..checks import count, is_real, number, real_array
from ..errors import DataError
from ..model import ONLINE_ALPHA_BOUNDS, ONLINE_REFITS, CreepModel
from .checkpoint import Checkpointable
from .inputs import InputStage
from .recovery import PASS_THROUGH, Recovery
from .report import OnlineEstimate, build_estimate, shifted
from .settings import DEFAULT_SETTINGS, OnlineSettings, check_effects
from .soe import DEFAULT_DX, DEFAULT_HORIZON_S, SOE_TOP, SoeBasis
from .startup import Startup
from .stored_params import StoredParams
from .trackers import Tracker
from .warmup import warm_kernels

__all__ = ["OnlineEstimator", "OnlineEstimate", "warm_kernels", "PHASES", "QUALITIES", "INPUT_GATE"]

PHASES = ("buffering", "searching", "tracking")
QUALITIES = ("none", "provisional", "good", "changing", "degraded")
#: Default ``input_gate``: an input further than this many input ranges from the last accepted one is a glitch
#: candidate (``policy/input_gate.py``).
INPUT_GATE = 20.0
#: The two Remark-3 strategies (``refit``): recompute over the window, or carry on recursively.
REFITS = ONLINE_REFITS


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
    settings:       the rules' thresholds (``online.settings.OnlineSettings``; None: the defaults).
    effects:        effects estimated with the creep: () none, ``("hysteresis",)`` (``settings.check_effects``).
    """

    def __init__(self, dt: float, *, window_s: float | None = 10.0, update_every_s: float = 0.1,
                 t_c: float | None = None, alpha0: float | None = None,
                 horizon_s: float = DEFAULT_HORIZON_S, soe_dx: float = DEFAULT_DX,
                 alpha_bounds: tuple[float, float] = ONLINE_ALPHA_BOUNDS, t_c_max: float = 2.0,
                 outlier_gate: float = 8.0, burst_s: float = 0.002, input_gate: float = INPUT_GATE,
                 detect_changes: bool = True,
                 work_units: int | None = None, track_drift: bool = True, refit: str = "window",
                 settings: OnlineSettings | None = None, effects: tuple[str, ...] = ()) -> None:
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
        self.refit, self.settings, self.effects = refit, settings, effects
        self._validate()
        self.reset()

    # ------------------------------------------------------------------ parameters
    def _validate(self) -> None:
        if self.settings is not None and not isinstance(self.settings, OnlineSettings):
            raise DataError(f"settings must be an OnlineSettings or None, got {self.settings!r}")
        cfg = self.settings or DEFAULT_SETTINGS
        min_window, buffer = cfg.memory.min_window_samples, cfg.startup.buffer_samples

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
        check_effects(self.effects, self.refit)
        if self.horizon_s <= self.dt:
            raise DataError(f"horizon_s ({self.horizon_s}) must exceed dt ({self.dt})")
        if self.window_s is not None and self.window_s < min_window * self.dt:
            raise DataError(f"window_s ({self.window_s:g} s) must hold at least {min_window} samples "
                            f"({min_window * self.dt:g} s at dt = {self.dt:g} s)")
        if self.t_c is not None and self.t_c > (buffer // 2) * self.dt:
            raise DataError(f"t_c ({self.t_c:g} s) is longer than the start-up buffer holds "
                            f"({(buffer // 2) * self.dt:g} s at dt = {self.dt:g} s)")

    # ------------------------------------------------------------------ lifecycle
    def reset(self) -> "OnlineEstimator":
        """Forget everything: derived settings rebuilt, back to buffering, counters to zero.

        The stream's shared state lives here (the per-sample path reads it directly); the start-up
        (``Startup``), the input gate's held samples (``InputStage``) and the fault record (``Recovery``) keep
        their own."""
        h = float(self.dt)
        self._h = h
        self._settings = cfg = self.settings or DEFAULT_SETTINGS
        self.basis = SoeBasis.build(h, horizon_s=float(self.horizon_s), dx=float(self.soe_dx), top=SOE_TOP)
        self._units = self.work_units or max(1, int(h / 100e-6))
        self._bounds = tuple(float(v) for v in self.alpha_bounds)     # alpha's (lo, hi) as floats
        self._refit_every = max(5, int(round(self.update_every_s / h)))
        self._test_every = max(10, int(round(0.5 / h)))
        self._history = int(min(cfg.memory.max_history, max(1024, 3 * (self.window_s or 30.0) / h)))
        self._burst = max(2, int(round(self.burst_s / h)))
        self._recursive = self.refit == "recursive"
        self.samples = 0
        self.skipped_nonfinite = 0
        self.internal_faults = 0
        self.gaps = 0
        self.input_outliers = 0
        self.frozen = False
        self._frozen_t = 0.0               # stream time of freeze()
        self._phase = "buffering"
        self._n_shift = 0                  # stream samples before the tracker's first (a lead-in's or restart's)
        self._u_ref: float | None = None   # the input reference: inputs are fed as deviations from it
        self._u_lo = self._u_hi = 0.0      # the input's range seen so far
        self._u_last = 0.0                 # the last accepted input
        self._held: list[tuple[float, float]] = []           # glitch candidates (u, y) not yet decided
        self._backlog: deque[tuple[float, float]] = deque()   # decided samples (du, y) the live tracker awaits
        self._deferred = False             # either is non-empty (or a read found a fault): update()'s slow path
        self._tracker: Tracker | None = None
        self._catchup = 0                  # the start-up buffer is being replayed into the tracker
        self._ring = np.zeros((2, self._history))
        self._ring.fill(0.0)
        self._recovery = Recovery(self)
        self._inputs = InputStage(self)
        self._startup = Startup(self)
        return self

    def freeze(self) -> None:
        """Stop adapting: samples still advance the states and the predictions; the estimate stays, and its quality
        judges it against the new samples (``policy.quality.frozen_quality``)."""
        if not self.frozen:
            self._frozen_t = self.samples * self._h
        self.frozen = True
        if self._tracker is not None:
            self._tracker.adapting = False

    def unfreeze(self) -> None:
        """Resume adapting."""
        self.frozen = False
        if self._tracker is not None:
            self._tracker.adapting = True

    # ------------------------------------------------------------------ checkpoint (pickle, deepcopy)
    def _checkpoint(self) -> None:
        """Finish the background work under way now (``checkpoint``: generators cannot be pickled): the grid's
        frequencies, the start-up search with all its rows in and the tracker's start and replay, the tracker's
        queued jobs. The prepared search of a buffer still filling is dropped (it is built again, the same, when
        the buffer is ready). An internal fault meanwhile is caught and recovered from as in update()."""
        try:
            self._startup.finish_plan()
            if self._phase == "searching" or self._startup.starting is not None or self._catchup:
                self._startup.advance(1 << 30)
            if self._tracker is not None:
                self._tracker.drain()
        except PASS_THROUGH:
            raise
        except Exception as exc:  # noqa: BLE001 - the error contract, as in update()
            self._recovery.fault(exc, "checkpoint")

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
        rec = self._recovery
        shift = self._n_shift * self._h
        live = [] if self._tracker is None else [shifted(ev, shift, "change") for ev in self._tracker.report_events()]
        events = rec.past_events + live
        if rec.faults:
            events = sorted(events + rec.faults, key=lambda ev: ev["t"])
        return events

    @property
    def researches(self) -> list[dict]:
        """The tracker's re-searches of the resonance (and those of trackers a fault's restart dropped)."""
        shift = self._n_shift * self._h
        live = [] if self._tracker is None else [shifted(r, shift) for r in self._tracker.researches]
        return self._recovery.past_researches + live

    @property
    def estimate(self) -> OnlineEstimate:
        """The current answer. Never raises and never restarts anything: a fault found while it is built (or a
        non-finite state) is reported at once (the bare answer, quality degraded, the fault named) and recorded
        and recovered from at the next sample fed (module docstring: error contract)."""
        try:
            tr = self._tracker
            if tr is not None and not tr.state_finite():
                return self._recovery.defer(None)
            return build_estimate(self)
        except PASS_THROUGH:
            raise
        except Exception as exc:  # noqa: BLE001 - the error contract: an internal fault never reaches the caller
            return self._recovery.defer(exc)

    def predict_one(self, u: float) -> float | None:
        """Model output at the next sample if u is applied now (no state change); None without a model."""
        tr = self._tracker
        if tr is None or self._phase != "tracking":
            return None
        return tr.predict_next(float(u) - (self._u_ref or 0.0))

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
            tr = self._tracker if self._catchup == 0 else None    # (``_live`` inlined: the per-sample path)
            if tr is None:
                if self._recovery.pending is not None:
                    self._recovery.settle_pending()
                self._inputs.buffer_sample(u, y)
                self._startup.advance(self._units)
                return
            if self._u_lo <= u <= self._u_hi and not self._deferred:
                self._u_last = u
                du = u - self._u_ref
            elif not self._deferred and not self._inputs.glitch_candidate(u):
                du = self._inputs.accept(u)    # the range grows (no glitch candidate): still the direct path
            else:
                if self._recovery.pending is not None:
                    self._recovery.settle_pending()
                    if self._live is not tr:   # (restarted: the sample goes to the start-up)
                        self._inputs.buffer_sample(u, y)
                        self._startup.advance(self._units)
                        return
                self._inputs.update_deferred(tr, u, y)
                return
            if not tr.advance(du, y, self._units):
                self._recovery.fault(None, "update")
        except PASS_THROUGH:
            raise
        except Exception as exc:  # noqa: BLE001 - the error contract: an internal fault never reaches the loop
            self._recovery.fault(exc, "update")

    def update_block(self, u: np.ndarray, y: np.ndarray) -> None:
        """Feed many samples: the estimates of repeated update() (``==``, any chunking: the background work lands at
        update()'s sample, ``_feed_block``).

        Raises only ``DataError`` (arrays that cannot be used). An internal fault is caught, counted and recovered
        from, and the block goes on from the sample after the one it came in (``_block_from``)."""
        u = real_array(u, "update_block(): u")
        y = real_array(y, "update_block(): y")
        if u.shape != y.shape:
            raise DataError(f"update_block(): u and y differ in length ({u.size} vs {y.size})")
        ok = np.isfinite(u) & np.isfinite(y)
        if not ok.all():
            self.skipped_nonfinite += int(u.size - np.count_nonzero(ok))
            u, y = u[ok], y[ok]
        if self._recovery.pending is not None and u.size:
            self._recovery.settle_pending()
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
            self._recovery.fault(exc, "update_block")
        return max(done[0], k + 1)

    def _feed_block(self, u: np.ndarray, y: np.ndarray, done: list[int]) -> None:
        """update_block()'s work from ``done[0]`` on. ``done[0]``: samples taken (counted in ``samples``); in the
        tracker's loop it is advanced by the tracker's own sample count, which its kernel moves per sample, so a
        fault inside leaves it exact. While work is under way (``Tracker.pending``) it runs update()'s course
        (``feed_pending``), else the block kernel up to the next scheduled job: update()'s course in fewer calls."""
        n = u.size
        i = self._inputs.buffer_until_live(u, y, done)
        if i == n:
            return
        du, yy, exact = self._inputs.block(u[i:], y[i:])
        status = np.empty(du.size, dtype=np.int64)
        tr = self._live
        n0, s0, j = tr.n, self.samples, 0
        # the arrays are the samples as they came unless the input gate kept some back or had some waiting: then
        # all of u[i:] is taken (decided or held), and a fault leaves the rest of du, yy waiting (``block_resync``)
        self._recovery.block_progress = (tr, n0, s0, i, done, None if exact else (du, yy, n))
        while j < du.size:
            if tr.pending:                   # background work under way: update()'s course (``feed_pending``)
                used, finite = tr.feed_pending(du[j:], yy[j:], status[j:], self._units)
                j += used
            else:                            # none: the block kernel up to the next scheduled job
                j += tr.feed_block(du[j:], yy[j:], status[j:])
                finite = tr.state_finite()
            self.samples = s0 + (j if exact else n - i)
            done[0] = i + j if exact else n
            if not finite:
                self._recovery.fault(None, "update_block")
                tr = self._live
                if tr is None or not exact:  # restarted: the rest of the block goes through the start-up (what
                    self._recovery.block_progress = None   # the gate had decided waits: ``block_resync``)
                    return self._feed_block(u, y, done)
        self._recovery.block_progress = None
        if not exact:                        # (every sample of the block may still be held)
            self.samples = s0 + (n - i)
            done[0] = n

    def gap(self, n: int) -> None:
        """n samples were lost (sequence counter): time advances with the input held, no output used.

        Internal faults are caught as in update() (one per lost sample at most). A run longer than
        ``OnlineSettings.recovery.gap_replay_max`` restarts the tracker instead (``Recovery.outage``)."""
        n = count(n, "gap(): n (lost samples)", minimum=0, maximum=1 << 62)
        if n == 0:
            return
        if self._recovery.pending is not None:
            self._recovery.settle_pending()
        if n > self._settings.recovery.gap_replay_max:
            self._recovery.outage(n)
            return
        self.gaps += n
        if self._deferred:
            self._inputs.settle()
        du = self._u_last - (self._u_ref or 0.0)
        for _ in range(n):
            self.samples += 1
            try:
                if self._live is not None:
                    self._live.feed(du, math.nan)
                else:
                    self._startup.buffer(du, math.nan)
            except PASS_THROUGH:
                raise
            except Exception as exc:  # noqa: BLE001 - the error contract: an internal fault never reaches the loop
                self._recovery.fault(exc, "gap")

    @property
    def _live(self) -> Tracker | None:
        """The tracker once it is fed directly (after the start-up buffer has been replayed)."""
        return self._tracker if self._catchup == 0 else None


def _finite_float(x) -> bool:
    """Is the real number ``x`` finite as a float (a huge int is not)?"""
    try:
        return math.isfinite(float(x))
    except OverflowError:
        return False
