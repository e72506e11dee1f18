"""Helpers shared by the sub-commands: JSON output, parameter parsing, column flags, model files, and the
flag types that check values.

Every flag that takes a number or a name is parsed by one of the types below
(``type=seconds`` ...): NaN, inf, a negative or zero value where a positive one
is meant, 1e300 where the quantity has a physical range, an empty name, are
refused by argparse with one line and exit 2 before any work (``cli.OneLineParser``).
"""
from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path
from typing import Any, Callable, Mapping


__all__ = ["print_json", "parse_params", "add_column_options", "moves_text", "research_lines", "add_model_output",
           "check_model_output", "save_fitted", "warn_time_unit", "seconds", "positive_number", "finite_number",
           "fraction", "whole", "nonempty"]

#: A record whose header names no time unit, sampled at this step (s) or slower, ...
MS_STEP_S = 0.01
#: ... with a resonance identified below this frequency (Hz) looks like time written in milliseconds: a
#: piezo actuator's or sensor's first resonance lies above it, and such records are sampled 1000x faster.
MS_RESONANCE_HZ = 5.0

#: The longest time any flag may give (s): ~30 years; beyond it a value is a unit mistake, not a setting.
MAX_SECONDS = 1e9
#: The largest frequency (Hz) or rate any flag may give.
MAX_HZ = 1e9


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text[:40]!r}") from None


def seconds(text: str) -> float:
    """A time in s: finite, > 0, at most MAX_SECONDS."""
    value = _number(text)
    if not (math.isfinite(value) and 0 < value <= MAX_SECONDS):
        raise argparse.ArgumentTypeError(f"must be a time in seconds, > 0 and at most {MAX_SECONDS:g}, "
                                         f"got {text[:40]!r}")
    return value


def positive_number(maximum: float = math.inf, what: str = "number") -> Callable[[str], float]:
    """A flag type: a finite number > 0 (and <= ``maximum``)."""
    def convert(text: str) -> float:
        value = _number(text)
        if not (math.isfinite(value) and 0 < value <= maximum):
            limit = f" and at most {maximum:g}" if math.isfinite(maximum) else ""
            raise argparse.ArgumentTypeError(f"must be a positive finite {what}{limit}, got {text[:40]!r}")
        return value
    convert.__name__ = what
    return convert


def finite_number(text: str) -> float:
    """Any finite number (a level, an amplitude)."""
    value = _number(text)
    if not (math.isfinite(value) and abs(value) <= 1e100):
        raise argparse.ArgumentTypeError(f"must be a finite number (|x| <= 1e100), got {text[:40]!r}")
    return value


def fraction(text: str) -> float:
    """A number strictly between 0 and 1 (alpha)."""
    value = _number(text)
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"must lie strictly between 0 and 1, got {text[:40]!r}")
    return value


def whole(minimum: int = 1, maximum: int = 1 << 31) -> Callable[[str], int]:
    """A flag type: a whole number in ``minimum..maximum``."""
    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text[:40]!r}") from None
        if not minimum <= value <= maximum:
            raise argparse.ArgumentTypeError(f"must be a whole number from {minimum} to {maximum}, got {text[:40]!r}")
        return value
    convert.__name__ = "whole number"
    return convert


def nonempty(text: str) -> str:
    """A name or a list that must not be empty."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must not be empty")
    return text


def add_column_options(parser, time: bool = True) -> None:
    """``--t-column`` / ``--u-column`` / ``--y-column``: the same flags in every command that reads a record file
    (``time`` False: no --t-column, for a source whose time is not a column)."""
    if time:
        parser.add_argument("--t-column", default=None, metavar="NAME", type=nonempty,
                            help="time column: a CSV header name (default t or time; a unit in the header such as "
                                 "'t [ms]' converts it to seconds)")
    parser.add_argument("--u-column", default=None, metavar="NAME", type=nonempty,
                        help="input column: a CSV header name (default u) or, in a PI GCS data-recorder file, "
                             "a NAMEi text or NAMEi itself (default NAME0 of two channels; of more, the one "
                             "named as a voltage or command)")
    parser.add_argument("--y-column", default=None, metavar="NAME", type=nonempty,
                        help="output column: a CSV header name (default y) or a GCS NAMEi (default NAME1 of two "
                             "channels; of more, the one named as a current position or sensor)")
    if time:
        parser.add_argument("--dt", type=seconds, default=None, metavar="SECONDS",
                            help="sample time of a PI GCS file that has no SAMPLE_TIME line (for a CSV it must "
                                 "agree with the time column)")


def print_json(obj: Any) -> None:
    """Write one JSON document to stdout (non-finite numbers as null: ``creep_online.io.jsonable``)."""
    from ..io.jsonable import json_text   # numpy: imported when a command runs, not for its --help
    sys.stdout.write(json_text(obj))
    sys.stdout.write("\n")


def parse_params(text: str | None, defaults: Mapping[str, float] | None = None, what: str = "--params"):
    """``creep_online.io.params.parse_params`` (which loads the model and numpy when it is first called)."""
    from ..io.params import parse_params as parse
    return parse(text, defaults, what)


def moves_text(relative_change: dict) -> str:
    """``a1 -12.0 %, a2 +25.0 %``: the relative moves of a change event or a re-search."""
    return ", ".join(f"{k} {100 * v:+.1f} %" for k, v in relative_change.items())


def fault_line(event: dict) -> str:
    """An internal-fault event (``kind`` "internal_fault") on one line: when, what, where, how it was recovered."""
    return (f"internal fault at t = {event['t']:.4g} s: {event['error']} in {event['where']} ({event['message']}); "
            f"{event['recovery']}")


def event_line(event: dict) -> str:
    """A change event (or an internal fault, ``fault_line``) on one line: when it began and was detected, what
    moved and by how much, and whether the estimate it was judged against had settled (``stream``, ``demo``)."""
    if event.get("kind") == "internal_fault":
        return fault_line(event)
    moves = moves_text(event["relative_change"])
    found = "; found by re-searching a sudden misfit" if event.get("found_by") == "re-search" else ""
    return (f"change near t = {event['t']:.4g} s (detected {event['detected_t']:.4g} s): "
            f"{', '.join(event['moved']) or 'nothing significant'} moved ({moves}){found}{unsettled_note(event)}")


def unsettled_note(event: dict) -> str:
    """What a change event judged against a still-moving estimate says (``estimate_settled`` False): it may
    correct the estimate (a start-up estimate converging) rather than report a change of the plant."""
    if event.get("estimate_settled") is False:
        return "; the estimate had not settled before it: may correct the estimate, not the plant"
    return ""


def research_lines(researches: list[dict]) -> list[str]:
    """One line per re-search of the resonance that replaced the estimate, and one for those that kept it.

    A re-search runs when the window's error stays above the noise floor (or a
    fit breaks): the user sees when the estimator left a wrong resonance, why,
    and what moved (``OnlineEstimate.researches``).
    """
    lines = []
    for rs in researches:
        if rs["switched"]:
            lines.append(f"resonance re-searched at t = {rs['t']:.4g} s ({rs['reason']}): "
                         f"{', '.join(rs['moved'])} moved ({moves_text(rs['relative_change'])}; "
                         f"likelihood ratio {rs['lr']:.3g})")
    kept = [rs for rs in researches if not rs["switched"]]
    if kept:
        lines.append(f"{len(kept)} re-search(es) of the resonance kept the estimate (the data could not do better; "
                     f"last at t = {kept[-1]['t']:.4g} s: {kept[-1]['reason']})")
    return lines


def add_model_output(parser) -> None:
    """``-o/--output MODEL.json``: save the fitted model as a model file (``creep_online.io.model_file``)."""
    parser.add_argument("-o", "--output", default=None, metavar="MODEL.json", type=nonempty,
                        help="save the model (parameters, effects, offsets, units) as a JSON model file, for "
                             "'creep-online compare' and 'simulate --model' (written atomically, never over the data)")


def check_model_output(path: str | None, data: str) -> Path | None:
    """The model file to write (checked before the work: suffix .json, writable, not the data), or None."""
    if path is None:
        return None
    from ..errors import OutputError
    from ..io.model_file import SUFFIX
    from ..io.safe_files import check_output
    out = Path(path)
    if out.suffix.lower() != SUFFIX:
        raise OutputError(f"{out}: a model file is JSON: give a name ending in {SUFFIX}")
    return check_output(out, inputs=[data])


def save_fitted(result, path: Path, rec) -> Path:
    """Save a fit's result as a model file with the record's units and name."""
    from ..io.model_file import save_model
    return save_model(result, path, units=getattr(rec, "units", {}), inputs=[rec.source], file=rec.source,
                      samples=len(rec))


def warn_time_unit(rec, model) -> None:
    """Warn (DataWarning) when a record's time looks like milliseconds: no unit in its header, a step of at
    least ``MS_STEP_S`` and a resonance identified below ``MS_RESONANCE_HZ``."""
    from ..errors import DataWarning
    if "t" in getattr(rec, "units", {}) or len(rec) < 2 or rec.h < MS_STEP_S or model.fn >= MS_RESONANCE_HZ:
        return
    warnings.warn(f"{rec.source}: time step {rec.h:.4g} s and a resonance at {model.fn:.3g} Hz: if the time column "
                  f"is in milliseconds, the record is sampled at {1e3 / rec.h:.4g} Hz and the resonance is at "
                  f"{1e3 * model.fn:.4g} Hz; convert t to seconds or name its unit in the header ('t [ms]')",
                  DataWarning, stacklevel=2)
