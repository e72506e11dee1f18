"""What ``EstimatorListener`` costs the application's notifier thread per CAN message (JSON on stdout).

    python -m bench.bench_can_listener [--frames N] [--out bench/results/can_listener.json]

Thread CPU time (``time.thread_time_ns``) of each call, p50/p99/max, per frame and per sample, for the
two-sample classic frame (``AMP_PAIR``) and the seven-sample CAN FD frame (``AMP_BLOCK``):

* ``decode``: ``can_source.decode_message`` alone, the DBC decoding the listener shares with ``CanSource``
  (the baseline, measured in the same run);
* ``listener``: ``EstimatorListener(msg)`` feeding an estimator that does nothing: decoding plus ordering
  (counter unwrapping, reorder window, gap accounting) and the calls, the listener's own cost;
* ``listener+estimator``: the same feeding a real ``OnlineEstimator`` (10 kHz, a staircase plant), i.e. what
  the notifier thread spends per message in use.
"""
from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np


import can  # noqa: E402

from creep_online.io import can_frames as cf  # noqa: E402
from creep_online.io.can_frames import CanDecoder  # noqa: E402
from creep_online.io.can_listener import EstimatorListener  # noqa: E402
from creep_online.io.can_source import decode_message  # noqa: E402
from creep_online.online import OnlineEstimator, warm_kernels  # noqa: E402
from hil_sim import PlantConfig, generate, parse_params  # noqa: E402
from bench.harness import dist, write_report  # noqa: E402

RATE = 10_000.0
WARM = 200       # calls not measured (first decodes, caches)


class Idle:
    """An estimator that takes the samples and does nothing (the listener's own cost)."""

    dt = 1.0 / RATE

    def update(self, u: float, y: float) -> None:
        pass

    def gap(self, n: int) -> None:
        pass


def messages(kind: str, n_frames: int) -> list[can.Message]:
    """The frames of a simulated 10 kHz staircase record."""
    spf = cf.BLOCK_SAMPLES if kind == "block" else 2
    rec = generate(PlantConfig(parse_params(""), rate=RATE, duration=n_frames * spf / RATE, t_start=0.05, seed=1))
    out = []
    if kind == "block":
        for k in range(n_frames):
            s = slice(k * spf, (k + 1) * spf)
            i, d, fd = cf.encode_block((k * spf) % cf.COUNTER_MODULUS, 0, rec.u[s], rec.y[s])
            out.append(can.Message(arbitration_id=i, data=d, is_fd=True, is_extended_id=False))
        return out
    gen, last_u = 0, None
    for k in range(n_frames):
        for j in (2 * k, 2 * k + 1):
            if rec.u[j] != last_u:
                gen, last_u = (gen + 1) % 16, rec.u[j]
                i, d, _ = cf.encode_input(gen, rec.u[j])
                out.append(can.Message(arbitration_id=i, data=d, is_extended_id=False))
        i, d, _ = cf.encode_pair((2 * k) % cf.COUNTER_MODULUS, gen, gen, rec.y[2 * k], rec.y[2 * k + 1])
        out.append(can.Message(arbitration_id=i, data=d, is_extended_id=False))
    return out


def timed(call, msgs: list[can.Message]) -> np.ndarray:
    """Thread CPU time (us) of ``call(msg)`` for each message after the first ``WARM``."""
    out = np.empty(len(msgs))
    clock = time.thread_time_ns
    for k, msg in enumerate(msgs):
        t0 = clock()
        call(msg)
        out[k] = clock() - t0
    return out[WARM:] / 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=4000)
    ap.add_argument("--out", default=None, help="also write the JSON here")
    args = ap.parse_args()
    warm_kernels()
    result: dict = {"bench": "can_listener", "python": platform.python_version(), "can": can.__version__,
                    "frames": args.frames, "unit": "us of thread CPU time", "kinds": {}}
    for kind in ("pair", "block"):
        msgs = messages(kind, args.frames)
        data = [m for m in msgs if m.arbitration_id != cf.ID_INPUT]
        spf = cf.BLOCK_SAMPLES if kind == "block" else 2
        decoder = CanDecoder()
        base = timed(lambda m: decode_message(decoder, m), msgs)
        idle = EstimatorListener(Idle())
        own = timed(idle, msgs)
        live = EstimatorListener(OnlineEstimator(1.0 / RATE))
        used = timed(live, msgs)
        assert idle.fed == live.fed == len(data) * spf, (idle.fed, live.fed, len(data) * spf)
        share = len(data) / len(msgs)          # data frames among the messages (pair: input frames too)
        result["kinds"][kind] = {
            "samples_per_data_frame": spf, "messages": len(msgs),
            "decode_per_message": dist(base, 1), "listener_per_message": dist(own, 1),
            "listener_per_sample": dist(own, spf * share), "listener_estimator_per_message": dist(used, 1),
            "listener_estimator_per_sample": dist(used, spf * share),
            "listener_vs_decode_p50": float(np.percentile(own, 50) / np.percentile(base, 50)),
            "estimate": {k: getattr(live.estimate, k) for k in ("alpha", "fn_hz", "zeta", "b", "phase")},
        }
    write_report(result, args.out)


if __name__ == "__main__":
    main()
