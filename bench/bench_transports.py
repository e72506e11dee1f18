"""Transport benchmark: throughput, end-to-end latency and a sustained 10 kHz run (JSON on stdout).

    python -m bench.bench_transports [--quick]

* throughput: frames/s and samples/s from the simulated plant (``hil_sim --fast``,
  its own process) through a real pty into ``SerialSource`` (binary and ASCII),
  through SLCAN over a pty into python-can + cantools (pair and FD block
  frames), and over python-can's in-process virtual bus. Baseline in the same
  run: the straightforward reader, pyserial ``readline()`` + ``split(',')`` on
  ASCII lines (no checksum, no sequence accounting).
* latency at 10 kHz, real time, binary serial: from the plant's sample time
  (``t0 + seq / rate`` on the shared monotonic clock) to the return of
  ``OnlineEstimator.update`` for that sample (``creep_online.io.feed.FeedLoop``
  with ``SampleAge``, the loop ``creep-online stream`` and ``demo`` run); p50/p99/max. Baseline: the same
  with the readline reader (no estimator).
* sustained: 10 kHz binary serial in real time for 60 s (10 s with --quick):
  samples lost, CRC errors, worst plant lag.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np


from creep_online.io.feed import FeedLoop, SampleAge  # noqa: E402
from creep_online.io import open_source  # noqa: E402
from hil_sim import PlantConfig, generate, parse_params, run_virtual_plant  # noqa: E402
from hil_sim.harness import PlantProcess  # noqa: E402
from bench.harness import dist, write_report  # noqa: E402

RATE = 10_000.0


def _drain(src, last_seq: int, timeout: float = 300.0) -> tuple[int, float]:
    n = 0
    t_first = None
    deadline = time.monotonic() + timeout
    last = -1
    while time.monotonic() < deadline and last < last_seq:
        got = src.read(0.05)
        if got:
            if t_first is None:
                t_first = time.monotonic()
            n += len(got)
            last = got[-1].seq
    return n, time.monotonic() - (t_first or time.monotonic())


def throughput_serial(fmt: str, seconds: float) -> dict:
    args = ["--rate", str(RATE), "--duration", str(seconds), "--transport", f"serial-{fmt}", "--fast",
            "--wait-start", "--linger", "5"]
    with PlantProcess(args) as plant:
        n_total = plant.ready["samples"]
        src = open_source(f"serial:{plant.port}?rate={RATE:g}&start=S", on_event=None)
        t0 = time.monotonic()
        n, _ = _drain(src, n_total - 1)
        wall = time.monotonic() - t0
        src.close()
    return {"frames": n, "wall_s": wall, "frames_per_s": n / wall, "samples_per_s": n / wall,
            "missing": src.stats.missing, "bad_frames": src.stats.bad_frames}


def throughput_serial_baseline(seconds: float) -> dict:
    """pyserial readline() + split: the straightforward reader of ASCII lines."""
    import serial
    args = ["--rate", str(RATE), "--duration", str(seconds), "--transport", "serial-ascii", "--fast",
            "--wait-start", "--linger", "5"]
    with PlantProcess(args) as plant:
        n_total = plant.ready["samples"]
        ser = serial.Serial(plant.port, timeout=1.0)
        ser.write(b"S")
        n = 0
        t0 = time.monotonic()
        while n < n_total:
            line = ser.readline()
            if not line:
                break
            body = line.split(b"*")[0].split(b",")
            int(body[0]), float(body[1]), float(body[2]), float(body[3])
            n += 1
        wall = time.monotonic() - t0
        ser.close()
    return {"frames": n, "wall_s": wall, "frames_per_s": n / wall}


def throughput_slcan(frame: str, seconds: float) -> dict:
    args = ["--rate", str(RATE), "--duration", str(seconds), "--transport", "slcan", "--can-frame", frame,
            "--fast", "--linger", "5"]
    with PlantProcess(args) as plant:
        n_total = plant.ready["samples"]
        spf = plant.ready["samples_per_frame"]
        src = open_source(f"can:slcan:{plant.port}?rate={RATE:g}", on_event=None)
        t0 = time.monotonic()
        n, _ = _drain(src, n_total - 1)
        wall = time.monotonic() - t0
        src.close()
    return {"samples": n, "samples_per_frame": spf, "wall_s": wall, "samples_per_s": n / wall,
            "frames_per_s": n / spf / wall, "missing": src.stats.missing}


def throughput_virtual(frame: str, seconds: float) -> dict:
    rec = generate(PlantConfig(parse_params(""), rate=RATE, duration=seconds))
    ch = f"bench_{frame}_{os.getpid()}"
    src = open_source(f"can:virtual:{ch}?rate={RATE:g}", on_event=None)
    th, runner = run_virtual_plant(rec, RATE, ch, can_frame=frame, realtime=False)
    t0 = time.monotonic()
    th.start()
    n, _ = _drain(src, runner.n_samples - 1)
    wall = time.monotonic() - t0
    th.join(30)
    src.close()
    return {"samples": n, "samples_per_frame": runner.spf, "wall_s": wall, "samples_per_s": n / wall,
            "frames_per_s": n / runner.spf / wall, "missing": src.stats.missing,
            "note": "plant and reader share one process (and its GIL)"}


def latency_serial(seconds: float, with_estimator: bool = True) -> dict:
    from creep_online.online import OnlineEstimator
    args = ["--rate", str(RATE), "--duration", str(seconds), "--t-start", "0.2", "--transport", "serial-binary",
            "--wait-start", "--linger", "5"]
    with PlantProcess(args) as plant:
        n_total = plant.ready["samples"]
        est = OnlineEstimator(1.0 / RATE)
        src = open_source(f"serial:{plant.port}?rate={RATE:g}&start=S", on_event=None)
        t0 = plant.wait_event("start")["t0_monotonic"]
        loop = FeedLoop(src, lambda _dt: est, dt=1.0 / RATE, latency=SampleAge(t0, 1.0 / RATE),
                        read_timeout=0.05, duration=seconds * 3 + 60,
                        stop_when=lambda lp: lp.last_seq is not None and lp.last_seq >= n_total - 1)
        end = loop.run()
        src.close()
        if end.error is not None:
            raise end.error
        ledger = plant.wait_event("end", timeout=30)["ledger"]
    return {"samples": loop.fed, "expected": n_total, "missing": src.stats.missing,
            "crc_errors": src.stats.crc_errors, "latency_us": dist(loop.latency_us()),
            "plant_late_max_ms": ledger["late_max_s"] * 1e3,
            "estimate": est.estimate.to_dict() if est.model else None}


def latency_baseline(seconds: float) -> dict:
    import serial
    args = ["--rate", str(RATE), "--duration", str(seconds), "--transport", "serial-ascii", "--wait-start",
            "--linger", "5"]
    with PlantProcess(args) as plant:
        n_total = plant.ready["samples"]
        ser = serial.Serial(plant.port, timeout=1.0)
        ser.write(b"S")
        t0 = plant.wait_event("start")["t0_monotonic"]
        lat = []
        while len(lat) < n_total:
            line = ser.readline()
            if not line:
                break
            seq = int(line.split(b",", 1)[0])
            lat.append(time.monotonic() - (t0 + seq / RATE))
        ser.close()
    return {"samples": len(lat), "latency_us": dist(np.asarray(lat) * 1e6),
            "reader": "pyserial readline() + split, no estimator"}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="shorter runs (sustained 10 s instead of 60 s)")
    args = ap.parse_args()
    q = args.quick
    tp_s = 5.0 if q else 20.0
    out: dict = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                             "load_avg_1m": os.getloadavg()[0]},
                 "rate_hz": RATE, "quick": q}
    out["throughput"] = {
        "serial_binary": throughput_serial("binary", tp_s),
        "serial_ascii": throughput_serial("ascii", tp_s),
        "serial_ascii_baseline_readline": throughput_serial_baseline(tp_s),
        "slcan_pair": throughput_slcan("pair", tp_s / 2),
        "slcan_fd_block": throughput_slcan("block", tp_s / 2),
        "virtual_fd_block": throughput_virtual("block", tp_s),
        "virtual_pair": throughput_virtual("pair", tp_s),
    }
    t = out["throughput"]
    t["ratio_serial_ascii_vs_baseline"] = t["serial_ascii"]["frames_per_s"] / t["serial_ascii_baseline_readline"]["frames_per_s"]
    lat_s = 5.0 if q else 15.0
    out["latency_10khz_serial_binary"] = latency_serial(lat_s)
    out["latency_10khz_baseline_readline"] = latency_baseline(lat_s)
    sus = 10.0 if q else 60.0
    r = latency_serial(sus)
    out["sustained_10khz_serial"] = {"seconds": sus, "samples": r["samples"], "expected": r["expected"],
                                     "lost": r["expected"] - r["samples"], "missing_counted": r["missing"],
                                     "crc_errors": r["crc_errors"], "latency_us": r["latency_us"],
                                     "plant_late_max_ms": r["plant_late_max_ms"]}
    out["machine"]["load_avg_1m_end"] = os.getloadavg()[0]
    write_report(out, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
