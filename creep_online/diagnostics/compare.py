"""Compare a model with a measured record: fit percent and the residual (MATLAB's ``compare``).

``compare(model, record)`` simulates the model for the record's input and
reports how much of the measured output it explains: the fit percent
(``100 (1 - ||y - y_hat|| / ||y - mean y||)``, NRMSE) and a residual summary
(rms, largest error, against the noise level, the worst stretch). The model is
fixed; what belongs to the record rather than to the model is estimated by
least squares, as the model's own fit estimated it (``initial="estimate"``):

* the output offset (a sensor's zero differs between records);
* the initial state. A model from ``identify`` (``FittedModel.initial_state``
  "free_response") reads the record as starting at rest at its input offset,
  and adds the free response of an unknown initial state (past steps and the
  resonance's modes, ``creep_online.initial_state``) when the record does not
  start at rest; the choice between these structures, and between a fitted and
  the model's own offset, is BIC's, as in ``identify``. A model from ``fit``
  ("reading") takes the reading of the start rule (``diagnostics.start``:
  from rest or in equilibrium at the first input).

On the record a model was fitted on this gives the fit's own fit percent
again. ``initial="zero"``: no initial state (the model's own start convention),
only the offset is estimated.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..metrics import fit_percent, noise_floor_fit, noise_std_estimate, rms
from ..model import FittedModel
from ..record import Record
from .._threads import single_threaded

#: ``compare``'s choices for the initial state.
INITIAL_CHOICES = ("estimate", "zero")
#: The residual's worst stretch is searched over windows of this fraction of the record.
WORST_WINDOW = 0.05


def error_metrics(y: np.ndarray, y_hat: np.ndarray, noise_std: float | None = None) -> dict[str, float]:
    """fit% (100 (1 - ||e|| / ||y - mean y||)), RMS, MAE, max |e|, R^2, and the noise-floor fit% if known."""
    y = np.asarray(y, dtype=float)
    e = y - np.asarray(y_hat, dtype=float)
    var = float(np.var(y))
    out = {
        "fit_percent": fit_percent(y, y_hat),
        "residual_rms": rms(e),
        "residual_mae": float(np.mean(np.abs(e))),
        "residual_max_abs": float(np.max(np.abs(e))),
        "residual_mean": float(np.mean(e)),
        "r2": float(1.0 - np.mean(e * e) / var) if var > 0 else float("nan"),
    }
    if noise_std is not None and np.isfinite(noise_std):
        out["noise_floor_fit_percent"] = noise_floor_fit(y, noise_std)
        out["residual_over_noise"] = out["residual_rms"] / noise_std if noise_std > 0 else float("inf")
    return out


def overlay(t: np.ndarray, y: np.ndarray, **models: np.ndarray) -> dict[str, np.ndarray]:
    """Columns for an overlay plot: time, measurement and each named model output with its residual."""
    out = {"t": np.asarray(t, dtype=float), "y": np.asarray(y, dtype=float)}
    for name, y_hat in models.items():
        out[name] = np.asarray(y_hat, dtype=float)
        out[f"{name}_residual"] = out["y"] - out[name]
    return out


@dataclass
class Comparison:
    """A model against a record: the fit percent, the residual and what was estimated for the record."""

    source: str
    fit_percent: float
    metrics: dict
    offset: float
    initial: dict
    t: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    y_hat: np.ndarray = field(repr=False)
    model: FittedModel = field(repr=False)

    @property
    def residual(self) -> np.ndarray:
        return self.y - self.y_hat

    def to_dict(self) -> dict:
        """JSON-ready (the ``creep-online compare --json`` keys)."""
        return {"file": self.source, "samples": int(self.y.size), "fit_percent": self.fit_percent,
                "residual": self.metrics, "offset": self.offset, "initial": self.initial,
                "model": {**self.model.base.describe(), "effects": self.model.effects,
                          "fitted_fit_percent": self.model.fitted.get("fit_percent")}}


@single_threaded
def compare(model, record, *, initial: str = "estimate", u_pre: float | None = None,
            t_pre: float | None = None) -> Comparison:
    """The model's fit percent and residual on ``record``, the offset and initial state estimated.

    ``model``: a ``FittedModel``, a result of ``identify`` or of ``fit_extended`` (``IdentificationResult``,
    ``ExtendedFit``), a ``CreepModel`` or ``ExtendedModel`` (read as at rest at input 0), or the path of a
    model file (``creep_online.io.model_file``). ``record``: a ``Record``, a ``(t, u, y)`` tuple or a
    file path (CSV or PI GCS, read as ``diagnose`` reads it). ``initial``: "estimate" (default; see the
    module notes) or "zero". ``u_pre``/``t_pre``: the input before the record and when it jumped to
    u[0], when known (they override the start rule).
    """
    if initial not in INITIAL_CHOICES:
        raise DataError(f"initial must be one of {', '.join(INITIAL_CHOICES)}, got {initial!r}")
    from ..io.model_file import as_fitted_model
    fitted = as_fitted_model(model)
    t, u, y, source, u_pre, t_pre = _record(record, u_pre, t_pre)
    from . import extended as ext
    data = ext.prepare(t, u, y, source=source, u_pre=u_pre, t_pre=t_pre)
    w = np.ones(data.n) if data.weights is None else data.weights
    if initial == "zero":
        reading = (fitted.input_offset, None) if u_pre is None and t_pre is None else (u_pre, t_pre)
        fit = _offset_fit(fitted, data, w, reading, free_offset=True)
    elif fitted.initial_state == "reading":
        fit = _by_reading(fitted, data, w, u_pre, t_pre)
    else:
        fit = _by_bic(fitted, data, w, u_pre, t_pre)
    y_hat, offset, info = fit
    info = {"method": initial, **info}
    noise = noise_std_estimate(data.y - y_hat)
    metrics = {**error_metrics(data.y, y_hat, noise), "noise_rms": noise, **_residual_shape(data.t, data.y - y_hat,
                                                                                              noise)}
    return Comparison(source, metrics["fit_percent"], metrics, offset, info, data.t, data.u, data.y, y_hat, fitted)


def _record(record, u_pre, t_pre) -> tuple:
    """(t, u, y, source, u_pre, t_pre) of a Record, a (t, u, y) tuple or a file."""
    if isinstance(record, (str, Path)):
        from .loading import load_for_diagnosis
        inp = load_for_diagnosis(record)
        rec = inp.record
        if u_pre is None and t_pre is None:
            u_pre, t_pre = inp.u_pre, inp.t_pre
    elif isinstance(record, Record):
        rec = record
    else:
        try:
            t, u, y = record
        except (TypeError, ValueError):
            raise DataError("compare needs a Record, a (t, u, y) tuple or a file path") from None
        rec = Record(t, u, y)
    if u_pre is None and t_pre is None:
        rec.validate()
    return rec.t, rec.u, rec.y, rec.source, u_pre, t_pre


def _path(fitted: FittedModel, data, reading) -> np.ndarray:
    """The model's output without its offset, for the record read as ``reading`` = (u_pre, t_pre)."""
    bare = replace(fitted.model, offset=0.0)
    return bare.simulate(data.t, data.u, u_pre=reading[0], t_pre=reading[1])


def _offset_fit(fitted: FittedModel, data, w: np.ndarray, reading, free_offset: bool) -> tuple:
    """(y_hat, offset, info) with the offset weighted-least-squares fitted (or the model's)."""
    path = _path(fitted, data, reading)
    offset = float(np.sum(w * w * (data.y - path)) / np.sum(w * w)) if free_offset else fitted.offset
    info = {"chosen_by": "the model's convention", "reading": "equilibrium" if reading[0] is None else "rest", "input_before": reading[0],
            "offset_estimated": bool(free_offset), "free_response_terms": 0}
    return path + offset, offset, info


def _wrss(r: np.ndarray, w: np.ndarray) -> float:
    rw = r * w
    return float(rw @ rw)


def _by_reading(fitted: FittedModel, data, w: np.ndarray, u_pre, t_pre) -> tuple:
    """A model from the extended fit: the start rule's reading (``diagnostics.start``), the offset fitted."""
    from .start import clearly_better, readings
    best = None
    for k, reading in enumerate(readings(data.u, u_pre, t_pre)):
        fit = _offset_fit(fitted, data, w, reading, free_offset=True)
        rss = _wrss(data.y - fit[0], w)
        if best is None or (k > 0 and clearly_better(rss, best[0])):
            best = (rss, fit)
    y_hat, offset, info = best[1]
    info["chosen_by"] = "start rule"
    return y_hat, offset, info


def _by_bic(fitted: FittedModel, data, w: np.ndarray, u_pre, t_pre) -> tuple:
    """A model from identify: at rest with the model's offset or a fitted one, or (a record that does not start
    at rest) with the free response of its initial state; the lowest BIC."""
    reading = (fitted.input_offset, None) if u_pre is None and t_pre is None else (u_pre, t_pre)
    n = data.n
    candidates = []
    for free in (False, True):
        y_hat, offset, info = _offset_fit(fitted, data, w, reading, free_offset=free)
        candidates.append((_bic(_wrss(data.y - y_hat, w), n, int(free)), (y_hat, offset, info)))
    if data.uniform and data.weights is None and not _starts_at_rest(data) and u_pre is None and t_pre is None:
        free_fit = _free_response_fit(fitted, data)
        if free_fit is not None:
            k = free_fit[2]["free_response_terms"] + 1
            candidates.append((_bic(_wrss(data.y - free_fit[0], w), n, k), free_fit))
    best = min(candidates, key=lambda c: c[0])[1]
    best[2]["chosen_by"] = "BIC"
    return best


def _bic(rss: float, n: int, k: int) -> float:
    """BIC of a Gaussian residual with k parameters estimated for the record (the model's own are fixed)."""
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def _starts_at_rest(data) -> bool:
    """identify's test: the output constant up to noise before the first input change."""
    from ..identification import input_schedule, starts_at_rest
    return starts_at_rest(data.y, input_schedule(data.t - data.t[0], data.u))


def _free_response_fit(fitted: FittedModel, data) -> tuple | None:
    """The record read as taken in operation: the model's response to u - u[0], an offset and the free response
    of the initial state (``initial_state.free_columns``), the last two by least squares."""
    from ..discretize import step_response_grid
    from ..initial_state import free_columns, past_offsets
    m = fitted.base
    n, h = data.n, data.h
    path = _path(fitted, data, (None, None))
    long = step_response_grid(m.alpha, m.a1, m.a2, h, n + int(past_offsets(n)[-1]) + 1)
    cols = np.column_stack((np.ones(n), free_columns(long, m.a1, m.a2, h, n)))
    norms = np.linalg.norm(cols, axis=0)
    keep = norms > 1e-300
    if not np.all(np.isfinite(cols[:, keep])):
        return None
    coef = np.zeros(cols.shape[1])
    c, *_ = np.linalg.lstsq(cols[:, keep] / norms[keep], data.y - path, rcond=1e-12)
    coef[keep] = c / norms[keep]
    y_hat = path + cols @ coef
    info = {"chosen_by": "BIC", "reading": "equilibrium", "input_before": None, "offset_estimated": True,
            "free_response_terms": int(keep.sum()) - 1}
    return y_hat, float(coef[0]), info


def _residual_shape(t: np.ndarray, r: np.ndarray, noise: float) -> dict:
    """Whether the residual is white noise, and its worst stretch (window of ``WORST_WINDOW`` of the record)."""
    from ..global_fit import at_floor
    width = max(1, int(WORST_WINDOW * r.size))
    c = np.concatenate(([0.0], np.cumsum(r * r)))
    power = (c[width:] - c[:-width]) / width
    k = int(np.argmax(power))
    return {"white": bool(at_floor(r, noise)),
            "worst_window": {"t_start": float(t[k]), "t_end": float(t[min(k + width, r.size) - 1]),
                             "rms": float(math.sqrt(power[k]))}}
