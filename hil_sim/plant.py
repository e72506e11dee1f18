"""The simulated plant: creep model (+ hidden effects) driven by an input schedule, plus noise and ADC.

The whole record is computed up front with the exact simulator
(``creep_online.simulate.simulate(..., method="exact")``: closed-form step
responses superposed, ~1e-14) so that pacing never waits on numerics; the
transport then releases sample n at t0 + n / rate. Effects from the catalogue
(docs/diagnostics.md) are applied by ``creep_online.effects`` when that module
is present; this package keeps no copy of the effect models.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from creep_online import CreepModel, simulate
from creep_online.io.params import parse_params as _parse_params

SCHEDULES = ("step", "staircase", "updown", "square")
#: The plant's limits: sample rates from 1 Hz to 1 MHz, at most 5e7 samples (the record is computed in memory).
MIN_RATE, MAX_RATE = 1.0, 1e6
MAX_SAMPLES = 5e7

#: The demo plant: a stacked piezo with marked creep, first mode at 420 Hz (no estimator default or grid point).
DEFAULT_PARAMS = {"alpha": 0.12, "fn": 420.0, "zeta": 0.08, "b": 2.5}


def parse_params(text: str | None) -> CreepModel:
    """The plant's model: ``creep_online.io.params.parse_params`` over :data:`DEFAULT_PARAMS`.

    Either ``alpha=..,fn=..,zeta=..,b=..`` or ``alpha=..,a1=..,a2=..,b=..``;
    what the text leaves out comes from the demo plant (a ModelError, a
    ValueError, names anything else).
    """
    return _parse_params(text, DEFAULT_PARAMS)


def make_input(schedule: str, t: np.ndarray, *, amplitude: float = 1.0, period: float = 2.0,
               t_start: float = 0.0) -> np.ndarray:
    """Input u(t) for a named schedule (zero-order held between samples).

    step       0 until t_start, then ``amplitude``
    staircase  up in 4 steps of amplitude/4, then down with reversals (up 1, down 2)
    updown     step up at t_start, back to 0 at the middle of the record
    square     amplitude/2 +- amplitude/2 with the given period
    """
    t = np.asarray(t, dtype=float)
    u = np.zeros_like(t)
    on = t >= t_start
    if schedule == "step":
        u[on] = amplitude
    elif schedule == "updown":
        mid = t_start + (t[-1] - t_start) / 2
        u[on & (t < mid)] = amplitude
    elif schedule == "staircase":
        levels = np.array([1, 2, 3, 4, 3, 3.5, 2, 2.5, 1, 1.5]) * amplitude / 4
        k = np.floor((t - t_start) / period).astype(int)
        k = np.clip(k, 0, len(levels) - 1)
        u[on] = levels[k[on]]
    elif schedule == "square":
        phase = np.floor((t - t_start) / (period / 2)).astype(int) % 2
        u[on] = np.where(phase[on] == 0, amplitude, 0.0)
    else:
        raise ValueError(f"unknown schedule {schedule!r}; choose one of {', '.join(SCHEDULES)}")
    return u


#: Parameters used when ``--effects`` names an effect without giving any (scenario values, not models).
EFFECT_DEFAULTS = {
    "hysteresis": {"r": [0.1, 0.3, 0.5], "w": [0.10, 0.06, 0.03]},
    "nonlinear_gain": {"k2": 0.08, "k3": 0.0},
    "second_mode": {"gain": 0.05, "fn_hz": 1200.0, "zeta": 0.03},
    "drift": {"rate": 2e-3, "offset": 0.0},
    "leakage": {"tau_s": 30.0},
    "delay": {"delay_s": 5e-4},
    "periodic_disturbance": {"f_hz": 50.0, "amplitude": 2e-3, "phase": 0.0},
    "second_creep": {"gain": 0.05, "alpha2": 0.4},
}


def parse_effects(text: str | None) -> dict[str, dict]:
    """``name[:k=v,k=v][;name...]`` or a JSON object -> ``{name: params}`` for creep_online.effects."""
    text = (text or "").strip()
    if not text:
        return {}
    if text.startswith("{"):
        import json
        try:
            loaded = json.loads(text)
            return {str(k): dict(v) for k, v in loaded.items()}
        except (ValueError, TypeError, AttributeError) as exc:
            raise ValueError(f"--effects: not a JSON object of effect parameters ({str(exc)[:80]})") from None
    out: dict[str, dict] = {}
    for item in text.split(";"):
        item = item.strip()
        if not item:
            continue
        name, _, rest = item.partition(":")
        name = name.strip()
        params = dict(EFFECT_DEFAULTS.get(name, {})) if not rest.strip() else {}
        for kv in filter(None, (x.strip() for x in rest.split(","))):
            k, _, v = kv.partition("=")
            try:
                vals = [float(x) for x in v.split("/")]
            except ValueError:
                raise ValueError(f"--effects: {name}: {k.strip()} must be numbers, got {v!r}") from None
            params[k.strip()] = vals if len(vals) > 1 else vals[0]
        out[name] = params
    return out


def check_effects(effects: dict) -> None:
    """ValueError unless every effect is in the catalogue and its parameters are finite numbers."""
    if not isinstance(effects, dict):
        raise ValueError(f"effects must be a mapping name -> parameters, got {type(effects).__name__}")
    try:
        from creep_online.effects import effect_names
        known = effect_names()
    except ImportError:          # (a build without the catalogue: apply_effects says so)
        known = tuple(effects)
    for name, params in effects.items():
        if name not in known:
            raise ValueError(f"unknown effect {name!r}; choose from {', '.join(known)}")
        if not isinstance(params, dict):
            raise ValueError(f"effect {name}: parameters must be key=value pairs, got {params!r}")
        for key, value in params.items():
            values = value if isinstance(value, list) else [value]
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values):
                raise ValueError(f"effect {name}: {key} must be finite numbers, got {value!r}")


def apply_effects(model: CreepModel, t: np.ndarray, u: np.ndarray, effects: dict[str, dict]) -> np.ndarray:
    """Output with hidden effects, delegated to ``creep_online.effects`` (no copy kept here)."""
    try:
        from creep_online import effects as fx
    except ImportError:
        raise SystemExit("hil_sim: --effects needs creep_online.effects, which is not available in this build")
    fn = getattr(fx, "simulate_with_effects", None)
    if fn is None:
        raise SystemExit("hil_sim: creep_online.effects has no simulate_with_effects(model, t, u, effects)")
    return np.asarray(fn(model, t, u, effects), dtype=float)


@dataclass
class PlantConfig:
    model: CreepModel
    rate: float = 10_000.0
    duration: float = 20.0
    schedule: str = "step"
    amplitude: float = 1.0
    period: float = 2.0
    t_start: float = 0.0
    noise: float = 2e-4           # output noise std (output units)
    adc_bits: int = 20
    adc_range: float = 10.0       # full scale +- adc_range/2
    effects: dict = field(default_factory=dict)
    seed: int = 0
    payload: tuple[float, float] | None = None   # (time s, added mass fraction): a2 *= 1 + m from then on
    drift: tuple[float, float] = (0.0, 0.0)      # relative drift of (alpha, b) over the record, linear in time

    def __post_init__(self) -> None:
        """ValueError naming the first setting the plant cannot run with (one line, as ``python -m hil_sim``
        prints it): every number finite and in its range, a known schedule and known effects."""
        def number(name: str, value, low: float, high: float, low_open: bool = False) -> None:
            ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) \
                and math.isfinite(value) and (value > low if low_open else value >= low) and value <= high
            if not ok:
                bound = f"> {low:g}" if low_open else f">= {low:g}"
                raise ValueError(f"{name} must be a finite number {bound} and <= {high:g}, got {value!r}")
        number("rate (Hz)", self.rate, MIN_RATE, MAX_RATE)
        number("duration (s)", self.duration, 0.0, MAX_SAMPLES, low_open=True)
        if self.duration * self.rate > MAX_SAMPLES:
            raise ValueError(f"duration x rate is {self.duration * self.rate:.3g} samples, more than {MAX_SAMPLES:.0e}")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"unknown schedule {self.schedule!r}; choose one of {', '.join(SCHEDULES)}")
        number("amplitude", self.amplitude, -1e6, 1e6)
        number("period (s)", self.period, 0.0, 1e9, low_open=True)
        number("t_start (s)", self.t_start, 0.0, 1e9)
        number("noise (std)", self.noise, 0.0, 1e6)
        if not (isinstance(self.adc_bits, (int, np.integer)) and 2 <= self.adc_bits <= 32):
            raise ValueError(f"adc_bits must be a whole number from 2 to 32, got {self.adc_bits!r}")
        number("adc_range", self.adc_range, 0.0, 1e9, low_open=True)
        check_effects(self.effects)
        if self.payload is not None:
            at, mass = self.payload
            number("payload time (s)", at, 0.0, 1e9)
            number("payload mass fraction", mass, -1.0, 1e6, low_open=True)
        for name, value in zip(("alpha drift", "b drift"), self.drift):
            number(name, value, -1.0, 1e6, low_open=True)


@dataclass
class PlantRecord:
    t: np.ndarray
    u: np.ndarray
    y_clean: np.ndarray   # model (+ effects) output, no noise
    y: np.ndarray         # what the amplifier reports: noisy, quantized
    lsb: float


def generate(cfg: PlantConfig, u: np.ndarray | None = None) -> PlantRecord:
    """The full sampled record of the plant for this configuration (``u``: an input that replaces the schedule)."""
    n = max(2, int(round(cfg.duration * cfg.rate))) if u is None else len(u)
    t = np.arange(n) / cfg.rate
    if u is None:
        u = make_input(cfg.schedule, t, amplitude=cfg.amplitude, period=cfg.period, t_start=cfg.t_start)
    if cfg.effects:
        y_clean = apply_effects(cfg.model, t, u, cfg.effects)
    elif any(cfg.drift):
        from .varying_plant import simulate_varying
        m = cfg.model
        frac = t / max(t[-1], 1e-12)
        y_clean = simulate_varying(t, u, m.alpha * (1 + cfg.drift[0] * frac), m.a1, m.a2, m.b * (1 + cfg.drift[1] * frac))
    elif cfg.payload is not None:
        from .scenarios import simulate_tv
        at, mass = cfg.payload
        m = cfg.model
        y_clean = simulate_tv(1.0 / cfg.rate, u, m.alpha, m.a1, np.where(t < at, m.a2, m.a2 * (1.0 + mass)), m.b)
    else:
        y_clean = simulate(cfg.model, t, u, method="exact")
    rng = np.random.default_rng(cfg.seed)
    y = y_clean + cfg.noise * rng.standard_normal(n) if cfg.noise > 0 else y_clean.copy()
    lsb = cfg.adc_range / 2.0 ** cfg.adc_bits
    half = cfg.adc_range / 2
    y = np.clip(np.round(y / lsb) * lsb, -half, half - lsb)
    return PlantRecord(t, u, y_clean, y, lsb)
