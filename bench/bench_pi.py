"""PI controller benchmark: the ``pi:`` source through pipython and the emulated controller (JSON on stdout).

    python -m bench.bench_pi [--quick] > bench/results/pi.json

* throughput: samples/s from ``python -m hil_sim.pi_controller --fast`` (its own
  process; a recording is complete at once) through a real pty, pipython's
  ``GCSDevice``/``PISerial`` and ``PiSource`` (``DRL?`` + ``DRR?`` in chunks of
  500 / 2000 / 8000 points), every value checked against the plant rebuilt here.
  Baseline in the same run: pipython alone reading the whole table with one
  ``qDRR`` (no chunking, no sequence accounting): the most the link gives.
  CPU: process CPU time (pipython's reading thread polls the port without
  sleeping, so it counts) and the main thread's CPU time, per sample.
* random plants: 12 plants over the issue's ranges (5 with --quick), random
  schedule, RTR 1-4 and chunk, fixed seeds: the fraction whose every point
  reads back equal to the plant with nothing lost.
* real time: the controller's recorder at 5, 10 and 20 kSa/s (servo rate, RTR 1)
  for 20 s (5 s with --quick), fed to ``OnlineEstimator.update`` by
  ``FeedLoop``: samples delivered vs recorded, lost, and the end-to-end latency
  from the sample's time on the controller (its trigger time + i / rate, on the
  shared monotonic clock) to the return of ``update()``, p50/p99/max. Baseline
  in the same run: 10 kSa/s with pipython's stock ``PISerial`` gateway
  (``?wait=0``), whose reply polling spins instead of waiting in ``select``.
* TCP: the same throughput (chunk 2000) and real-time (10 kSa/s) runs with the
  emulator on a loopback TCP port (``--tcp``) and the source as
  ``pi:tcp:127.0.0.1:PORT`` (pipython's ``PISocket``), with the select-waiting
  socket gateway and, as the baseline in the same run, pipython's stock one.
  ``--tcp-only`` runs just this part.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np


from bench.harness import dist, write_report  # noqa: E402  (p50/p99/max/mean/n)
from creep_online.io.feed import FeedLoop, SampleAge  # noqa: E402
from creep_online.io import open_source  # noqa: E402
from hil_sim.harness import PlantProcess  # noqa: E402
from hil_sim.pi_controller import build_parser, plant_config  # noqa: E402
from hil_sim.plant import generate  # noqa: E402


def controller(args: list[str]):
    plant = generate(plant_config(build_parser().parse_args(args)))
    return PlantProcess(args, module="hil_sim.pi_controller"), plant


def spec(proc: PlantProcess, tcp: bool) -> str:
    """The source spec of the emulator: ``pi:tcp:127.0.0.1:PORT`` over TCP, ``pi:PTY`` otherwise."""
    return f"pi:tcp:{proc.port}" if tcp else f"pi:{proc.port}"


def throughput_source(points: int, chunk: int, tcp: bool = False, wait: bool = True) -> dict:
    rate = 10_000.0
    args = ["--rate", f"{rate:g}", "--duration", f"{points / rate:g}", "--fast", "--table-points", str(points),
            "--t-start", "0.01"] + (["--tcp"] if tcp else [])
    proc, plant = controller(args)
    with proc:
        cpu0, th0, t0 = time.process_time(), time.thread_time(), time.perf_counter()
        src = open_source(f"{spec(proc, tcp)}?chunk={chunk}&wait={int(wait)}", on_event=None)
        got = []
        while len(got) < points and time.perf_counter() - t0 < 600:
            got += src.read(0.05)
        wall = time.perf_counter() - t0
        cpu, th = time.process_time() - cpu0, time.thread_time() - th0
        src.close()
    seq = np.array([s.seq for s in got])
    wrong = int(np.count_nonzero(np.abs(np.array([s.y for s in got]) - plant.y[seq]) > 1e-9 * (1 + np.abs(plant.y[seq]))))
    return {"link": "tcp" if tcp else "pty", "wait": wait, "chunk": chunk, "points": points, "samples": len(got),
            "missing": src.stats.missing,
            "values_wrong": wrong, "drr_queries": src.stats.parser.frames, "wall_s": wall,
            "samples_per_s": len(got) / wall, "process_cpu_us_per_sample": cpu / max(len(got), 1) * 1e6,
            "main_thread_cpu_us_per_sample": th / max(len(got), 1) * 1e6}


def throughput_baseline(points: int) -> dict:
    """pipython alone: one qDRR of the whole table (what PI's Datarecorder.read does)."""
    from pipython import GCSDevice
    from pipython.pidevice.interfaces.piserial import PISerial
    rate = 10_000.0
    args = ["--rate", f"{rate:g}", "--duration", f"{points / rate:g}", "--fast", "--table-points", str(points)]
    proc, _ = controller(args)
    with proc, GCSDevice(gateway=PISerial(proc.port, 115200)) as dev:
        t0 = time.perf_counter()
        dev.RTR(1)
        dev.DRC([1, 2], ["1", "1"], [7, 2])
        dev.DRT(0, 4, 0)
        n = dev.qDRL(1)[1]
        dev.qDRR([1, 2], 1, n)
        while dev.bufstate is not True:
            time.sleep(0.001)
        got = len(dev.bufdata[0])
        wall = time.perf_counter() - t0
    return {"points": points, "samples": got, "wall_s": wall, "samples_per_s": got / wall,
            "reader": "pipython GCSDevice: RTR, DRC, DRT, one qDRR of the whole table"}


def random_params(rng) -> str:
    """A plant over the issue's ranges (alpha 0.02-0.4, fn 100-800 Hz, zeta 0.03-0.3, b 0.5-5)."""
    return (f"alpha={rng.uniform(0.02, 0.4):.4f},fn={rng.uniform(100, 800):.1f},"
            f"zeta={rng.uniform(0.03, 0.3):.3f},b={rng.uniform(0.5, 5):.3f}")


def random_plants(n: int, points: int = 20_000) -> dict:
    """Plants, schedules, RTR and chunk drawn with fixed seeds: the fraction read back exactly, 0 lost."""
    cases = []
    for seed in range(n):
        rng = np.random.default_rng(1000 + seed)
        rtr, chunk = int(rng.integers(1, 5)), int(rng.choice([300, 2000, 8000]))
        schedule = str(rng.choice(["step", "staircase", "updown", "square"]))
        args = ["--rate", "10000", "--duration", f"{points * rtr / 10_000:g}", "--params", random_params(rng),
                "--schedule", schedule, "--period", "0.5", "--seed", str(seed), "--fast",
                "--table-points", str(points)]
        proc, plant = controller(args)
        with proc:
            src = open_source(f"pi:{proc.port}?rtr={rtr}&chunk={chunk}", on_event=None)
            got = []
            deadline = time.monotonic() + 120
            while len(got) < points and time.monotonic() < deadline:
                got += src.read(0.05)
            src.close()
        cycles = np.array([s.seq for s in got]) * rtr
        exact = bool(len(got) == points and np.allclose([s.y for s in got], plant.y[cycles], rtol=1e-9, atol=1e-12)
                     and np.allclose([s.u for s in got], plant.u[cycles], rtol=1e-9, atol=1e-12))
        ok = exact and src.stats.missing == 0 and abs(src.rate - 10_000 / rtr) < 1e-6
        cases.append({"seed": 1000 + seed, "rtr": rtr, "chunk": chunk, "schedule": schedule,
                      "samples": len(got), "missing": src.stats.missing, "values_exact": exact, "pass": ok})
    return {"plants": n, "points_each": points, "pass_fraction": sum(c["pass"] for c in cases) / n,
            "cases": cases}


def realtime(rate: float, seconds: float, wait: bool = True, tcp: bool = False) -> dict:
    from creep_online.online import OnlineEstimator, warm_kernels
    warm_kernels()
    args = ["--rate", f"{rate:g}", "--duration", f"{seconds + 5:g}", "--t-start", "0.2", "--schedule", "square",
            "--period", "1", "--table-points", str(int(rate * (seconds + 5)))] + (["--tcp"] if tcp else [])
    proc, plant = controller(args)
    n_target = int(rate * seconds)
    with proc:
        est = OnlineEstimator(1.0 / rate)
        src = open_source(f"{spec(proc, tcp)}?wait={int(wait)}", on_event=None)
        trigger = proc.wait_event("trigger", timeout=30)
        cpu0, th0, t0 = time.process_time(), time.thread_time(), time.perf_counter()
        loop = FeedLoop(src, lambda _dt: est, dt=1.0 / rate, latency=SampleAge(trigger["t_monotonic"], 1.0 / rate),
                        read_timeout=0.05, duration=seconds * 3 + 60,
                        stop_when=lambda lp: lp.last_seq is not None and lp.last_seq >= n_target - 1)
        end = loop.run()
        wall = time.perf_counter() - t0
        cpu, th = time.process_time() - cpu0, time.thread_time() - th0
        src.close()
        if end.error is not None:
            raise end.error
    model = proc.ready["model"]
    e = est.estimate
    stock = "stock PISocket (spins)" if tcp else "stock PISerial (spins)"
    return {"rate_sps": rate, "seconds": seconds, "link": "tcp" if tcp else "pty",
            "gateway": "select-waiting" if wait else stock,
            "samples": loop.fed, "recorded": n_target,
            "missing": src.stats.missing, "gaps": src.stats.sequence.gaps, "stalls": src.stats.stalls,
            "drr_queries": src.stats.parser.frames, "latency_us": dist(loop.latency_us()),
            "process_cpu_share": cpu / wall, "main_thread_cpu_share": th / wall,
            "estimate_error": {"alpha_abs": e.alpha - model["alpha"], "b_rel": e.b / model["b"] - 1,
                               "a2_rel": e.a2 / model["a2"] - 1}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="shorter runs (5 s real time instead of 20 s)")
    ap.add_argument("--tcp-only", action="store_true", help="only the TCP runs")
    args = ap.parse_args()
    points = 50_000 if args.quick else 200_000
    seconds = 5.0 if args.quick else 20.0
    out: dict = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                             "load_avg_1m": os.getloadavg()[0]}, "quick": args.quick}
    out["tcp"] = {"throughput": [throughput_source(points, 2000, tcp=True),
                                 throughput_source(points, 2000, tcp=True, wait=False)],
                  "realtime": realtime(10_000.0, seconds, tcp=True),
                  "realtime_baseline_stock_gateway": realtime(10_000.0, seconds, wait=False, tcp=True)}
    if args.tcp_only:
        out["machine"]["load_avg_1m_end"] = os.getloadavg()[0]
        write_report(out, indent=2)
        return 0
    base = throughput_baseline(points)
    runs = [throughput_source(points, chunk) for chunk in (500, 2000, 8000)]
    for r in runs:
        r["ratio_vs_baseline"] = r["samples_per_s"] / base["samples_per_s"]
    out["throughput"] = {"baseline_one_qdrr": base, "pi_source": runs}
    out["random_plants"] = random_plants(5 if args.quick else 12)
    out["realtime"] = [realtime(rate, seconds) for rate in (5_000.0, 10_000.0, 20_000.0)]
    out["realtime_baseline_stock_gateway"] = realtime(10_000.0, seconds, wait=False)
    out["machine"]["load_avg_1m_end"] = os.getloadavg()[0]
    write_report(out, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
