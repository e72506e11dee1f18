"""The input gate in action: samples held back while the gate decides, then fed (or buffered) in order.

The rule (``online/policy/input_gate.py``) says what becomes of each sample; ``InputStage`` keeps the samples it
holds (``est._held``: glitch candidates (u, y) not yet decided) and those decided but not yet taken by the live
tracker (``est._backlog``: (du, y), fed ``input_gate.drain_per_update`` per update()), and the input's range
(``est._u_lo``, ``est._u_hi``, ``est._u_last``, ``est._u_ref``: the reference inputs are deviations from). These
live on the estimator: update()'s per-sample path reads them directly.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .policy import input_gate as G

#: Samples a run of passed samples is judged over at most (``InputStage.passing_run``): a block with many glitch
#: candidates costs this many element operations per candidate, not the block's length.
PASS_SCAN = 4096

if TYPE_CHECKING:
    from .estimator import OnlineEstimator
    from .trackers import Tracker


class InputStage:
    """The input gate's held and waiting samples for one estimator (``est``)."""

    def __init__(self, est: "OnlineEstimator") -> None:
        self.est = est
        self.drain = est._settings.input_gate.drain_per_update

    def glitch_candidate(self, u: float) -> bool:
        """Is u a glitch candidate (``input_gate.glitch_candidate``)?"""
        est = self.est
        return G.glitch_candidate(u, G.InputRange(est._u_lo, est._u_hi, est._u_last), est.input_gate)

    def classify(self, u: float, y: float) -> list[tuple[float, float]]:
        """The samples (input to apply, y) decided by this one, in order (often just this one): ``input_gate.verdict``
        applied."""
        est = self.est
        if est._u_ref is None:
            est._u_ref = u
            est._u_lo = est._u_hi = u
            est._u_last = u
            # a first input of zero is a start at rest; a non-zero one at the stream's first sample is read from the
            # data (``Startup.read_start``); after a start over in mid-stream the plant is in operation
            est._startup.start = "rest" if u == 0.0 else (None if est.samples == 1 else "operation")
        verdict = G.verdict(self.glitch_candidate(u), len(est._held), est._burst)
        if verdict == G.PASS:
            return [(u, y)]
        if verdict == G.HOLD:
            est._held.append((u, y))
            est._deferred = True
            return []
        held, est._held = est._held, []
        est._deferred = bool(est._backlog)
        if verdict == G.MOVE:
            return held + [(u, y)]
        est.input_outliers += len(held)
        return [(est._u_last, w) for _, w in held] + [(u, y)]

    def accept(self, u: float) -> float:
        """Take u as the input applied (the range seen so far, the first input change); its deviation from the
        reference. Called per sample in stream order, just before the sample is fed or buffered."""
        est = self.est
        if u != est._u_last and est._startup.first_change is None:
            est._startup.first_change = est._startup.nbuf
        est._u_last = u
        est._u_lo = min(est._u_lo, u)
        est._u_hi = max(est._u_hi, u)
        return u - est._u_ref

    def block(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """Vector form of ``classify`` and ``accept`` for the live tracker: (du, y, exact). Exact: the arrays
        are the block's samples one for one (every input within the range seen so far, nothing waiting: the
        fast path); otherwise the samples that waited come first and glitch candidates at the end stay held.
        Runs of samples the gate passes are taken at once (``passing_run``); only the candidates and the samples
        after them while some are held go through ``classify`` one by one."""
        est = self.est
        if not est._deferred and est._u_lo <= u.min() and u.max() <= est._u_hi:
            est._u_last = float(u[-1])
            return u - est._u_ref, y, True
        parts_u: list[np.ndarray] = []
        parts_y: list[np.ndarray] = []
        if est._backlog:
            waited = np.array(est._backlog, dtype=float).reshape(-1, 2)
            parts_u.append(waited[:, 0])
            parts_y.append(waited[:, 1])
            est._backlog.clear()
        k, n = 0, u.size
        while k < n:
            run = 0 if est._held else self.passing_run(u[k:k + PASS_SCAN])
            if run:
                self.accept_run(u[k:k + run])
                parts_u.append(u[k:k + run] - est._u_ref)
                parts_y.append(y[k:k + run])
                k += run
                continue
            decided = [(self.accept(v), w) for v, w in self.classify(float(u[k]), float(y[k]))]
            if decided:
                pair = np.array(decided, dtype=float).reshape(-1, 2)
                parts_u.append(pair[:, 0])
                parts_y.append(pair[:, 1])
            k += 1
        est._deferred = bool(est._held)
        if not parts_u:
            return np.empty(0), np.empty(0), False
        return np.concatenate(parts_u), np.concatenate(parts_y), False

    def passing_run(self, u: np.ndarray) -> int:
        """How many of the samples u (nothing held) the gate passes one after the other, each accepted before the
        next is judged: ``input_gate.glitch_candidate`` on the range and the last input as they grow over the run."""
        est = self.est
        gate = est.input_gate
        if not gate > 0:
            return u.size
        lo = np.minimum.accumulate(u)
        hi = np.maximum.accumulate(u)
        lo_before = np.minimum(np.concatenate(([est._u_lo], lo[:-1])), est._u_lo)
        hi_before = np.maximum(np.concatenate(([est._u_hi], hi[:-1])), est._u_hi)
        last = np.concatenate(([est._u_last], u[:-1]))
        span = hi_before - lo_before
        candidate = (span > 0) & (np.abs(u - last) > gate * span)
        first = int(np.argmax(candidate))
        return first if candidate[first] else u.size

    def accept_run(self, u: np.ndarray) -> None:
        """``accept`` for each sample of a run the gate passed, at once (the range, the last input, the first
        input change)."""
        est = self.est
        if est._startup.first_change is None and (u[0] != est._u_last or np.any(u[1:] != u[:-1])):
            est._startup.first_change = est._startup.nbuf
        est._u_last = float(u[-1])
        est._u_lo = min(est._u_lo, float(u.min()))
        est._u_hi = max(est._u_hi, float(u.max()))

    def buffer_sample(self, u: float, y: float) -> None:
        """A sample into the start-up buffer through the input gate, after any the live tracker had waiting (a
        fault's restart leaves them: ``update_deferred``, ``Recovery.block_resync``)."""
        est = self.est
        self.backlog_to_buffer()
        for v, w in self.classify(u, y):
            est._startup.buffer(self.accept(v), w)
        est._deferred = bool(est._held)

    def buffer_until_live(self, u: np.ndarray, y: np.ndarray, done: list[int]) -> int:
        """Block mode before the tracker is live: u[done[0]:], y[...] into the start-up (its steps with update()'s
        budget after each sample, ``Startup.advance``, so it lands at update()'s sample) until the tracker goes live or
        the block ends; returns where it stopped. ``done[0]`` (and ``est.samples``) count the samples taken, each
        before it goes in (a fault inside counts it taken). The samples between the start-up's steps go in at once
        (``buffer_quiet``), and so do those of the search's run with its steps (``search_quiet``)."""
        est = self.est
        i, n = done[0], u.size
        while i < n and est._live is None:
            run = self.buffer_quiet(u[i:], y[i:]) or self.search_quiet(u[i:], y[i:])
            if run:
                est.samples += run
                i += run
                done[0] = i
                continue
            est.samples += 1
            done[0] = i + 1
            self.buffer_sample(float(u[i]), float(y[i]))
            i += 1
            est._startup.advance(est._units)   # (update()'s budget: the start-up lands at the same sample)
        return i

    def buffer_quiet(self, u: np.ndarray, y: np.ndarray) -> int:
        """Block mode: the leading samples of u, y that the gate passes, into the start-up buffer at once, as many as
        its quiet run allows (``Startup.quiet_samples``: no start-up step falls between them); returns how many
        (0: the next goes through ``buffer_sample``). The same values as ``buffer_sample`` one by one."""
        est = self.est
        if est._held or est._backlog or est._deferred or est._u_ref is None:
            return 0
        quiet = min(est._startup.quiet_samples(), u.size, PASS_SCAN)
        if quiet and est._startup.first_change is None:     # (the run ends at the input's first move)
            moves = np.flatnonzero(u[:quiet] != est._u_last)
            quiet = int(moves[0]) if moves.size else quiet
        run = self.passing_run(u[:quiet]) if quiet else 0
        if run:
            self.accept_run(u[:run])
            est._startup.buffer_run(u[:run] - est._u_ref, y[:run])
        return run

    def search_quiet(self, u: np.ndarray, y: np.ndarray) -> int:
        """Block mode while the start-up search runs: the leading samples of u, y that the gate passes, with the
        search's steps of each (``Startup.search_run``), into the start-up buffer at once; returns how many (0: the
        next goes through ``buffer_sample``). The same values as ``buffer_sample`` and ``advance`` one by one."""
        est = self.est
        if est._held or est._backlog or est._deferred or est._u_ref is None:
            return 0
        run = self.passing_run(u[:min(u.size, PASS_SCAN)])
        run = est._startup.search_run(run) if run else 0
        if run:
            self.accept_run(u[:run])
            est._startup.buffer_run(u[:run] - est._u_ref, y[:run])
            if est._startup.search.result is not None:     # (finished in the run's last sample)
                est._startup.search_landed()
        return run

    def update_deferred(self, tr: "Tracker", u: float, y: float) -> None:
        """update()'s slow path: an input outside the range seen so far, or samples waiting. The sample goes
        through the input gate; of the decided ones at most ``drain_per_update`` are fed now, in order."""
        est = self.est
        est._backlog.extend((self.accept(v), w) for v, w in self.classify(u, y))
        for k in range(min(self.drain, len(est._backlog))):
            du, w = est._backlog.popleft()
            self.feed_live(tr, du, w, work=k == self.drain - 1 or not est._backlog)
            if est._live is not tr:        # a fault restarted the tracker: the rest goes to the start-up buffer
                self.backlog_to_buffer()
                break
        est._deferred = bool(est._held or est._backlog)

    def feed_live(self, tr: "Tracker", du: float, y: float, work: bool) -> None:
        """One sample into the live tracker with its slice of a re-fit under way and, if ``work``, a share of the
        queued jobs (the per-sample path of update(), for the samples the input gate kept back)."""
        est = self.est
        if not tr.advance(du, y, est._units, work):
            est._recovery.fault(None, "update")

    def settle(self) -> None:
        """Before a gap: glitch candidates still held count as a glitch (the input is unknown past them) and every
        sample waiting is fed (or buffered) now."""
        est = self.est
        if est._held:
            est.input_outliers += len(est._held)
            est._backlog.extend((est._u_last - est._u_ref, w) for _, w in est._held)
            est._held = []
        while est._backlog and est._live is not None:
            du, w = est._backlog.popleft()
            self.feed_live(est._live, du, w, work=True)
        self.backlog_to_buffer()
        est._deferred = False

    def forget_held(self) -> None:
        """Before a long outage: glitch candidates count as a glitch (the input went on unknown), nothing waits."""
        est = self.est
        if est._held:
            est.input_outliers += len(est._held)
            est._held = []
        est._backlog.clear()
        est._deferred = False

    def backlog_to_buffer(self) -> None:
        """The decided samples the live tracker has not taken, in order, into the start-up buffer (the tracker was
        restarted by a fault: the start-up takes them first)."""
        est = self.est
        while est._backlog:
            est._startup.buffer(*est._backlog.popleft())
