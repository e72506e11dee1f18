"""A third-party sample source, written the way docs/transports.md ("Adding a source") says.

``toy:alpha=..,fn=..,zeta=..,b=..?rate=HZ&samples=N&drop=K&noise=S`` streams
the step response of that creep model, computed with creep_online's exact
simulator, with every K-th sample lost on the way (so the consumer must see
gaps). It lives outside the package on purpose: the tests add it through
``register_source`` and through an entry point of a tiny installed
distribution, then stream from it with ``creep-online stream``.
"""
from __future__ import annotations

import numpy as np

from creep_online.io.frames import RawSample
from creep_online.io.params import parse_params
from creep_online.io.source_options import Option
from creep_online.io.sources import SampleSource
from creep_online.simulate import simulate

STEP_AT_S = 0.1
STEP = 50.0
CHUNK = 500


class ToyCreepSource(SampleSource):
    """The step response of a creep model, as a stream with deterministic losses."""

    options = (
        Option("rate", float, 200.0, "sample rate in Hz"),
        Option("samples", int, 2400, "how many sequence numbers to send"),
        Option("drop", int, 0, "lose every K-th sample (0: none)"),
        Option("noise", float, 0.01, "output noise standard deviation"),
    )
    target_label = "model parameters"

    def __init__(self, params: str, *, rate: float = 200.0, samples: int = 2400, drop: int = 0,
                 noise: float = 0.01, **kw) -> None:
        super().__init__(rate=rate, t_from_seq=True, **kw)
        self.name = f"toy:{params}"
        model = parse_params(params, what=self.name)
        t = np.arange(samples) / rate
        self.u = np.where(t >= STEP_AT_S, STEP, 0.0)
        self.y = simulate(model, t, self.u) + np.random.default_rng(0).normal(0.0, noise, samples)
        self.drop = drop
        self._next = 0

    def lost(self, seq: int) -> bool:
        """True for the sequence numbers this source never sends."""
        return self.drop > 0 and seq % self.drop == self.drop - 1

    def _read_raw(self, timeout: float) -> list[RawSample] | None:
        start = self._next
        if start >= self.u.size:
            return None
        stop = min(start + CHUNK, self.u.size)
        self._next = stop
        return [RawSample(k, 0.0, float(self.u[k]), float(self.y[k]), 0)
                for k in range(start, stop) if not self.lost(k)]
