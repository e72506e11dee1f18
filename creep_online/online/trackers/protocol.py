"""What the online estimator needs of a tracker (``Tracker``), and nothing more.

A tracker follows the plant once the start-up search has found it: it takes the samples one by one (or in
blocks), keeps the estimate current with bounded work per sample and reports what the estimator shows.
``WindowTracker`` (a re-fit over the forgetting window) and ``RecursiveTracker`` (a recursive prediction-error
method) both satisfy it; the estimator reads and calls only these members, so a third strategy needs only them.

Inputs are deviations from the estimator's input reference (``u`` "as applied"); ``y`` NaN is a lost output.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Tracker(Protocol):
    """The tracker interface of ``OnlineEstimator``."""

    # ---------------------------------------------------------------- the estimate
    alpha: float
    a1: float
    a2: float
    b: float
    offset: float
    b_rate: float                       #: drift of b per second (0 while not modelled)
    alpha_rate: float                   #: drift of alpha per second (0 while not modelled)
    drift_on: bool                      #: the drift rates are fitted now
    hysteresis: dict | None             #: the live PI loop {"r", "w", "initial"}; None: none, or no fit yet
    fit: "object"                       #: the last fit: ``std`` (1-sigma by name), ``cost``, ``neff``, ``sample``
    n: int                              #: samples fed
    prediction: float                   #: model output for the latest sample
    refits: int                         #: fits (or recursive updates) done
    rejected: int                       #: fits rejected (the previous estimate kept)
    relinearizations: int
    events: list                        #: detected changes (dicts, tracker time; read them by ``report_events``)
    researches: list                    #: re-searches of the resonance (dicts, tracker time)
    disagreement: dict | None           #: the last change test, if the last second disagreed with the window
    feed_chunk: int                     #: samples per unit of work when a buffer is replayed
    busy: bool                          #: background jobs are queued
    pending: bool                       #: background work is under way (jobs queued, or a fit in the kernel)
    first_fit_pending: bool             #: the first fit after the start-up's replay has not finished yet

    # ---------------------------------------------------------------- monitors
    noise_level: float                  #: the output noise's standard deviation
    live_error_power: float             #: mean square live prediction error (the last ~0.2 s)
    outliers: int
    shifts: int
    output_stuck: bool
    input_held_samples: float           #: samples since the input last changed
    adapting: bool                      #: settable; False while the estimator is frozen
    remembered_window: int              #: samples of the current window a restart can search again

    # ---------------------------------------------------------------- feeding
    def advance(self, u: float, y: float, units: int, work: bool = True) -> bool:
        """One live sample and its share of the background work; False: the state was found non-finite."""

    def feed_pending(self, u: np.ndarray, y: np.ndarray, status: np.ndarray, units: int) -> tuple[int, bool]:
        """Block mode while work is under way: ``advance``'s course on the leading samples; (consumed, finite)."""

    def feed(self, u: float, y: float) -> int:
        """One sample without background work; the kernel's status."""

    def feed_block(self, u: np.ndarray, y: np.ndarray, status: np.ndarray, start: int = 0, stop: int = -1) -> int:
        """Samples ``start`` to ``stop`` up to the next scheduled job; how many were taken."""

    def work(self, units: int = 1) -> bool:
        """Up to ``units`` units of the queued jobs."""

    def finish(self) -> None:
        """Run the queued jobs until done or waiting for samples (block mode)."""

    def drain(self) -> None:
        """Run every queued job to its end (before a checkpoint)."""

    def predict_next(self, u: float) -> float:
        """Model output at the next sample if ``u`` is applied now (no state change)."""

    def state_finite(self) -> bool:
        """Can the state be trusted (estimate, statistics, prediction all finite)?"""

    # ---------------------------------------------------------------- life cycle
    def begin_replay(self, noise: float, adapting: bool) -> None:
        """Before the start-up buffer is replayed: noise monitor at ``noise``, no fitting yet."""

    def restart_monitors(self, noise: float) -> None:
        """Output monitors as at a stream's first sample (after a lead-in of still outputs)."""

    def begin_fitting(self) -> None:
        """The buffer replayed: fitting on (a first fit of the replayed window, if the tracker fits windows)."""

    def go_live(self, outlier_gate: float) -> None:
        """The buffer replayed: the outlier gate open, fitting on."""

    # ---------------------------------------------------------------- recovery
    def report_events(self) -> list[dict]:
        """``events`` as reported to the user: anything left to fill in on a settled change filled in now."""

    def drop_failed_jobs(self) -> list[str] | None:
        """After a fault in the background work: the names of the failed periodic jobs dropped, or None."""

    def copy_recent(self, u: np.ndarray, y: np.ndarray) -> None:
        """The newest remembered samples into u, y (as many as u holds)."""
