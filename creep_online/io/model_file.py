"""Model files: a fitted model saved as JSON (``identify -o``, ``fit -o``) and read back, validated.

One versioned schema (``SCHEMA``, ``SCHEMA_VERSION``)::

    {
      "schema": "creep_online.model",
      "schema_version": 1,
      "creep_online_version": "0.1.0",
      "created": "2025-01-31T12:00:00Z",
      "model": {"alpha": 0.12, "a1": 3.8e-4, "a2": 1.4e-7, "b": 2.5, "fn_hz": 420.0, "zeta": 0.08},
      "effects": {"delay": {"delay_s": 0.002}},
      "offset": 0.0,
      "input_offset": 0.0,
      "initial_state": "free_response",
      "units": {"t": "s", "u": "V", "y": "um"},
      "fitted": {"command": "identify", "file": "step.csv", "samples": 20000, "fit_percent": 99.1}
    }

``model``: the four parameters (``fn_hz``/``zeta`` are derived, for readers; ignored on load).
``effects``: catalogue effects and their parameter dicts (``creep_online.effects``). ``offset``:
the output at rest. ``input_offset``: the input the plant rests at before a record (the input jumps
to its first value at the first sample); null: it rests at the record's own first input (the
model sees u - u[0]). ``initial_state``: how the fit treated a record that did not start at rest
("free_response": free initial-state terms, ``identify``; "reading": from rest or in equilibrium,
``fit``), which is how ``compare`` estimates a record's initial state. ``units`` and ``fitted``
are descriptive. The output is ``y = offset + G[u]``, the input held between samples.

``load_model`` refuses, in one line (``DataError``), anything that is not such a file: not JSON,
another schema, a newer schema version, a missing or invalid field, an unknown effect or effect
parameters the forward model rejects.
"""
from __future__ import annotations

import datetime as _dt
import json
import math
from pathlib import Path

import numpy as np

from ..errors import CreepOnlineError, DataError, ModelError
from ..model import INITIAL_STATE_METHODS, CreepModel, ExtendedModel, FittedModel
from .jsonable import json_text

SCHEMA = "creep_online.model"
SCHEMA_VERSION = 1
#: The suffix a model file must have (``-o``).
SUFFIX = ".json"
#: Largest model file read (bytes): a model is a few hundred bytes, hysteresis' weights a few kB.
MAX_BYTES = 1 << 20


def tool_version() -> str:
    """The installed creep_online's version."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("creep_online")
    except PackageNotFoundError:
        from .. import __version__
        return __version__


def as_fitted_model(model) -> FittedModel:
    """A ``FittedModel`` from any model form: itself, a fit result (``.fitted_model()``), a ``CreepModel`` or
    ``ExtendedModel`` (at rest at input 0 before a record), or a model file's path."""
    if isinstance(model, FittedModel):
        return model
    if isinstance(model, (str, Path)):
        return load_model(model)
    if hasattr(model, "fitted_model"):
        return model.fitted_model()
    if isinstance(model, CreepModel):
        model = ExtendedModel(model)
    if isinstance(model, ExtendedModel):
        return FittedModel(model, input_offset=0.0, initial_state="reading" if model.effects else "free_response")
    raise DataError(f"not a model: {type(model).__name__} (give a FittedModel, a fit result, a CreepModel, "
                    "an ExtendedModel or a model file)")


def model_document(model, units: dict | None = None, **fitted) -> dict:
    """The model file's JSON document for ``model`` (any form ``as_fitted_model`` takes)."""
    fm = as_fitted_model(model)
    doc_units = {k: v for k, v in {**fm.units, **(units or {})}.items() if v}
    return {"schema": SCHEMA, "schema_version": SCHEMA_VERSION, "creep_online_version": tool_version(),
            "created": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "model": fm.base.describe(), "effects": fm.effects, "offset": fm.offset,
            "input_offset": fm.input_offset, "initial_state": fm.initial_state, "units": doc_units,
            "fitted": {**fm.fitted, **fitted}}


def save_model(model, path: str | Path, *, units: dict | None = None, inputs=(), **fitted) -> Path:
    """Write ``model`` as a model file (atomically; never over one of ``inputs``); the path written.

    ``units``: {"t": ..., "u": ..., "y": ...} where known; ``fitted``: more about the fit (file, samples).
    """
    from .safe_files import atomic_write, check_output
    out = Path(path)
    if out.suffix.lower() != SUFFIX:
        raise DataError(f"{out}: a model file is JSON: give a name ending in {SUFFIX}")
    check_output(out, inputs=inputs)
    text = json_text(model_document(model, units, **fitted))
    with atomic_write(out) as fh:
        fh.write(text + "\n")
    return out


def load_model(path: str | Path) -> FittedModel:
    """The model a model file holds, validated; ``DataError`` naming the file and the first problem."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            raw = fh.read(MAX_BYTES + 1)
    except FileNotFoundError:
        raise DataError(f"{path}: no such file") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(raw) > MAX_BYTES:
        raise DataError(f"{path}: larger than {MAX_BYTES} bytes: not a creep_online model file")
    try:
        doc = json.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: not a creep_online model file (not JSON: {exc})") from None
    try:
        return model_from_document(doc)
    except CreepOnlineError as exc:
        raise DataError(f"{path}: {str(exc).splitlines()[0]}") from None


def model_from_document(doc) -> FittedModel:
    """A ``FittedModel`` from a parsed model file; DataError naming the first problem."""
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        found = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
        raise DataError(f"not a creep_online model file (schema {found!r}, expected {SCHEMA!r})")
    version = doc.get("schema_version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise DataError(f"schema_version must be a positive integer, got {version!r}")
    if version > SCHEMA_VERSION:
        raise DataError(f"model file schema version {version} is newer than this creep_online reads "
                        f"({SCHEMA_VERSION}): upgrade creep_online")
    params = _field(doc, "model", dict)
    try:
        base = CreepModel(*(_number(params, k, "model") for k in ("alpha", "a1", "a2", "b")))
    except ModelError as exc:
        raise DataError(f"model: {exc}") from None
    effects = _field(doc, "effects", dict)
    offset = _number(doc, "offset", "")
    input_offset = doc.get("input_offset", "missing")
    if input_offset == "missing":
        raise DataError("missing field input_offset (a number, or null)")
    if input_offset is not None:
        input_offset = _number(doc, "input_offset", "")
    method = doc.get("initial_state")
    if method not in INITIAL_STATE_METHODS:
        raise DataError(f"initial_state must be one of {', '.join(INITIAL_STATE_METHODS)}, got {method!r}")
    units = _field(doc, "units", dict, optional=True)
    if not all(isinstance(v, str) for v in units.values()):
        raise DataError("units must map t, u, y to unit names (strings)")
    model = ExtendedModel(base, _checked_effects(base, effects), offset)
    return FittedModel(model, input_offset=input_offset, initial_state=method, units=dict(units),
                       fitted=_field(doc, "fitted", dict, optional=True),
                       version=str(doc.get("creep_online_version", "")))


def _field(doc: dict, key: str, kind: type, optional: bool = False):
    if key not in doc:
        if optional:
            return kind()
        raise DataError(f"missing field {key}")
    if not isinstance(doc[key], kind):
        raise DataError(f"field {key} must be a JSON {'object' if kind is dict else kind.__name__}, "
                        f"got {type(doc[key]).__name__}")
    return doc[key]


def _number(doc: dict, key: str, where: str) -> float:
    name = f"{where}.{key}" if where else key
    if key not in doc:
        raise DataError(f"missing field {name}")
    value = doc[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise DataError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _checked_effects(base: CreepModel, effects: dict) -> dict:
    """The effects, each known and accepted by the forward model (a short simulation with each alone)."""
    from ..effects import check_effect_names
    try:
        check_effect_names(effects)
    except ModelError as exc:
        raise DataError(f"effects: {exc}") from None
    from ..effects.forward import simulate_with_effects
    h = 0.05 / base.fn
    t = np.arange(32) * h
    u = np.where(t >= 8 * h, 1.0, 0.0)
    for name, params in effects.items():
        if not isinstance(params, dict):
            raise DataError(f"effects.{name} must be a JSON object of parameters, got {type(params).__name__}")
        expected = _parameter_names(name, base, t, u)
        if expected and not set(params) & expected:
            raise DataError(f"effects.{name}: none of its parameters given (expected {', '.join(sorted(expected))}, "
                            f"got {', '.join(sorted(params)) or 'none'})")
        try:
            y = simulate_with_effects(base, t, u, {name: params})
        except Exception as exc:  # noqa: BLE001 - an effect's own check may raise anything: one line, naming it
            raise DataError(f"effects.{name}: parameters rejected ({type(exc).__name__}: {exc})") from None
        if not np.all(np.isfinite(y)):
            raise DataError(f"effects.{name}: parameters give a non-finite output")
    return {name: dict(params) for name, params in effects.items()}


def read_model_json(path: str | Path) -> FittedModel:
    """A model from a JSON file: a model file, or the ``--json`` output of ``identify`` or ``fit`` (its alpha,
    a1, a2, b, offset, input_offset and effect_params); DataError naming the file and the problem."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        doc = json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: not JSON ({exc})") from None
    if isinstance(doc, dict) and "schema" in doc:
        return load_model(path)
    if not isinstance(doc, dict) or not all(k in doc for k in ("alpha", "a1", "a2", "b")):
        raise DataError(f"{path}: neither a model file nor the --json output of identify or fit "
                        "(no alpha, a1, a2, b)")
    try:
        base = CreepModel(*(_number(doc, k, "") for k in ("alpha", "a1", "a2", "b")))
        offset = _number(doc, "offset", "") if doc.get("offset") is not None else 0.0
        input_offset = _number(doc, "input_offset", "") if doc.get("input_offset") is not None else 0.0
        effects = _checked_effects(base, _field(doc, "effect_params", dict, optional=True))
    except (DataError, ModelError) as exc:
        raise DataError(f"{path}: {str(exc).splitlines()[0]}") from None
    return FittedModel(ExtendedModel(base, effects, offset), input_offset=input_offset,
                       initial_state="reading" if effects else "free_response",
                       fitted={"command": "fit" if "effects" in doc else "identify",
                               "fit_percent": doc.get("fit_percent")})


def _parameter_names(name: str, base: CreepModel, t: np.ndarray, u: np.ndarray) -> set[str]:
    """The parameter names an effect's plausible example has (empty when the effect cannot make one)."""
    from ..effects import get_effect
    from ..effects.forward import simulate_with_effects
    try:
        example = get_effect(name).example_params(base, t, u, simulate_with_effects(base, t, u),
                                                  np.random.default_rng(0))
    except Exception:  # noqa: BLE001 - a plug-in's example may fail on this tiny record: no name check then
        return set()
    return set(example) if isinstance(example, dict) else set()
