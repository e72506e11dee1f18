"""The start-up: buffer the stream, read how it starts, search the plant, start the tracker, replay the buffer.

``Startup.advance`` runs it in bounded steps, called by ``OnlineEstimator`` on every sample until the tracker is
live (phases ``buffering``, ``searching``, then ``tracking`` while the buffer is replayed):

1. the samples go to the buffer (``buffer``; before the input's first move only the latest are kept);
2. a stream whose first input is not zero is read: a step from rest at its first sample, or taken in operation
   (``read_start``; both readings compete when the output may show a step: ``compete``);
3. the first search's grid is planned on idle calls (``plan_grid``), the search runs in slices once the buffer spans
   the search window (``start_search``), and again on a longer window when the resonance found needs one
   (``longer_window_needed``);
4. the tracker starts at the search's result and the buffer is replayed into it, after the rest a stream read from
   rest implies (``lead_in``); it goes live after its first fit of the replayed window (``handover.Handover``).

Sample by sample each of these takes calls of its own (no update() pays two of them); block mode takes the same
steps at the same samples (``search_run``); with ``units`` >= 2^29 (a full buffer, a checkpoint) everything runs
at once. Thresholds: ``OnlineSettings.startup``; the reading of the start: ``online/rest.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Generator

import numpy as np

from ..errors import DataError
from . import rest
from .handover import EAGER, Handover
from .search import ResonanceSearch, SearchScratch, frequency_steps, grid_ends
from .trackers.window import FREE_RATES

if TYPE_CHECKING:
    from .estimator import OnlineEstimator

#: A generator's end (``next(gen, _DONE)``).
_DONE = object()


@dataclass
class GridPlan:
    """The start-up search prepared on idle buffering calls (``Startup.plan_grid``): the buffer's rows it will take,
    its grid frequencies' steps, the frequencies once computed, the search once built."""
    span: tuple[int, int]
    steps: Generator | None
    freqs: np.ndarray | None = None
    search: ResonanceSearch | None = None


class Startup:
    """The start-up's state and steps for one estimator (``est``: the stream's shared state and settings)."""

    def __init__(self, est: "OnlineEstimator") -> None:
        self.est = est
        self.cfg = cfg = est._settings.startup
        h = est._h
        self.bu = np.empty(cfg.buffer_samples)
        self.by = np.empty(cfg.buffer_samples)
        self.nbuf = 0
        # pre-faulted work memory: page faults would otherwise land inside update()
        self.bu.fill(0.0)
        self.by.fill(0.0)
        self.hist_work = np.zeros((cfg.max_search_samples, est.basis.size))
        self.hist_work.fill(0.0)
        self.first_change: int | None = None   # buffer index of the input's first change
        #: how the stream starts (``rest.py``): "rest" (its first input zero), "step" (a step from rest at its first
        #: sample), "operation" (taken in operation), None while the data do not tell yet
        self.start: str | None = None
        self.competing = False             # both readings of the start are being searched (``compete``)
        self.move_a: int | None = None     # the input's first move (buffer index) in operation's reading
        self.jump = 0.0                    # the first input level (the step's size in the step's reading)
        self.reframing: Generator | None = None   # the buffer moving to the step's frame (``read_start``)
        self.lead: int | None = None       # rest samples replayed before the buffer (``lead_in``; None: not yet)
        self.lead_u = np.zeros(rest.REST_LEAD)            # ... their inputs (0) and outputs (the rest level)
        self.lead_y = np.zeros(rest.REST_LEAD)
        self.start_wait = max(64, min(int(rest.WAIT_S / h), cfg.buffer_samples // 2))   # (``rest.WAIT_S``)
        self.t_need = max(cfg.first_window_s, cfg.first_window_samples * h)
        self.search: ResonanceSearch | None = None
        self.search_scratch = SearchScratch(est.basis.size)
        self.search_scratch.prepare_judge(FREE_RATES, est.basis.h)   # (a start-up search in operation's)
        self.grid_plan: GridPlan | None = None
        self.search_rounds = 0
        self.search_end = 0                # end (buffer index) of the last start-up search's rows
        self.plan_waits = 0                # ready calls spent on the plan (``plan_pending``)
        self.tc_used = 0.0
        self.starting: Generator | None = None      # the tracker's start under way (``Handover.start_steps``)
        self.restarted = False             # restarted in operation after a fault: the plant was not at rest
        self.hint: tuple | None = None     # (alpha, a1, a2) before a fault's restart: a candidate of the search
        self.handover = Handover(self)     # the tracker's start, the buffer's replay, going live
        self.eager = False                 # the current call runs everything at once (``advance``: a checkpoint)

    # ------------------------------------------------------------------ the buffer
    def buffer(self, du: float, y: float) -> None:
        """Append to the start-up buffer (before any input change only the last samples are kept)."""
        cfg = self.cfg
        k = self.nbuf
        if self.first_change is None and k >= cfg.idle_buffer and self.start is not None:  # no excitation: the latest
            keep = cfg.idle_keep
            self.bu[:keep] = self.bu[k - keep:k]
            self.by[:keep] = self.by[k - keep:k]
            k = keep
        if k == self.bu.size:
            if self.first_change is None:
                if self.start is None:       # (a held input whose output never showed a step: the first sample goes)
                    self.start = "operation"
                keep = cfg.idle_keep
                self.bu[:keep] = self.bu[k - keep:k]
                self.by[:keep] = self.by[k - keep:k]
                k = keep
            else:                            # the search cannot keep up: finish it now
                self.advance(1 << 30)
                if self.est._live is not None:
                    self.est._live.feed(du, y)
                    return
                raise DataError("start-up buffer overflow: the stream is too fast for the search")
        self.bu[k] = du
        self.by[k] = y
        self.nbuf = k + 1

    def quiet_samples(self) -> int:
        """Block mode: how many samples the buffer can take now, one after the other, with every ``advance`` after
        them doing nothing (0: the next sample must go through ``buffer`` and ``advance``). Before the input's first
        move (the caller ends the run at it): up to the sample at which ``buffer`` would keep only the latest or
        ``read_start`` would read the start. After it: once the rest's lead and the search's plan are settled (or a
        search has run), up to the sample that makes the buffer ready for the search (the search's rows depend on
        the sample it starts at) or full."""
        est = self.est
        if est._phase != "buffering" or self.reframing is not None:
            return 0
        if self.first_change is None:
            room = (self.cfg.idle_buffer if self.start is not None else self.bu.size) - self.nbuf
            if self.start is None and not self.competing:
                room = min(room, self.start_wait - self.nbuf % self.start_wait - 1)
            return max(0, room)
        if self.lead is None and not self.in_operation:
            return 0
        plan = self.grid_plan
        if self.search is None and (plan is None or plan.search is None):
            return 0
        before_ready = math.ceil(self.t_search() / est._h - (self.nbuf - self.first_change)) - 1
        return max(0, min(before_ready, self.bu.size - self.nbuf))

    def buffer_run(self, du: np.ndarray, y: np.ndarray) -> None:
        """``buffer`` for each of a quiet run of samples (``quiet_samples``), at once."""
        k, m = self.nbuf, du.size
        self.bu[k:k + m] = du
        self.by[k:k + m] = y
        self.nbuf = k + m

    def ready_to_search(self) -> bool:
        return self.first_change is not None and self.nbuf - self.first_change >= self.t_search() / self.est._h

    def t_search(self) -> float:
        return self.t_need if self.est.t_c is None else float(self.est.t_c)

    @property
    def in_operation(self) -> bool:
        """Does the buffer start with the plant not at rest? A stream whose first input is not zero, and every
        buffer after a fault's restart: the searches and the tracker then fit free responses."""
        return self.restarted or bool(self.est._u_ref)

    # ------------------------------------------------------------------ the steps
    def advance(self, units: int) -> None:
        """Buffering and searching: start the search when ready, give it ``units``, start the tracker.

        Sample by sample the search's end, the tracker's start steps and the replay's first unit each take
        a call of their own (``start_steps``): together they were one update() of ~80-120 us. The estimate
        reads "searching" until the tracker has started, a few samples later. With ``units`` >= ``EAGER``
        (a full buffer, a checkpoint) everything runs in this call."""
        est = self.est
        eager = self.eager = units >= EAGER
        while self.reframing is not None:      # (the step's reading's buffer moving to its frame, a chunk per call)
            if next(self.reframing, _DONE) is _DONE:
                self.reframing = None
            if not eager:
                return
        if self.lead is None and self.first_change is not None and not self.in_operation:
            self.lead_in()
            if not eager:
                return
        if est._phase == "buffering":
            if self.start is None and not self.competing and self.read_start():
                return
            if not self.ready_to_search() or self.plan_pending():
                self.plan_grid()
                return
            self.start_search()
            units -= 1
        if est._phase == "searching":
            if self.starting is None:
                self.search_units(units)
                if not self.search_landed() or not eager:
                    return
            for _ in self.starting:
                if not eager:
                    return
            if not eager:                  # started in this call: the replay from the next
                return
        if est._catchup:
            self.handover.catch_up(max(units, 1))

    def search_units(self, units: int) -> bool:
        """Up to ``units`` steps of the search under way (``eager``: each candidate's rows in one kernel call); returns
        whether one of them finished it (the steps left then go unused, as in ``advance``)."""
        s = self.search
        s.eager = self.eager
        while units > 0 and not s.step():
            units -= 1
        return units > 0

    def search_landed(self) -> bool:
        """After the search's steps of a call: has it ended with a result to start the tracker at (the tracker's
        start, ``Handover.start_steps``, is then under way), rather than still running or wanting a longer window?"""
        res = self.search.result
        if res is None or self.longer_window_needed(res):
            return False
        self.starting = self.handover.start_steps(res, compete=self.competing)
        return True

    def search_run(self, limit: int) -> int:
        """Block mode while the start-up search runs and nothing else of the start-up is under way: the search's
        steps of up to ``limit`` samples, ``units`` a sample as update()'s ``advance`` gives them, up to the sample
        whose steps finish it; returns how many samples (0: the next goes through ``advance``). The caller buffers
        them at once (the search reads only rows already buffered) and, if the search finished, calls
        ``search_landed`` as ``advance`` does after that sample's steps."""
        est = self.est
        if (est._phase != "searching" or self.starting is not None or self.reframing is not None
                or self.lead is None and not self.in_operation):
            return 0
        units, self.eager = est._units, False      # (``advance`` with update()'s budget)
        for j in range(min(limit, self.bu.size - self.nbuf)):
            if self.search_units(units):
                return j + 1
        return min(limit, self.bu.size - self.nbuf)

    def read_start(self) -> bool:
        """A stream whose input is at a non-zero level from its first sample: a step from rest there, or taken in
        operation (``rest``)? Read when the search in operation is ready (the input has moved: if the output may show
        a step, both readings compete, ``compete``), or every ``rest.WAIT_S`` while the input holds (the step's
        reading once the output shows one; until then the buffer keeps the first sample). Returns whether this call
        read it."""
        est = self.est
        n = self.nbuf
        moved = self.first_change is not None
        if not (self.ready_to_search() if moved else n % self.start_wait == 0):
            return False
        near, step = rest.reading(self.by[:n])
        if not near:
            self.start = "operation"
            self.keep_latest_before_move()
            return True
        if not (moved or step):
            return True                    # (near rest, not moved yet: read again after another WAIT_S)
        self.competing = moved
        if not moved:
            self.start = "step"
        self.move_a = self.first_change
        self.jump = est._u_ref
        est._u_lo, est._u_hi = min(est._u_lo, 0.0), max(est._u_hi, 0.0)
        self.reframing = self.reframe(0.0)   # (in the next calls)
        next(self.reframing)               # (the frame itself now: samples from the next call on are in it)
        self.first_change = 0
        self.grid_plan = None
        return True

    def keep_latest_before_move(self) -> None:
        """A stream read in operation after its input moved: of the samples before the move, the latest ``idle_keep``
        only if there were ``idle_buffer`` of them, as ``buffer`` drops them while the input holds (the reading kept
        them all). A held input's are dropped by ``buffer`` itself."""
        fc = self.first_change
        if fc is None or fc < self.cfg.idle_buffer:
            return
        drop = fc - self.cfg.idle_keep
        n = self.nbuf - drop
        self.bu[:n] = self.bu[drop:drop + n]
        self.by[:n] = self.by[drop:drop + n]
        self.nbuf = n
        self.first_change = fc - drop
        self.grid_plan = None

    def lead_in(self) -> None:
        """A stream read from rest: the rest it implies before its first sample, if it shows too little of it
        (``rest.lead_in``): input 0, output at the mean of its rest outputs (those up to its first input change),
        replayed into the tracker before the buffer (``catch_up``; the searches start at the first change and need
        no more rest). The tracker's time then runs that many samples ahead of the stream's (``_n_shift``)."""
        fc = self.first_change
        lead = rest.lead_in(fc + 1)
        outputs = [v for v in self.by[:min(fc + 1, self.nbuf)].tolist() if v == v] if lead else []
        self.lead = lead if outputs else 0     # (plain Python on <= REST_LEAD values: numpy's nanmean was ~100 us cold)
        if self.lead:
            self.lead_y[:lead] = sum(outputs) / len(outputs)
            self.est._n_shift -= lead

    def reframe(self, u_ref: float) -> Generator:
        """The buffered inputs as deviations from ``u_ref`` (0: the step's reading, the input 0 before the first
        sample; the first level: the stream in operation), ``reframe_chunk`` per unit; samples that arrive meanwhile
        are buffered in the new frame."""
        est = self.est
        shift, est._u_ref = est._u_ref - u_ref, u_ref
        n = self.nbuf
        chunk = self.cfg.reframe_chunk
        yield                              # (the frame is set: the caller's next samples are buffered in it)
        for k in range(0, n, chunk):
            self.bu[k:min(k + chunk, n)] += shift
            yield

    def compete(self, step) -> Generator:
        """Both readings of the start on the samples the step's search had (``rest``, stage 2): the buffer in the
        in-operation frame, its search (the step's result a candidate), the costs compared; the buffer in the frame
        taken. In units; returns the search result to start the tracker at.

        The in-operation search refines the step's search's candidates (its ``starts``) instead of running a grid of
        its own: both readings share the plant's resonance, only the start's free responses differ, and a grid of
        its own takes several times the units (one per sample) for the same reading."""
        rows = self.search_end             # (the step's search: from the first sample)
        starts = [c[1:] for c in self.search.candidates] or None
        yield from self.reframe(self.jump)
        search = ResonanceSearch(self.est.basis, self.bu[:rows], self.by[:rows],
                                 extra=((step.alpha, step.a1, step.a2),), work=self.hist_work,
                                 scratch=self.search_scratch, free=FREE_RATES, starts=starts)
        while True:
            search.eager = self.eager
            if search.step():
                break
            yield
        operation = search.result
        self.competing = False
        if rest.prefer_step(step.cost, operation.cost, rows, 2 + len(FREE_RATES)):
            self.start = "step"
            yield from self.reframe(0.0)
            return step
        self.start = "operation"
        self.est._n_shift += self.lead or 0   # (no rest to replay in operation)
        self.lead = 0
        self.first_change = self.move_a
        return operation

    # ------------------------------------------------------------------ the search
    def search_span(self, nbuf: int) -> tuple[int, int]:
        """(start, end) in the buffer of the search that starts with ``nbuf`` samples buffered: from rest, the search
        window after the first change (a step read at the first sample after a held second has a whole second
        buffered: searched at a stride, a fast mode's transient fell between the rows and the search took a slower
        resonance); in operation, and for the step's reading in a competition (``compete``: it must meet the input's
        moves that the in-operation reading is searched on), everything buffered."""
        most = self.cfg.max_search_samples
        if self.in_operation:
            return 0, min(nbuf, most)
        start = max(0, self.first_change - 1)
        end = nbuf if self.competing else self.first_change + math.ceil(self.t_search() / self.est._h)
        return start, min(nbuf, end, start + most)

    def plan_grid(self) -> None:
        """On an idle buffering call, one step of the search that starts when the buffer is ready: its grid
        frequencies (``search.frequency_steps``, a few numpy calls), then its construction (the buffer's rows
        to come are views of memory already there). Its first unit, in the update() that fills the buffer,
        then does neither (~35 us of cold numpy and ~10 us of cold Python). Only the first search has a grid (later
        ones refine its candidates); the plan is used only if its rows are the search's (``start_search``)."""
        plan = self.grid_plan
        if self.first_change is None or self.search is not None or plan is not None and plan.search is not None:
            return
        if plan is None:
            start, end = self.search_span(self.first_change + math.ceil(self.t_search() / self.est._h))
            self.grid_plan = GridPlan((start, end), frequency_steps(*grid_ends(end - start, self.est._h)))
            return
        if plan.freqs is None:
            try:
                next(plan.steps)
            except StopIteration as done:
                plan.freqs = done.value
            return
        plan.search = self.new_search(*plan.span, plan.freqs)

    def plan_pending(self) -> bool:
        """Is the first search's plan (``plan_grid``) still being prepared although the buffer is ready? A step read
        at the first sample finds its buffer full at once: the few calls of the plan come first (unplanned, the
        search's construction and first unit were ~170 us in one update()). Not in a competition of the start's
        readings (its search takes every buffered sample, not the plan's rows)."""
        plan = self.grid_plan
        if (self.search is not None or self.competing or self.first_change is None
                or plan is not None and plan.search is not None or self.plan_waits >= self.cfg.plan_waits):
            return False
        self.plan_waits += 1
        return True

    def finish_plan(self) -> None:
        """Before a checkpoint (generators cannot be pickled): the grid's frequencies computed, the prepared search
        dropped (it is built again, the same, when the buffer is ready)."""
        plan = self.grid_plan
        if plan is None:
            return
        if plan.freqs is None and plan.steps is not None:
            try:
                while True:
                    next(plan.steps)
            except StopIteration as done:
                plan.freqs = done.value
        plan.steps = None
        plan.search = None

    def start_search(self) -> None:
        est = self.est
        start, end = self.search_span(self.nbuf)
        self.search_end = end
        plan, self.grid_plan = self.grid_plan, None
        planned = plan is not None and plan.span == (start, end)
        if planned and plan.search is not None:
            self.search = plan.search
        else:
            self.search = self.new_search(start, end, plan.freqs if planned else None)
        self.tc_used = (end - start) * est._h
        est._phase = "searching"

    def new_search(self, start: int, end: int, freqs: np.ndarray | None) -> ResonanceSearch:
        """The search over the buffer's rows [start, end) (some may be still to come), with the grid's
        frequencies ``freqs`` if computed ahead; after a first search it refines that one's candidates."""
        est = self.est
        prev = self.search
        starts = [c[1:] for c in prev.candidates] if prev is not None and prev.candidates else None
        alphas = () if est.alpha0 is None else (float(est.alpha0),)
        # in operation the buffer starts in the fading memory of an unknown past input: the search projects it
        # out (the tracker's free responses), as it does the unknown resonance state (``ResonanceSearch`` free)
        extra = () if self.hint is None else (self.hint,)     # (a fault's restart: the estimate before it)
        return ResonanceSearch(est.basis, self.bu[start:end], self.by[start:end], alphas=alphas,
                               extra=extra, work=self.hist_work, starts=starts, scratch=self.search_scratch,
                               freqs=freqs, free=FREE_RATES if self.in_operation else None)

    def longer_window_needed(self, res) -> bool:
        """After a search: grow the buffer to ``settling_windows`` settling times of the resonance found and search
        again; or, if the result sits on the search box's edge (``ResonanceSearch.at_bound``: held by the box, not
        shown by the data), to ``box_growth`` times the window (a slow mode searched on a short window comes out as a
        fast, over-damped one with alpha near its bound: the tracker would start there)."""
        est, cfg = self.est, self.cfg
        if est.t_c is not None or self.search_rounds >= cfg.search_rounds:
            return False
        settle = 8.0 * res.a2 / res.a1
        held = cfg.box_growth * self.t_need if self.search.at_bound(res) else 0.0
        want = min(max(cfg.settling_windows * settle, held, cfg.first_window_s, cfg.first_window_samples * est._h),
                   float(est.t_c_max), cfg.max_search_samples * est._h * 0.95)
        if want <= 1.05 * self.t_need:
            return False
        self.search_rounds += 1
        self.t_need = want
        est._phase = "buffering"
        return True

    # ------------------------------------------------------------------ after a fault or an outage
    def restart_on(self, k: int) -> None:
        """Start again in operation on the ``k`` samples now at the head of the buffer (a fault's restart)."""
        self.restarted = True
        self.lead = 0                      # (in operation: no rest to replay)
        self.nbuf = k
        moves = np.flatnonzero(self.bu[1:k] != self.bu[:k - 1]) if k > 1 else ()
        self.first_change = int(moves[0]) + 1 if len(moves) else None

    def restart_empty(self) -> None:
        """Start again in operation on new samples (the buffer dropped)."""
        self.restarted = self.restarted or self.first_change is not None
        if self.start is None:             # (the stream's first samples are gone: a step there can no longer show)
            self.start = "operation"
            self.competing = False
        self.lead = 0
        self.nbuf = 0
        self.first_change = None
