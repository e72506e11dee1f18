"""``creep-online demo --compensate``: the closed loop on the simulated plant, live.

reference -> CreepCompensator -> command frames -> pty -> hil_sim (its DAC applies
them, ``--command-input``) -> sample frames -> pty -> OnlineEstimator -> the
compensator takes the estimate whenever ``online.gate.ModelGate`` gives it one
(alpha and b determined at the noise floor; the resonance when determined, else
the last determined one or a rough one). The estimator is fed the commands the
compensator computed (``input_gate=0``: their step transients are no glitches).

Commands are sent ``LEAD_S`` ahead of the newest sample received, each naming
the sample at which the DAC must apply it (the plant waits for a command that
is late, up to a second, as a busy machine delays samples rather than losing
them; the ledger counts what it held). Before the first model the reference
passes through unchanged (the estimator needs that input to find a model).
The report adds the reference, the measured (compensated) output, the output the
same plant gives without compensation (exact simulation, ``u = r / g`` with
the static gain 1 s after a step), and both creep errors over time.

``--effects hysteresis``: the plant's actuator has a Prandtl-Ishlinskii loop
(``hil_sim --command-input --effects hysteresis``; without parameters a smooth
loop of 30 thresholds, 10 % of the stroke of commands for a unit output). The estimator
runs with ``effects=("hysteresis",)``; the gate gives the creep part with the
live loop, which the compensator inverts. The reference is the staircase
(``--period`` holds, 0.4 s by default: its steps and reversals identify creep,
resonance and loop) followed by a triangle scan at ``SCAN_HZ`` over the same
range, where the report measures the tracking error (output minus the shaped
reference) compensated (measured), creep-only and uncompensated (both
simulated exactly on the same plant).
"""
from __future__ import annotations

import math
import os

import numpy as np

from ..errors import CreepOnlineError

#: How far ahead of the newest received sample commands are sent (s): covers the host's read latency.
LEAD_S = 0.05
#: The demo staircase (fractions of --amplitude), one level per hold.
LEVELS = (0.25, 0.5, 0.75, 1.0, 0.75, 0.875, 0.5, 0.625, 0.25, 0.375)


#: ``--effects hysteresis``: the simulated sensor's noise over the output's stroke (an estimate of 8 operators
#: approximates the plant's smooth loop to about 0.3 % of the stroke: on a much cleaner sensor its window reads
#: ``degraded`` and the gate gives no model).
HYSTERESIS_NOISE = 2.5e-3
#: With hysteresis: the staircase's default hold (s), then a triangle scan at this frequency (Hz).
HYSTERESIS_HOLD_S = 0.4
SCAN_HZ = 2.0


def reference(t: np.ndarray, hold_s: float, amplitude: float, t_start: float) -> np.ndarray:
    """The demo staircase: ``LEVELS`` times amplitude, one per hold, 0 before t_start."""
    k = np.clip(np.floor((t - t_start) / hold_s).astype(int), 0, len(LEVELS) - 1)
    return np.where(t >= t_start, amplitude * np.asarray(LEVELS)[k], 0.0)


def scan_reference(t: np.ndarray, hold_s: float, amplitude: float, t_start: float) -> tuple[np.ndarray, float]:
    """(r, t_scan): the staircase, then from ``t_scan`` a triangle at SCAN_HZ between 0 and amplitude (starting
    at the staircase's last level, rising)."""
    r = reference(t, hold_s, amplitude, t_start)
    t_scan = t_start + len(LEVELS) * hold_s
    first = LEVELS[-1] / 2 / SCAN_HZ                     # (the triangle's time at which it rises through that level)
    phase = SCAN_HZ * (t - t_scan + first)
    return np.where(t >= t_scan, amplitude * (1.0 - np.abs(2.0 * (phase % 1.0) - 1.0)), r), t_scan


def run_compensated(args, progress) -> dict:
    """Run the loop; return the demo's result dict plus ``compensation`` (and the arrays for the report)."""
    from ..model import CreepModel
    from ..online import OnlineEstimator, warm_kernels
    from ..online.compensator import CreepCompensator
    from ..online.compensator import warm_kernels as warm_compensator
    from .demo_plant import DRIFT, hardware_extras, start_plant
    open_source = hardware_extras()
    if args.transport != "serial-binary" or args.faults:
        raise CreepOnlineError("--compensate runs over --transport serial-binary without --faults")
    plant_args = ["--rate", repr(args.rate), "--duration", repr(args.duration), "--transport", "serial-binary",
                  "--command-input", "--seed", str(args.seed), "--linger", "30"]
    if args.effects:                 # (the closed-loop plant takes hysteresis only, and says so in one line)
        plant_args += ["--effects", args.effects]
        if "hysteresis" in args.effects:
            plant_args += ["--noise", repr(HYSTERESIS_NOISE * abs(args.amplitude))]
    if args.params:
        plant_args += ["--params", args.params]
    if args.scenario == "drift":
        plant_args += ["--drift", f"alpha={DRIFT[0]!r},b={DRIFT[1]!r}"]
    plant = start_plant(plant_args, progress, f"the closed-loop plant (hil_sim --command-input, {args.rate:g} Hz)")
    with plant:
        ready = plant.ready
        truth = CreepModel(**ready["model"])
        loop = (ready.get("effects") or {}).get("hysteresis")       # the plant's loop, as it runs it
        n = int(ready["samples"])
        dt = 1.0 / args.rate
        t = np.arange(n) * dt
        if loop is None:
            r, t_scan = reference(t, args.period or 2.0, args.amplitude, 0.2), None
        else:
            r, t_scan = scan_reference(t, args.period or HYSTERESIS_HOLD_S, args.amplitude, 0.2)
        warm_kernels()
        warm_compensator()
        est = OnlineEstimator(dt, input_gate=0.0, **({} if args.refit is None else {"refit": args.refit}),
                              **({} if loop is None else {"effects": ("hysteresis",)}))
        comp = CreepCompensator(dt, bandwidth_hz=args.bandwidth or truth.fn / 2, u_min=args.u_min, u_max=args.u_max)
        src = open_source(f"serial:{plant.port}?rate={args.rate!r}&format=binary")
        dac = os.open(plant.port, os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK)
        sender = _Sender(dac, comp, r, max(1, int(LEAD_S * args.rate)), args.rate)
        sender.send_upto(sender.lead)
        t0 = float(plant.wait_event("start", timeout=60)["t0_monotonic"])
        progress.show(f"demo: closed loop over {plant.port} ({ready['tty']})", force=True)
        from .demo_plant import stream_plant
        result = stream_plant(src, est, truth, n, args, t0, progress,
                         on_batch=lambda loop: sender.step(loop, est))
        progress.close()
        try:
            end = plant.wait_event("end", timeout=10)
        except (TimeoutError, RuntimeError):
            end = {}
        os.close(dac)
        src.close()
    result.update(port=plant.port, tty=ready["tty"], transport="serial-binary", rate_hz=args.rate,
                  truth=truth.describe(), link_events=[], plant_ledger=end.get("ledger"),
                  source_stats=src.stats.as_dict())
    result["compensation"] = _judge(result, r, truth, comp, sender, ready, loop, t_scan)
    if loop is not None:
        result["compensation"]["hysteresis"] = _judge_scan(result, r, t_scan, truth, loop, comp, sender)
    return result


class _Sender:
    """Keeps the command frames ``lead`` samples ahead of the newest received one; adapts the model.

    Writes never block (the port is opened non-blocking and what the pty does
    not take now waits in ``pending``): a host blocked on a full pty while the
    plant is blocked on its own full output would deadlock both.
    """

    def __init__(self, dac: int, comp, r: np.ndarray, lead: int, rate: float) -> None:
        self.dac, self.comp, self.r, self.lead, self.rate = dac, comp, r, lead, rate
        from ..online.gate import ModelGate
        self.pending = bytearray()
        self.gate = ModelGate()
        self.sent = 0
        self.commands = np.zeros(r.size)
        self.shaped = np.full(r.size, np.nan)   # the compensator's shaped reference at each command
        self.model_t: list[int] = []    # sample at which each model was taken

    def send_upto(self, upto: int) -> None:
        from ..io.frames import encode_command
        upto = min(upto, self.r.size)
        if upto <= self.sent:
            return
        frames = []
        for k in range(self.sent, upto):
            u = self.comp.command(self.r[k])
            self.commands[k] = u
            self.shaped[k] = self.comp.shaped_reference
            frames.append(encode_command(k, u))
        self.pending += b"".join(frames)
        self.sent = upto
        self.flush()

    def flush(self) -> None:
        """Write what the pty takes now; keep the rest for the next call."""
        try:
            while self.pending:
                n = os.write(self.dac, self.pending)
                del self.pending[:n]
        except BlockingIOError:
            pass

    def step(self, loop, est) -> None:
        """After each batch of samples: take the gate's model, then send the next commands."""
        m = self.gate.model(est.estimate)
        if m is not None and m != self.comp.current_model \
                and self.comp.accepts(m):    # (one it cannot take: the last one is held)
            self.comp.set_model(m)
            self.model_t.append(loop.last_seq or 0)
        self.send_upto((loop.last_seq or 0) + 1 + self.lead)
        self.flush()


def _judge(result: dict, r: np.ndarray, truth, comp, sender: _Sender, ready: dict, loop: dict | None = None,
           t_scan: float | None = None) -> dict:
    """Creep errors measured (compensated) and simulated (uncompensated), and what the loop did (with a loop: on the
    staircase's holds before the scan)."""
    from ..effects.forward import simulate_with_effects
    from ..metrics import creep_error
    seq, y = result["_seq"], result["_y"]
    dt = 1.0 / float(ready["rate"])
    n = r.size
    t = np.arange(n) * dt
    y_full = np.full(n, math.nan)
    y_full[seq] = y
    gain = truth.b / math.gamma(1.0 + truth.alpha)
    y_uncomp = simulate_with_effects(truth, t, r / gain, {} if loop is None else {"hysteresis": loop})
    settle = max(truth.settling_time, 10 * (comp.tau or 0.0))
    first = sender.model_t[0] * dt if sender.model_t else t[-1]
    ok = ~np.isnan(y_full) & (t < (t_scan if t_scan is not None else math.inf))
    held = t < (t_scan if t_scan is not None else math.inf)
    measured = creep_error(t[ok], r[ok], y_full[ok], settle, skip_before=first)
    uncomp = creep_error(t[held], r[held], y_uncomp[held], settle, skip_before=first)
    result["_r"], result["_y_uncomp"], result["_y_full"] = r, y_uncomp, y_full
    led = ready.get("drift") or {}
    return {"reference": "staircase", "hold_s": float(np.diff(np.flatnonzero(np.diff(r)))[0] * dt) if n > 2 else 0.0,
            "bandwidth_hz": comp.bandwidth_hz, "tau_s": comp.tau, "lead_s": sender.lead * dt,
            "model_changes": len(sender.model_t), "first_model_t": first, "clipped": comp.clipped,
            "creep_error_compensated": {k: measured[k] for k in ("max_abs", "rms")},
            "creep_error_uncompensated_simulated": {k: uncomp[k] for k in ("max_abs", "rms")},
            "ratio_rms": uncomp["rms"] / measured["rms"] if measured["rms"] > 0 else math.inf,
            "noise_std": float(ready.get("noise", 0.0)), "drift": led,
            "note": "errors on the holds after the first model, from the end of the resonance transient; "
                    "the compensated error is measured (it includes the sensor noise)"}


def _judge_scan(result: dict, r: np.ndarray, t_scan: float, truth, loop: dict, comp, sender: _Sender) -> dict:
    """Tracking error on the scan (rms of output minus the shaped reference, from t_scan + 0.5 s): compensated
    (measured), creep-only and uncompensated (simulated exactly: the true loop, then the true creep plant)."""
    from ..effects.forward import simulate_with_effects
    from ..model import ExtendedModel
    from ..online.compensator import CreepCompensator
    dt = 1.0 / float(result["rate_hz"])
    t = np.arange(r.size) * dt
    last = comp.current_model
    plant = {"hysteresis": loop}
    gain = truth.b / math.gamma(1.0 + truth.alpha)
    y_uncomp = simulate_with_effects(truth, t, r / gain, plant)
    y_creep = np.full(r.size, math.nan)
    if last is not None:
        creep = CreepCompensator(dt, last.base if isinstance(last, ExtendedModel) else last,
                                 bandwidth_hz=comp.bandwidth_hz or 1.0 / (2 * math.pi * comp.tau))
        y_creep = simulate_with_effects(truth, t, creep.command_block(r), plant)
    result["_y_creep"], result["_y_uncomp"], result["_t_scan"] = y_creep, y_uncomp, t_scan
    judged = (t >= t_scan + 0.5) & ~np.isnan(result["_y_full"]) & ~np.isnan(sender.shaped)
    shaped = sender.shaped[judged]

    def rms(y: np.ndarray) -> float:
        return float(np.sqrt(np.mean((y[judged] - shaped) ** 2))) if judged.any() else math.nan

    out = {"scan_hz": SCAN_HZ, "t_scan": t_scan, "loop": loop, "live_loop": (last.effects.get("hysteresis")
                                                                               if isinstance(last, ExtendedModel)
                                                                               else None),
           "tracking_rms": {"compensated": rms(result["_y_full"]), "creep_only_simulated": rms(y_creep),
                            "uncompensated_simulated": rms(y_uncomp)},
           "note": "rms of output minus the compensator's shaped reference on the scan, from 0.5 s after it starts; "
                   "the compensated output is measured (with noise), the others simulated exactly on the same plant "
                   "(creep-only: the last model's creep part)"}
    tr = out["tracking_rms"]
    out["ratio_uncompensated"] = tr["uncompensated_simulated"] / tr["compensated"] if tr["compensated"] > 0 else math.inf
    out["ratio_creep_only"] = tr["creep_only_simulated"] / tr["compensated"] if tr["compensated"] > 0 else math.inf
    return out


def print_compensation(c: dict) -> None:
    """The demo summary's compensation lines."""
    m, un = c["creep_error_compensated"], c["creep_error_uncompensated_simulated"]
    print(f"  compens.: reference filter {c['bandwidth_hz']:.0f} Hz, first model at {c['first_model_t']:.2f} s, "
          f"{c['model_changes']} model updates, {c['clipped']} clipped commands")
    print(f"    creep error (measured, with noise)    : max {m['max_abs']:.2e}, rms {m['rms']:.2e}")
    print(f"    uncompensated (same plant, simulated) : max {un['max_abs']:.2e}, rms {un['rms']:.2e} "
          f"({c['ratio_rms']:.0f}x the compensated rms)")
    h = c.get("hysteresis")
    if h:
        tr = h["tracking_rms"]
        print(f"  hysteresis: {SCAN_HZ:g} Hz triangle scan from {h['t_scan']:.2f} s, tracking error rms (output minus "
              f"shaped reference)")
        print(f"    compensated, live loop + creep (measured) : {tr['compensated']:.2e}")
        print(f"    creep only (simulated)                    : {tr['creep_only_simulated']:.2e} "
              f"({h['ratio_creep_only']:.1f}x)")
        print(f"    uncompensated (simulated)                 : {tr['uncompensated_simulated']:.2e} "
              f"({h['ratio_uncompensated']:.1f}x)")
