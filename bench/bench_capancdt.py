"""capaNCDT-style TCP stream benchmark: 3.9 kSa/s sustained, injected drops counted, latency and CPU (JSON).

    python -m bench.bench_capancdt [--quick] [--out bench/results/capancdt.json]

* sustained: ``python -m hil_sim --transport capancdt`` (its own process, real
  time, 3906.25 frames/s in packets of 4, loopback TCP) for 60 s (10 s with
  --quick) into ``capancdt:127.0.0.1:PORT``, fed sample by sample to
  ``OnlineEstimator`` by ``FeedLoop`` (what ``creep-online stream`` runs).
  Counted: samples delivered vs sent, lost. Latency from the frame's sample
  time at the plant (``t0 + n / rate`` on the shared monotonic clock) to the
  return of ``update()`` for it: p50/p99/max. CPU: the reading thread's CPU
  time (source + estimator) and wall time, per sample; the plant process's
  CPU from ``getrusage(RUSAGE_CHILDREN)``. The estimator's share is the thread
  CPU time of its update() calls (``time.thread_time`` around each; the rest is
  the source, parser, command lookup and loop).
* faults: 20 s (10 s quick) in real time with drops of 3 frames, corrupt
  headers, garbage and a disconnect: every injected drop must appear as a
  missing run of exactly its length, the counters must equal the plant's
  ledger.
* parser: CPU time per packet of ``CapancdtParser.feed`` against a baseline
  measured in the same run on the same bytes: the straightforward reader
  (``struct.unpack`` of the header + ``np.frombuffer`` of the values, as the
  public DT6220 scripts do; no resynchronisation, identity or 24-bit checks).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


from creep_online.io.capancdt_frames import CapancdtParser, encode_packet  # noqa: E402
from creep_online.io.feed import FeedLoop, SampleAge  # noqa: E402
from creep_online.io import open_source  # noqa: E402
from hil_sim.harness import PlantProcess  # noqa: E402

from bench.harness import dist, write_report  # noqa: E402  (p50/p99/max/mean/n)

RATE = 3906.25
PLANT = ["--transport", "capancdt", "--rate", str(RATE), "--t-start", "0.2", "--schedule", "square",
         "--period", "1.0", "--linger", "5"]


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def stream(seconds: float, faults: str = "") -> dict:
    """Run the plant in real time and feed every sample to the online estimator; counters, latency, CPU."""
    from creep_online.online import OnlineEstimator, warm_kernels
    warm_kernels()
    cmd = os.path.join(tempfile.mkdtemp(prefix="bench_capancdt_"), "cmd.csv")
    cpu_children0 = _children_cpu()
    with PlantProcess(PLANT + ["--duration", str(seconds), "--command-file", cmd, "--faults", faults]) as plant:
        n_total = plant.ready["samples"]
        est = OnlineEstimator(1.0 / RATE)
        timed = ThreadCpu(est)
        src = open_source(f"capancdt:{plant.port}?command={cmd}&control={plant.ready['control_port']}", on_event=None)
        t0 = plant.wait_event("start")["t0_monotonic"]
        seqs: list[int] = []
        loop = FeedLoop(src, lambda _dt: timed, dt=1.0 / RATE, latency=SampleAge(t0, 1.0 / RATE),
                        read_timeout=0.05, duration=seconds * 3 + 60,
                        on_sample=lambda _lp, s: seqs.append(s.seq),
                        stop_when=lambda lp: lp.last_seq is not None and lp.last_seq >= n_total - 1)
        cpu0, wall0 = time.thread_time(), time.monotonic()
        end = loop.run()
        cpu, wall = time.thread_time() - cpu0, time.monotonic() - wall0
        src.close()
        if end.error is not None:
            raise end.error
        ledger = plant.wait_event("end", timeout=60)["ledger"]
        plant.stop()
    cpu_plant = _children_cpu() - cpu_children0
    stats = src.stats
    gaps = np.diff(np.asarray(seqs))
    runs = sorted((gaps[gaps > 1] - 1).tolist())
    return {"seconds": seconds, "sent": n_total, "samples": loop.fed, "lost": n_total - loop.fed,
            "missing_counted": stats.missing, "gaps": stats.sequence.gaps, "malformed": stats.parser.malformed,
            "garbage_bytes": stats.parser.garbage_bytes, "disconnects": stats.disconnects,
            "reconnects": stats.reconnects, "missing_runs": runs,
            "latency_us": dist(loop.latency_us()),
            "reader_thread_cpu_s": cpu, "reader_wall_s": wall, "reader_cpu_fraction": cpu / wall,
            "reader_cpu_us_per_sample": cpu / max(loop.fed, 1) * 1e6,
            "estimator_cpu_us_per_sample": timed.cpu / max(loop.fed, 1) * 1e6,
            "source_and_loop_cpu_us_per_sample": (cpu - timed.cpu) / max(loop.fed, 1) * 1e6,
            "plant_process_cpu_s": cpu_plant, "plant_late_max_ms": ledger["late_max_s"] * 1e3,
            "ledger": {k: ledger[k] for k in ("dropped", "dropped_samples", "bad_headers", "bad_header_samples",
                                              "garbage", "garbage_bytes", "disconnects", "disconnect_lost_samples")},
            "estimate": {k: est.estimate.to_dict()[k] for k in ("alpha", "fn_hz", "zeta", "b")} if est.model else None}


class ThreadCpu:
    """The estimator with the thread CPU time of its update() and gap() calls added up (source vs estimator)."""

    def __init__(self, est) -> None:
        self.est = est
        self.cpu = 0.0

    def update(self, u: float, y: float):
        c0 = time.thread_time()
        out = self.est.update(u, y)
        self.cpu += time.thread_time() - c0
        return out

    def gap(self, n: int) -> None:
        c0 = time.thread_time()
        self.est.gap(n)
        self.cpu += time.thread_time() - c0


def _baseline_parse(data: bytes, chunk: int) -> int:
    """The straightforward reader: header by struct, values by frombuffer, trusting every field."""
    head = struct.Struct("<4sIIQIHHI")
    buf = b""
    frames = 0
    for i in range(0, len(data), chunk):
        buf += data[i:i + chunk]
        while len(buf) >= 32:
            _, _, _, _, _, m, bpf, counter = head.unpack_from(buf)
            end = 32 + m * bpf
            if len(buf) < end:
                break
            values = np.frombuffer(buf[32:end], "<i4").reshape(m, -1)
            frames += values.shape[0]
            buf = buf[end:]
    return frames


def parser_cost(packets: int = 20_000, m: int = 4, chunk: int = 4096) -> dict:
    rng = np.random.default_rng(1)
    values = rng.integers(0, 1 << 24, (packets * m, 1))
    data = b"".join(encode_packet(i * m, values[i * m:(i + 1) * m]) for i in range(packets))
    out = {}
    for name, fn in (("capancdt_parser", lambda: sum(p.values.shape[0] for i in range(0, len(data), chunk)
                                                     for p in parser.feed(data[i:i + chunk]))),
                     ("baseline_struct_frombuffer", lambda: _baseline_parse(data, chunk))):
        best = None
        for _ in range(3):
            parser = CapancdtParser()
            c0 = time.thread_time()
            frames = fn()
            c = time.thread_time() - c0
            best = c if best is None else min(best, c)
        out[name] = {"frames": frames, "cpu_us_per_packet": best / packets * 1e6,
                     "cpu_us_per_frame": best / (packets * m) * 1e6}
    out["ratio_parser_vs_baseline"] = out["capancdt_parser"]["cpu_us_per_packet"] / \
        out["baseline_struct_frombuffer"]["cpu_us_per_packet"]
    out["note"] = (f"{packets} packets of {m} frames x 1 channel fed in {chunk}-byte chunks; best of 3 "
                   "(the parser waits for the next header only while (re)locking)")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 s runs instead of 60 s / 20 s")
    ap.add_argument("--out", default=None, help="also write the JSON here")
    args = ap.parse_args()
    q = args.quick
    out: dict = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                             "load_avg_1m": os.getloadavg()[0]},
                 "rate_hz": RATE, "frames_per_packet": 4, "quick": q}
    out["parser"] = parser_cost()
    out["sustained"] = stream(10.0 if q else 60.0)
    out["faults"] = stream(10.0 if q else 20.0, "drop=10,drop_frames=3,badheader=5,garbage=5,disconnect=1")
    f = out["faults"]
    led = f["ledger"]
    expected_runs = sorted([3] * len(led["dropped"]) + [4] * len(led["bad_headers"])
                           + ([led["disconnect_lost_samples"]] if led["disconnects"] else []))
    f["every_drop_counted"] = (f["missing_runs"] == expected_runs
                               and f["missing_counted"] == led["dropped_samples"] + led["bad_header_samples"]
                               + led["disconnect_lost_samples"])
    out["machine"]["load_avg_1m_end"] = os.getloadavg()[0]
    write_report(out, args.out, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
