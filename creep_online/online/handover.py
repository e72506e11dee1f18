"""The tracker's start after the start-up search (``startup.Startup``): its state at the search's result, the
start-up buffer replayed into it, and going live once its first fit of the replayed window has finished.

Sample by sample each step takes calls of its own (no update() pays two of them), in block mode too; with
``units`` >= ``EAGER`` (a full buffer, a checkpoint) everything runs at once.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Generator

import numpy as np

from ._kernels import window as W
from .trackers.recursive import RecursiveTracker
from .trackers.window import WindowTracker

if TYPE_CHECKING:
    from .startup import Startup

#: A unit budget this large runs every step in one call (a full start-up buffer, a checkpoint).
EAGER = 1 << 29


class Handover:
    """The start-up's hand-over to the tracker (``startup``: the buffer, the reading of the start, the search)."""

    def __init__(self, startup: "Startup") -> None:
        self.startup = startup
        self.est = est = startup.est
        self.noise_scratch = np.zeros(W.NOISE_SEED_ROWS)
        self.noise_seed = 0.0              # the buffer's noise level (``buffer_noise``)
        self.replayed = 0
        # the window trackers for a stream from rest and one taken in operation, built now (``WindowTracker.start``)
        self.spares = {} if est._recursive else {free: self.window_tracker(free) for free in (False, True)}
        #: the catch-up's status buffer (``catch_up``), allocated ahead for the window trackers
        self.status = np.empty(max([t.feed_chunk for t in self.spares.values()] or [0]), dtype=np.int64)

    def window_tracker(self, free: bool) -> WindowTracker:
        """A window tracker with the estimator's settings, linearized at a placeholder resonance (fs / 20,
        zeta 0.5) until ``WindowTracker.start`` gives it the start-up search's estimate."""
        est = self.est
        lo, hi = est._bounds
        wn = 2.0 * math.pi / (20.0 * est._h)
        theta = np.array([0.5 * (lo + hi), math.log(1.0 / wn), math.log(1.0 / wn ** 2), 1.0, 0.0])
        return WindowTracker(
            est.basis, theta, window_s=est.window_s, free=free, ring=est._ring, work=self.startup.hist_work,
            gate=0.0, burst=est._burst, stuck=max(10, int(round(0.05 / est._h))), alpha_bounds=(lo, hi),
            refit_every=est._refit_every, test_every=est._test_every, detect=bool(est.detect_changes),
            drift=est._settings.memory.drift_columns if est.track_drift else 0, settings=est._settings.trackers,
            hysteresis=est._settings.memory.hysteresis_operators if "hysteresis" in est.effects else 0)

    def start_steps(self, res, compete: bool = False) -> Generator:
        """Start the tracker at the search's result (with ``compete``: at the reading of the start taken,
        ``compete``), in steps (one per call sample by sample, ``advance``): the window tracker's fresh state
        (``WindowTracker.start_state``), then its adoption; the replay of the buffer (``catch_up``) follows."""
        if compete:
            res = yield from self.startup.compete(res)
        est = self.est
        lo, hi = est._bounds
        theta = np.array([min(max(res.alpha, lo), hi), math.log(res.a1), math.log(res.a2), res.b, res.c])
        if est._recursive:
            est._tracker = RecursiveTracker(
                est.basis, theta, window_s=est.window_s, free=self.startup.in_operation, gate=0.0, burst=est._burst,
                stuck=max(10, int(round(0.05 / est._h))), alpha_bounds=(lo, hi), refit_every=est._refit_every,
                detect=bool(est.detect_changes), scale=res.b * (est._u_hi - est._u_lo), settings=est._settings.trackers)
        else:
            yield                          # (theta above, the fresh state below: ~30 us cold in one call)
            # (the other spare stays until reset(): freeing its arrays here cost ~35 us of this update())
            key = self.startup.in_operation
            if key not in self.spares:     # (used by a tracker that a fault's restart dropped)
                self.spares[key] = self.window_tracker(key)
            tracker = self.spares[key]
            tracker.start_state(theta, est._u_hi - est._u_lo)
            yield
            # the buffer's noise level in two calls of their own (``buffer_noise``): 2048 second differences spread
            # over the buffer, cold memory, then their median (together ~30 us in one update())
            k = W.noise_differences(self.startup.by, self.startup.nbuf, self.noise_scratch)
            yield
            self.noise_seed = W.noise_level(self.noise_scratch, k)
            yield
            est._tracker = self.spares.pop(key)
            est._tracker.start_adopt()
        self.startup.starting = None
        self.start_tracking()

    def buffer_noise(self) -> None:
        """The start-up buffer's noise level (``window.noise_seed``; a lead-in's still outputs left out)."""
        self.noise_seed = W.noise_seed(self.startup.by, self.startup.nbuf, self.noise_scratch)

    def start_tracking(self) -> None:
        """The tracker has started: its noise monitor at the buffer's noise level (``buffer_noise``, computed by the
        window tracker's start a call before), the replay of the buffer (``catch_up``) follows."""
        est = self.est
        if est._recursive:
            self.buffer_noise()
        est._tracker.begin_replay(self.noise_seed, adapting=not est.frozen)
        est._catchup = 1
        self.replayed = 0
        est._phase = "tracking"

    def catch_up(self, units: int) -> None:
        """Feed the buffer into the new tracker, a few samples per unit, then go live (outlier gate open)."""
        est = self.est
        tr = est._tracker
        per_unit = tr.feed_chunk
        if self.status.size < per_unit:
            self.status = np.empty(per_unit, dtype=np.int64)
        status = self.status
        lead = self.startup.lead or 0
        total = lead + self.startup.nbuf           # (the lead-in's rest first, then the buffer)
        if tr.fitting:                     # (the replay is done: waiting for the first fit, ``await_first_fit``)
            self.await_first_fit(units, total)
            return
        while units > 0 and self.replayed < total:
            units -= 1
            k = self.replayed
            # (the first unit a quarter: the new tracker's statistics and the block kernel are cold, ~27 us whole)
            n = min(per_unit if k else max(per_unit // 4, 1), total - k)
            if k < lead:
                n = min(n, lead - k)
                used = tr.feed_block(self.startup.lead_u, self.startup.lead_y, status, k, k + n)
            else:
                used = tr.feed_block(self.startup.bu, self.startup.by, status, k - lead, k - lead + n)
            self.replayed += used
            if k < lead <= self.replayed:  # the lead-in's still outputs are no sample of the sensor's noise
                tr.restart_monitors(self.noise_seed)
            if tr.busy and units > 0:      # the tracker's own jobs share the budget
                units -= 1
                tr.work(1 if units < EAGER else 1 << 30)
        if self.replayed >= total:
            tr.begin_fitting()
            self.await_first_fit(units, total)

    def await_first_fit(self, units: int, total: int) -> None:
        """The buffer replayed: go live once the tracker's first fit of the replayed window has finished. The
        start-up search's estimate comes from its grid on the search window, which a plant the model class does not
        hold (close unmodelled modes) can leave a fifth off in gain; the live predictions start from the window's
        own fit. Meanwhile the new samples are fed as live ones (the fit's slices run in the per-sample kernel),
        only their predictions are not reported. With ``EAGER`` (a full buffer, a checkpoint) it goes live at once,
        and the fit runs with the next samples."""
        est = self.est
        tr = est._tracker
        lead = self.startup.lead or 0
        while self.replayed < total:       # (the samples that arrived since: one per call sample by sample)
            k = self.replayed - lead
            tr.advance(float(self.startup.bu[k]), float(self.startup.by[k]), units)
            self.replayed += 1
        if tr.first_fit_pending and units < EAGER:
            return
        est._recovery.went_live()
        est._catchup = 0
        self.startup.nbuf = 0
        tr.go_live(est.outlier_gate)
