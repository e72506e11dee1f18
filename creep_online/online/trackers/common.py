"""What the trackers share: the fit record, the parameter view of theta, the job protocol's tokens."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._kernels import window as W
from ..search import ZETA_BOX

#: What a job yields while it waits for samples to arrive (the unit is not spent on it).
WAIT = "wait"
#: What a job yields while its re-fit or change test runs in ``machine`` (advanced by the per-sample
#: kernel, ``fit_machine.sample_work``; in block mode by ``finish``).
MACHINE = "machine"
MACHINE_REFIT, MACHINE_TEST = 0, 1      # the work arrays in the tracker's context (``fit_machine.context``)
#: Change-test snapshots kept, live and replayed: the test of the second before the last reads the oldest.
KEPT_SNAPSHOTS = 3
#: Snapshot slots of the change test, reused in turn (see ``workspace.allocate_work``).
SNAP_SLOTS = 6
#: Jobs that run before the long ones (``Scheduler.next_job``).
PERIODIC_JOBS = ("snapshot_job", "refit_job", "change_job")
#: Resonances the window fit may reach (those of the search).
ZETA_BOUNDS = ZETA_BOX
#: theta = [alpha, ln a1, ln a2, b, offset, free-response weights..., b'/b, alpha'] (the last two with drift)




def settled_moves(before, now: list[float], move: dict) -> tuple[dict, list[str]]:
    """A change event's relative moves of alpha, a1, a2, b (a1 and a2 from their logarithms) between the estimate
    ``before`` it and ``now`` that it has settled, and the parameters that moved beyond their threshold in ``move``
    (default 2 %), sorted."""
    change = {"alpha": now[0] / before[0] - 1, "a1": math.exp(now[1] - before[1]) - 1,
              "a2": math.exp(now[2] - before[2]) - 1, "b": now[3] / before[3] - 1}
    return {k: float(v) for k, v in change.items()}, sorted(k for k, v in change.items() if abs(v) > move.get(k, 0.02))


def largest_move(new: list[float], old: list[float]) -> float:
    """Largest relative move of alpha, ln a1, ln a2, b (plain floats: numpy on 4-vectors costs ~2 us)."""
    return max(abs(a - b) / max(abs(b), 1e-300) for a, b in zip(new[:4], old[:4]))


@dataclass
class Fit:
    """The window's last fit: parameters, cost, 1-sigma std, and when."""

    theta: np.ndarray | list[float]     # [alpha, ln a1, ln a2, b, ...]
    cost: float = math.inf
    neff: float = 0.0
    std: dict = field(default_factory=dict)
    sample: int = 0


class ParameterView:
    """The model parameters read from ``theta`` = [alpha, ln a1, ln a2, b, offset, ...] (both trackers)."""

    theta: np.ndarray

    @property
    def alpha(self) -> float:
        return float(self.theta[0])

    @property
    def a1(self) -> float:
        return math.exp(self.theta[1])

    @property
    def a2(self) -> float:
        return math.exp(self.theta[2])

    @property
    def b(self) -> float:
        return float(self.theta[3])

    @property
    def offset(self) -> float:
        return float(self.theta[4])


class LiveMonitors:
    """What both trackers report of the live stream and how the estimator starts them (``Tracker`` protocol):
    the output monitors in the scalar slots ``sc`` and the live prediction from the states ``phi``."""

    sc: np.ndarray
    phi: np.ndarray
    co: np.ndarray
    m: np.ndarray
    q: int
    theta: np.ndarray
    S: np.ndarray
    fitting: bool

    def state_finite(self) -> bool:
        """Are the estimate, the statistics' diagonal and the live prediction all finite (``window.state_finite``)?"""
        return W.state_finite(self.theta, self.S, self.sc)

    def predict_next(self, u: float) -> float:
        """The model output at the next sample if ``u`` (as applied) is applied now; no state changes."""
        phi = self.phi.copy()
        W.advance(phi, self.co, self.q, u)
        return float(phi @ self.m)

    def begin_replay(self, noise: float, adapting: bool) -> None:
        """Before the start-up buffer is replayed: the noise monitor at ``noise``, no fitting until ``go_live``."""
        self.sc[W.SC_NOISE] = noise
        if not adapting:
            self.sc[W.SC_ACC] = 0.0
        self.fitting = False

    def restart_monitors(self, noise: float) -> None:
        """The output monitors as at a stream's first sample (``window.restart_monitors``)."""
        W.restart_monitors(self.sc, noise)

    @property
    def adapting(self) -> bool:
        """Do the fits move the estimate (False: frozen)?"""
        return bool(self.sc[W.SC_ACC])

    @adapting.setter
    def adapting(self, on: bool) -> None:
        self.sc[W.SC_ACC] = 1.0 if on else 0.0

    @property
    def noise_level(self) -> float:
        """The output noise monitor's standard deviation."""
        return float(self.sc[W.SC_NOISE])

    @property
    def live_error_power(self) -> float:
        """Mean square of the live prediction error over the last ~0.2 s."""
        return float(self.sc[W.SC_E2])

    @property
    def outliers(self) -> int:
        """Outputs the gate did not use."""
        return int(self.sc[W.SC_OUTLIERS])

    @property
    def shifts(self) -> int:
        """Runs of gated outputs longer than the burst: shifts, not outliers."""
        return int(self.sc[W.SC_SHIFTS])

    @property
    def output_stuck(self) -> bool:
        """Is the output frozen or clipped while the model says it moves?"""
        return bool(self.sc[W.SC_STUCK])

    @property
    def input_held_samples(self) -> float:
        """Samples since the input last changed."""
        return float(self.sc[W.SC_SINCE])
