"""Reference -> compensator -> plant -> estimator -> compensator, in one process (bench and tests).

``run_closed_loop`` steps a (possibly drifting) plant block by block: the
compensator turns each block of the reference into commands with the model it
holds, the plant (``varying_plant.PlantStream``: per-sample alpha and b)
answers, the estimator learns from (command, noisy output), and the
compensator takes the estimator's model according to ``mode``:

``adaptive``       the estimator's current model after every block, as ``online.gate.ModelGate`` gives it:
                   whenever the estimate determines alpha and b at the noise floor (``good``, or
                   ``provisional`` with only the resonance undetermined: then the last determined
                   resonance, or a rough one), never one the estimator calls degraded or changing (unless
                   only the resonance is contested: then alpha and b stay determined), nor one the
                   compensator cannot take (``CreepCompensator.accepts``); ``gate=False``: only
                   ``good`` estimates, whole (the policy before the gate);
``frozen``         the first model the estimator calls ``good`` (after 10 s: whatever it has), never again
                   (the estimator is not fed after it);
``known``          the true initial model from the start (no estimator needed);
``oracle``         the true current parameters (alpha, b per sample) at every block: the limit of a
                   compensator that inverts the frozen-time plant (no estimator needed; each model taken at once,
                   ``CreepCompensator(rebase="never")``: the plant's past commands were right for the plant of their
                   time, so there is nothing to re-read);
``uncompensated``  u = r / g with g the plant's static gain 1 s after a step (b / Gamma(1 + alpha));
``creep_only``     as ``adaptive``, the estimate's hysteresis loop left out (what inverting the loop adds).

A plant with hysteresis (``hysteresis``: a Prandtl-Ishlinskii loop, ``play_stage.PlayStage``, before the creep
plant; ``loop_scale`` per sample makes its width drift) is identified with ``OnlineEstimator(dt,
effects=("hysteresis",))``: the gate then gives the creep part with the live loop and the window's offset
(``ModelGate``), which the compensator inverts, each new model after it has re-read the commands the plant received
(``CreepCompensator``'s ``rebase``). ``known`` inverts the true initial loop, ``oracle`` the true current one (its weights
times ``loop_scale`` at each block); ``frozen`` keeps the gate's model in force at
``FROZEN_WAIT_S`` (the loop learnt at the start, never updated).

``creep_online.metrics.creep_error`` measures what the issue asks: output minus
reference from the end of the resonance transient after each step to the end of its hold.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from creep_online.model import CreepModel, ExtendedModel
from creep_online.online.compensator import CreepCompensator
from creep_online.online.gate import ModelGate

from .play_stage import PlayStage
from .varying_plant import PlantStream

MODES = ("adaptive", "frozen", "known", "oracle", "uncompensated", "creep_only")


@dataclass
class LoopRecord:
    """What one closed-loop run produced (noise-free output kept for judging)."""

    t: np.ndarray
    r: np.ndarray
    u: np.ndarray
    y_clean: np.ndarray
    y: np.ndarray
    model_t: list          # times (block ends) at which the compensator's model in force changed
    models: list           # the models it took (CreepModel, or ExtendedModel with the live loop)


def run_closed_loop(t: np.ndarray, r: np.ndarray, plant: CreepModel, mode: str, *,
                    alpha: np.ndarray | None = None, b: np.ndarray | None = None, estimator=None,
                    compensator: CreepCompensator | None = None, noise: float = 2e-4, seed: int = 0,
                    block: int = 10, gate: bool = True, hysteresis: dict | None = None,
                    loop_scale: np.ndarray | None = None) -> LoopRecord:
    """One run of the loop; ``alpha``/``b`` per sample make the plant drift (default: constant); ``hysteresis``
    puts a loop before the plant, its weights times ``loop_scale`` per sample (default 1)."""
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}")
    h = float(t[1] - t[0])
    n = t.size
    alpha = np.full(n, plant.alpha) if alpha is None else np.asarray(alpha, dtype=float)
    b = np.full(n, plant.b) if b is None else np.asarray(b, dtype=float)
    stream = PlantStream(h, plant.alpha, plant.a1, plant.a2, plant.b, horizon_s=max(3600.0, 10 * n * h))
    rng = np.random.default_rng(seed)
    stage = None if hysteresis is None else PlayStage(hysteresis)
    scale = np.ones(n) if loop_scale is None else np.asarray(loop_scale, dtype=float)
    comp = compensator or CreepCompensator(h)
    if mode == "oracle" and comp.rebase != "never":
        comp = CreepCompensator(**{**comp.get_params(deep=False), "rebase": "never"})
    if mode == "known":
        comp.set_model(plant if hysteresis is None else ExtendedModel(plant, {"hysteresis": hysteresis}))
    gain = plant.b / math.gamma(1.0 + plant.alpha)
    u_all, y_clean = np.empty(n), np.empty(n)
    model_t, models = [], []
    frozen = False
    take = _policy(mode, gate, hysteresis is not None)
    for k0 in range(0, n, block):
        k1 = min(n, k0 + block)
        if mode == "oracle":
            now = CreepModel(alpha[k0], plant.a1, plant.a2, b[k0])
            comp.set_model(now if stage is None else
                           ExtendedModel(now, {"hysteresis": {**hysteresis, "w": (stage.w * scale[k0]).tolist()}}))
        u = r[k0:k1] / gain if mode == "uncompensated" else comp.command_block(r[k0:k1])
        v = u if stage is None else stage.step_block(u, scale[k0:k1])
        yc = stream.step_block(v, alpha[k0:k1], b[k0:k1])
        u_all[k0:k1], y_clean[k0:k1] = u, yc
        if mode not in ("known", "oracle") and comp.current_model is not None and \
                (not models or comp.current_model is not models[-1]):
            model_t.append(float(t[k1 - 1]))      # (the model in force from the next block)
            models.append(comp.current_model)
        if estimator is None or mode in ("known", "oracle", "uncompensated") or frozen:
            continue                 # (frozen: the estimator's later models are never used: not fed)
        estimator.update_block(u, yc + noise * rng.standard_normal(k1 - k0))
        m = take(estimator, t[k1 - 1])
        if m is not None and mode == "creep_only" and isinstance(m, ExtendedModel):
            m = m.base
        if m is not None and m != comp.current_model:
            if comp.accepts(m):
                comp.set_model(m)    # (in force at once, or after re-reading the history: recorded then)
            else:
                m = None             # a model the compensator cannot take: the last one is held
        if mode == "frozen":
            frozen = m is not None if hysteresis is None else \
                comp.current_model is not None and t[k1 - 1] >= FROZEN_WAIT_S
    y = y_clean + noise * np.random.default_rng(seed + 1).standard_normal(n)
    return LoopRecord(t, r, u_all, y_clean, y, model_t, models)


#: Estimate qualities the compensator takes a whole model from (``OnlineEstimate.quality``).
TRUSTED = ("good",)
#: ``frozen`` waits at most this long (s) for a ``good`` estimate, then takes what there is.
FROZEN_WAIT_S = 10.0


def _policy(mode: str, gate: bool, hysteresis: bool = False):
    """f(estimator, t) -> the model the compensator may take now, or None: per mode (module docstring)."""
    if mode == "creep_only" or (mode == "adaptive" and gate) or (mode == "frozen" and hysteresis):
        g = ModelGate()
        return lambda est, t: g.model(est.estimate)

    def trusted(est, t: float) -> CreepModel | None:
        m = est.model
        if m is None or (est.estimate.quality not in TRUSTED and (mode == "adaptive" or t < FROZEN_WAIT_S)):
            return None
        return m
    return trusted


def staircase(t: np.ndarray, levels, hold_s: float, t_start: float = 0.0) -> np.ndarray:
    """Reference holding ``levels[k]`` on [t_start + k hold_s, t_start + (k+1) hold_s); 0 before."""
    k = np.floor((t - t_start) / hold_s).astype(int)
    out = np.asarray(levels, dtype=float)[np.clip(k, 0, len(levels) - 1)]
    return np.where(t >= t_start, out, 0.0)


def random_drifting_plant(seed: int) -> tuple[CreepModel, np.ndarray]:
    """A seeded random plant over the issue's ranges, and the 6 levels of its staircase.

    alpha 0.02-0.6, fn 100-2000 Hz (log-uniform; for 10 kHz sampling), zeta 0.02-0.7, b of random
    sign and magnitude 0.1-10 (log-uniform); levels 0.2-1.0.
    """
    rng = np.random.default_rng(seed)
    plant = CreepModel.from_resonance(rng.uniform(0.02, 0.6), float(np.exp(rng.uniform(math.log(100.0),
                                                                                       math.log(2000.0)))),
                                      rng.uniform(0.02, 0.7),
                                      float(rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-1.0, 1.0)))
    return plant, rng.uniform(0.2, 1.0, 6)


def drifting_comparison(seed: int, duration: float = 30.0, est_kwargs: dict | None = None,
                        modes: tuple = ("frozen", "adaptive", "oracle"), dt: float = 1e-4, gate: bool = True) -> dict:
    """Creep error per mode on ``random_drifting_plant(seed)`` while alpha drifts +20 % and b +10 % over the run.

    A 6-level staircase (holds of duration / 6, the first left out of the error: start-up), noise 2e-4,
    the estimator fed and read every 100 samples (``OnlineEstimator(dt, input_gate=0, **est_kwargs)``: it is fed
    the compensator's own commands, which no glitch can corrupt and whose step transients jump far beyond the
    pass-through range; ``est_kwargs`` may set it back), the reference
    filter at half the plant's natural frequency; ``gate`` as in ``run_closed_loop``. Returns {mode: creep error
    max abs} plus ``plant``.
    """
    from creep_online.metrics import creep_error
    from creep_online.online import OnlineEstimator
    plant, levels = random_drifting_plant(seed)
    t = np.arange(int(round(duration / dt))) * dt
    hold = duration / len(levels)
    r = staircase(t, levels, hold, t_start=0.05)
    alpha = plant.alpha * (1 + 0.2 * t / duration)
    b = plant.b * (1 + 0.1 * t / duration)
    out: dict = {"plant": plant.describe()}
    for mode in modes:
        est = OnlineEstimator(dt, **{"input_gate": 0.0, **(est_kwargs or {})}) if mode in ("frozen", "adaptive") \
            else None
        rec = run_closed_loop(t, r, plant, mode, alpha=alpha, b=b, estimator=est,
                              compensator=CreepCompensator(dt, bandwidth_hz=plant.fn / 2), block=100, seed=seed,
                              gate=gate)
        out[mode] = creep_error(t, r, rec.y_clean, plant.settling_time, skip_before=hold)["max_abs"]
    return out
