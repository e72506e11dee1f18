"""Online estimation with an extended model: stream-compensate the fitted effects, watch the live error fall.

``EffectCompensator`` undoes catalogue effects sample by sample, turning a
measured pair (u, y) into the pair (v, y_base) the *base* creep model would
see: input effects are applied to the input (hysteresis, nonlinear gain,
delay), additive and parallel ones are removed from the output (drift,
periodic disturbance, second mode, second creep) and leakage is inverted
(``(1 + tau s)/(tau s) = 1 + 1/(tau s)``: add the running integral of the
output over tau). ``ExtendedOnlineEstimator`` feeds the compensated stream to
the project's ``OnlineEstimator`` (unchanged), so the estimator runs with the
extended model, and its live prediction error can be compared with the plain
estimator's (``live_error``; both warm-started from their batch fits, ``warm_start``;
``measure`` and ``python -m creep_online.diagnostics.online`` give the table in
docs/diagnostics.md). Per-sample work is O(1) for every effect except
``second_creep`` (O(number of input changes so far), exact for a staircase).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.signal import cont2discrete

from ..effects import INITIAL_STATES
from ..errors import ModelError


class EffectCompensator:
    """Per-sample inverse of fitted catalogue effects (parameters as in ``ExtendedFit.effect_params``)."""

    def __init__(self, dt: float, effects: dict[str, dict]) -> None:
        self.dt = float(dt)
        self.effects = {k: dict(v) for k, v in effects.items()}
        self.n = 0
        self._ref = None
        self._y0 = 0.0
        self._vprev = 0.0
        e = self.effects
        if "hysteresis" in e:
            self._r = np.asarray(e["hysteresis"]["r"], dtype=float)
            self._w = np.asarray(e["hysteresis"]["w"], dtype=float)
            self._init = INITIAL_STATES[e["hysteresis"].get("initial", "centred")]
            self._p = None
        # delay = k whole samples + a fraction f: the sample-held input delayed by (k + f) h, averaged over
        # each sample interval, is (1 - f) v[n-k] + f v[n-k-1] (rounding to whole samples left 1.2-1.5x
        # the noise floor online on the hidden-effect records; this leaves ~1.0x)
        d = float(e.get("delay", {}).get("delay_s", 0.0)) / self.dt
        self._k = int(math.floor(d + 1e-9))
        self._frac = d - self._k if d - self._k > 1e-9 else 0.0
        self._k1 = self._k + (1 if self._frac else 0)   # samples of history kept
        self._hist: list[float] = []
        if "second_mode" in e:
            p = e["second_mode"]
            wn = 2 * math.pi * float(p["fn_hz"])
            a = np.array([[0.0, 1.0], [-wn * wn, -2 * float(p["zeta"]) * wn]])
            b = np.array([[0.0], [wn * wn]])
            ad, bd, *_ = cont2discrete((a, b, np.eye(2), np.zeros((2, 1))), self.dt, method="zoh")
            self._ad, self._bd = ad, bd[:, 0]
            self._x2 = np.zeros(2)
            self._g2 = float(p["gain"])
        if "second_creep" in e:
            self._c = float(e["second_creep"]["gain"])
            self._a2 = float(e["second_creep"]["alpha2"])
            self._changes: list[tuple[int, float]] = []
        if "leakage" in e:
            self._tau = float(e["leakage"]["tau_s"])
            self._integral = 0.0
            self._yprev = 0.0

    def step(self, u: float, y: float) -> tuple[float, float]:
        """(v, y_base) for one sample."""
        e = self.effects
        n = self.n
        t = n * self.dt
        v = float(u)
        if "hysteresis" in e:
            if self._p is None:
                self._p = v + self._init * self._r
            self._p = np.maximum(v - self._r, np.minimum(v + self._r, self._p))
            v = v + float(self._w @ self._p)
        if "nonlinear_gain" in e:
            p = e["nonlinear_gain"]
            v = v + float(p.get("k2", 0.0)) * v * v + float(p.get("k3", 0.0)) * v ** 3
        if self._ref is None:  # the record starts in equilibrium at its first (transformed) input
            self._ref, self._y0 = v, float(y)
            self._hist = [v] * self._k1
            self._vprev = v
        if self._k1:
            self._hist.append(v)          # _hist[-1 - j] = v[n - j]
            v = self._hist[-1 - self._k]
            if self._frac:
                v = (1.0 - self._frac) * v + self._frac * self._hist[0]
            self._hist.pop(0)
        yb = float(y)
        if "leakage" in e:  # y_lin - y0 = (y - y0) + (1/tau) int (y - y0) dt   (trapezoid)
            d = yb - self._y0
            if n:
                self._integral += 0.5 * (d + self._yprev) * self.dt
            self._yprev = d
            yb = yb + self._integral / self._tau
        if "drift" in e:
            yb -= float(e["drift"].get("rate", 0.0)) * t
        if "periodic_disturbance" in e:
            p = e["periodic_disturbance"]
            amp = np.atleast_1d(p.get("amplitude", 0.0))
            ph = np.broadcast_to(np.atleast_1d(p.get("phase", 0.0)), amp.shape)
            for k, (a, phi) in enumerate(zip(amp, ph), start=1):
                yb -= float(a) * math.sin(2 * math.pi * k * float(p["f_hz"]) * t + float(phi))
        if "second_mode" in e:  # output at this sample, then advance the ZOH state with this input
            yb -= self._g2 * self._x2[0]
            self._x2 = self._ad @ self._x2 + self._bd * (v - self._ref)
        if "second_creep" in e:
            dv = v - self._vprev
            if dv != 0.0:
                self._changes.append((n, dv))
            yb -= self._c * sum(dvk * ((n - k) * self.dt) ** self._a2 for k, dvk in self._changes) \
                / math.gamma(1.0 + self._a2)
        self._vprev = v
        self.n += 1
        return v, yb


class ExtendedOnlineEstimator:
    """The project's ``OnlineEstimator`` run on the effect-compensated stream: the extended model, online."""

    def __init__(self, dt: float, effects: dict[str, dict], **estimator_kwargs) -> None:
        from ..online.estimator import OnlineEstimator
        unknown = [k for k in effects if k not in ("hysteresis", "nonlinear_gain", "delay", "drift", "leakage",
                                                    "periodic_disturbance", "second_mode", "second_creep")]
        if unknown:
            raise ModelError(f"unknown effect(s) {', '.join(unknown)}")
        self.compensator = EffectCompensator(dt, effects)
        self.estimator = OnlineEstimator(dt, **estimator_kwargs)
        self._last = math.nan

    def update(self, u: float, y: float) -> None:
        v, yb = self.compensator.step(u, y)
        self._last = yb
        self.estimator.update(v, yb)

    @property
    def model(self):
        return self.estimator.model

    @property
    def estimate(self):
        return self.estimator.estimate

    @property
    def prediction_error(self) -> float:
        """Latest output minus the extended model's prediction (NaN before tracking)."""
        p = self.estimator.last_prediction
        if p is None or self.estimator.phase != "tracking":
            return math.nan
        return self._last - p


def warm_start(model, dt: float) -> dict:
    """``OnlineEstimator`` keyword arguments that start it from a batch fit: the fit's alpha as a hint.

    The estimator's start-up search needs no guess (it compares candidates
    over alpha, fn and zeta); the batch alpha is added to its grid so that a
    record too short to settle the search still starts at the batch answer.
    The search window (t_c) is left to the estimator.
    """
    if model is None:
        return {}
    return {"alpha0": float(np.clip(model.alpha, 0.01, 0.95))}


def live_error(t: np.ndarray, u: np.ndarray, y: np.ndarray, effects: dict[str, dict], window_s: float = 1.0,
               base_model=None, extended_model=None, **estimator_kwargs) -> dict:
    """Stream a record through the plain and the extended online estimator; windowed RMS prediction errors.

    ``base_model`` / ``extended_model``: batch fits (``CreepModel``) whose alpha the plain and the
    extended estimator get as a hint (``warm_start``); None runs the estimator's defaults.
    Returns ``{"t": window ends, "base": RMS per window, "extended": RMS per window}`` (NaN while
    an estimator is not tracking yet): the live error display's data.
    """
    from ..online.estimator import OnlineEstimator
    dt = float(t[1] - t[0])
    plain = OnlineEstimator(dt, **{**estimator_kwargs, **warm_start(base_model, dt)})
    ext = ExtendedOnlineEstimator(dt, effects, **{**estimator_kwargs, **warm_start(extended_model, dt)})
    e0 = np.full(len(t), np.nan)
    e1 = np.full(len(t), np.nan)
    for i in range(len(t)):
        plain.update(u[i], y[i])
        p = plain.last_prediction
        if p is not None and plain.phase == "tracking":
            e0[i] = y[i] - p
        ext.update(u[i], y[i])
        e1[i] = ext.prediction_error
    w = max(1, int(round(window_s / dt)))
    ends, r0, r1 = [], [], []
    for a in range(0, len(t), w):
        ends.append(float(t[min(a + w, len(t)) - 1]))
        for src, dst in ((e0, r0), (e1, r1)):
            seg = src[a:a + w]
            seg = seg[np.isfinite(seg)]
            dst.append(float(np.sqrt(np.mean(seg * seg))) if seg.size else math.nan)
    return {"t": ends, "base": r0, "extended": r1}


def tail_rms(table: dict, fraction: float = 0.25) -> tuple[float, float]:
    """(plain, extended) RMS live error over the last ``fraction`` of the windows (NaN windows ignored)."""
    k = max(1, int(round(fraction * len(table["t"]))))
    out = []
    for key in ("base", "extended"):
        r = np.asarray(table[key][-k:], dtype=float)
        r = r[np.isfinite(r)]
        out.append(float(np.sqrt(np.mean(r * r))) if r.size else math.nan)
    return out[0], out[1]


def measure(effect: str | None, seed: int = 0, n: int = 20000, warm: bool = True) -> dict:
    """One row of the online table: a hidden-effect record (``hil_sim``), batch fits, both online runs.

    Live errors over the last quarter of the record, as multiples of the true noise RMS.
    """
    from hil_sim.hidden_effects import hidden_dataset

    from .extended import fit_base, fit_extended, prepare
    ds = hidden_dataset(effect, seed, n=n)
    data = prepare(ds.t, ds.u, ds.y)
    base = fit_base(data)
    fit = fit_extended(data, [effect], base) if effect else base
    params = fit.effect_params if effect else {}
    table = live_error(ds.t, ds.u, ds.y, params, window_s=1.0,
                       base_model=base.model if warm else None, extended_model=fit.model if warm else None)
    raw, comp = tail_rms(table)
    return {"effect": effect or "none", "seed": seed, "seconds": n * float(ds.t[1] - ds.t[0]),
            "batch_before": base.residual_rms / ds.noise_std, "batch_after": fit.residual_rms / ds.noise_std,
            "online_plain": raw / ds.noise_std, "online_extended": comp / ds.noise_std}


def format_live_error(table: dict, noise: float | None = None) -> str:
    """The live error display as text: one line per window, base vs extended model."""
    lines = [f"  {'t (s)':>8} {'online error, base':>18} {'extended':>10}" + ("   (x noise floor)" if noise else "")]
    for t, a, b in zip(table["t"], table["base"], table["extended"]):
        sa = "-" if not math.isfinite(a) else (f"{a / noise:.3g}x" if noise else f"{a:.4g}")
        sb = "-" if not math.isfinite(b) else (f"{b / noise:.3g}x" if noise else f"{b:.4g}")
        lines.append(f"  {t:>8.3g} {sa:>18} {sb:>10}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``python -m creep_online.diagnostics.online [N] [SEEDS] [--cold]``: the online table (JSON lines)."""
    import json
    import sys

    from ..effects import EFFECTS
    args = list(sys.argv[1:] if argv is None else argv)
    warm = "--cold" not in args
    args = [a for a in args if a != "--cold"]
    n = int(args[0]) if args else 20000
    seeds = [int(x) for x in args[1].split(",")] if len(args) > 1 else [0, 1, 2]
    for seed in seeds:
        for effect in (None, *EFFECTS):
            print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v)
                              for k, v in measure(effect, seed, n, warm).items()}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
