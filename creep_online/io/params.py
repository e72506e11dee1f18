"""Model parameters written as text: ``alpha=..,a1=..,a2=..,b=..`` or ``alpha=..,fn=..,zeta=..,b=..``.

One grammar for every place a user types a model: ``creep-online simulate
--params``, ``creep-online demo --params`` and ``python -m hil_sim --params``.
The two forms are the two parameterisations of ``CreepModel`` (``a1``/``a2``
directly, or the resonance ``fn`` in Hz and damping ``zeta`` through
``CreepModel.from_resonance``); they cannot be mixed. ``b`` defaults to 1.
"""
from __future__ import annotations

from typing import Mapping

from ..errors import ModelError
from ..model import CreepModel

COEFFICIENTS = ("a1", "a2")
RESONANCE = ("fn", "zeta")
NAMES = ("alpha", *COEFFICIENTS, *RESONANCE, "b")
GRAMMAR = "alpha=..,a1=..,a2=..,b=.. or alpha=..,fn=..,zeta=..,b=.."


def parse_params(text: str | None, defaults: Mapping[str, float] | None = None,
                 what: str = "--params") -> CreepModel:
    """The model ``text`` describes, with ``defaults`` for what it leaves out; one-line ModelError otherwise.

    ``defaults`` may use either form: a form named in ``text`` replaces the
    other form's defaults (``a1=..,a2=..`` over default ``fn``/``zeta``).
    ``what`` names the setting in messages.
    """
    given = _read(text or "", what)
    values = {k: v for k, v in (defaults or {}).items() if k in NAMES}
    if any(k in given for k in COEFFICIENTS):
        values = {k: v for k, v in values.items() if k not in RESONANCE}
    if any(k in given for k in RESONANCE):
        values = {k: v for k, v in values.items() if k not in COEFFICIENTS}
    values.update(given)
    return _build(values, what)


def _read(text: str, what: str) -> dict[str, float]:
    values: dict[str, float] = {}
    for item in filter(None, (p.strip() for p in text.split(","))):
        key, sep, val = item.partition("=")
        key = key.strip()
        if not sep or key not in NAMES:
            raise ModelError(f"{what}: expected {GRAMMAR}, got {item!r}")
        if key in values:
            raise ModelError(f"{what}: {key} given twice")
        try:
            values[key] = float(val)
        except ValueError:
            raise ModelError(f"{what}: {key} is not a number: {val.strip()!r}") from None
    return values


def _build(values: dict[str, float], what: str) -> CreepModel:
    coefficients = [k for k in COEFFICIENTS if k in values]
    resonance = [k for k in RESONANCE if k in values]
    if coefficients and resonance:
        raise ModelError(f"{what}: give a1 and a2, or fn and zeta, not both")
    needed = ("alpha", *(RESONANCE if resonance else COEFFICIENTS))
    missing = [k for k in needed if k not in values]
    if missing:
        raise ModelError(f"{what}: missing {', '.join(missing)}")
    b = values.get("b", 1.0)
    try:
        if resonance:
            return CreepModel.from_resonance(values["alpha"], values["fn"], values["zeta"], b)
        return CreepModel(values["alpha"], values["a1"], values["a2"], b)
    except ModelError as exc:
        raise ModelError(f"{what}: {str(exc).splitlines()[0]}") from None
