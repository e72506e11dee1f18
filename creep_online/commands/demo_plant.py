"""The simulated plant's side of both demos (``demo`` and ``demo --compensate``): start ``hil_sim`` in its own
process, stream its samples into the estimator with the live status line, and measure the estimate against the
plant valid at each moment."""
from __future__ import annotations

import math
import time

import numpy as np

from ..errors import CreepOnlineError
from ._progress import Progress

#: The drift scenario: alpha and b grow by these fractions over the run (temperature).
DRIFT = (0.2, 0.1)


def estimate_errors(model, truth) -> dict:
    if model is None:
        return {}
    return {"alpha_abs": model.alpha - truth.alpha, "fn_rel": model.fn / truth.fn - 1,
            "zeta_rel": model.zeta / truth.zeta - 1, "b_rel": model.b / truth.b - 1}


def hardware_extras():
    """``open_source``, once the demo's extras (pyserial, hil_sim) import; a one-line error if they do not."""
    try:
        import hil_sim.harness  # noqa: F401
        from ..io import open_source
    except ImportError as exc:
        raise CreepOnlineError(f"demo needs the hardware extras ({exc.name} missing): "
                               "pip install 'creep_online[hardware]'") from None
    return open_source


def start_plant(plant_args: list[str], progress: Progress, what: str):
    """``hil_sim`` in its own process (``hil_sim.harness.PlantProcess``); a one-line error if it does not come up."""
    from hil_sim.harness import PlantProcess
    progress.show(f"demo: starting {what}...", force=True)
    try:
        return PlantProcess(plant_args)
    except RuntimeError as exc:
        raise CreepOnlineError(str(exc).splitlines()[0]) from None


def stream_plant(src, est, truth, n_total: int, args, t0: float, progress: Progress, on_batch=None) -> dict:
    """Feed the plant's stream to the estimator; ``truth``: the plant (a CreepModel), or the plant valid at
    each plant time (a function of t), which the live line and the final errors are measured against."""
    from ..io.feed import FeedLoop, SampleAge
    dt = 1.0 / args.rate
    truth_at = truth if callable(truth) else (lambda _t: truth)
    trace: list[dict] = []
    next_trace = 0.0

    def show(loop: FeedLoop) -> None:
        nonlocal next_trace
        t_plant = loop.last_seq * dt
        if t_plant >= next_trace:
            e = est.estimate
            trace.append({"t": t_plant, "alpha": e.alpha, "a1": e.a1, "a2": e.a2, "b": e.b,
                          "phase": e.phase, "quality": e.quality, "events": len(e.events),
                          "wall": time.monotonic() - loop.started})
            next_trace = t_plant + 0.1
        progress.show(status_line(loop, truth_at((loop.last_seq or 0) * dt)))
        if on_batch is not None:        # --compensate: adapt and send the next commands
            on_batch(loop)

    loop = FeedLoop(src, lambda _dt: est, dt=dt, latency=SampleAge(t0, dt), read_timeout=0.05,
                    duration=args.duration * 3 + 60, on_batch=show, record=True,
                    stop_when=lambda loop: loop.last_seq is not None and loop.last_seq >= n_total - 1)
    end = loop.run()
    if end.error is not None:      # Ctrl-C, a lost port, a bug: the CLI reports it (130, 2, 3)
        raise end.error
    lat = loop.latency_us()
    e = est.estimate
    t_end = (loop.last_seq or 0) * dt
    trace.append({"t": t_end, "alpha": e.alpha, "a1": e.a1, "a2": e.a2, "b": e.b,
                  "phase": e.phase, "quality": e.quality, "wall": loop.wall_s})
    return {
        "estimate": e.to_dict(), "model": est.model.describe() if est.model else None, "t_end": t_end,
        "errors": estimate_errors(est.model, truth_at(t_end)), "samples_received": loop.fed, "samples_sent_by_plant": n_total,
        "wall_s": loop.wall_s, "achieved_rate_sps": loop.fed / loop.wall_s if loop.wall_s > 0 else 0.0,
        "latency_us": latency_dist(lat), "gaps_not_fed": loop.lost_not_fed,
        "trace": trace, "_seq": np.asarray(loop.seqs), "_u": np.asarray(loop.us), "_y": np.asarray(loop.ys),
        "_lat_us": lat,
    }


def latency_dist(x: np.ndarray) -> dict:
    if x.size == 0:
        return {"p50": math.nan, "p99": math.nan, "max": math.nan}
    return {"p50": float(np.percentile(x, 50)), "p99": float(np.percentile(x, 99)), "max": float(np.max(x))}


def status_line(loop, truth) -> str:
    """The live line: plant time, rate, phase, latest change, estimate and its error, latency, link trouble."""
    est, src = loop.estimator, loop.source
    e = est.estimate
    el = time.monotonic() - loop.started
    n = src.stats.samples
    text = f"t={(loop.last_seq or 0) * est.dt:6.2f}s {n / max(el, 1e-9) / 1e3:5.1f} kS/s "
    text += f"[{e.phase}/{e.quality}] "
    if e.events:
        ev = e.events[-1]
        text += (f"fault@{ev['t']:.1f}s({ev['error']}) " if ev.get("kind") == "internal_fault" else
                 f"change@{ev['t']:.1f}s({','.join(ev['moved']) or '?'}) ")
    switched = [rs for rs in e.researches if rs["switched"]]
    if switched:
        text += f"research@{switched[-1]['t']:.1f}s({','.join(switched[-1]['moved'])}) "
    if e.outliers or e.input_outliers:
        text += f"outliers y{e.outliers} u{e.input_outliers} "
    m = est.model
    if m is not None:
        err = estimate_errors(m, truth)
        text += (f"alpha={m.alpha:.4f} ({err['alpha_abs']:+.1e}) fn={m.fn:.1f}Hz ({100 * err['fn_rel']:+.2f}%) "
                 f"zeta={m.zeta:.3f} b={m.b:.4f} ({100 * err['b_rel']:+.2f}%) ")
    recent = loop.recent_latency_us(2000)
    if recent.size:
        text += f"lat p99={np.percentile(recent, 99):.0f}us "
    st = src.stats
    bad = st.missing + st.bad_frames + st.sequence.duplicates + st.disconnects
    if bad:
        text += f"| lost {st.missing} bad {st.bad_frames} dup {st.sequence.duplicates} disc {st.disconnects}"
    return text
