"""Helpers shared by the sub-commands: JSON output, parameter parsing, column flags, model files."""
from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any

from ..io.jsonable import json_text
from ..io.params import parse_params

__all__ = ["print_json", "parse_params", "add_column_options", "moves_text", "research_lines", "add_model_output",
           "check_model_output", "save_fitted", "warn_time_unit"]

#: A record whose header names no time unit, sampled at this step (s) or slower, ...
MS_STEP_S = 0.01
#: ... with a resonance identified below this frequency (Hz) looks like time written in milliseconds: a
#: piezo actuator's or sensor's first resonance lies above it, and such records are sampled 1000x faster.
MS_RESONANCE_HZ = 5.0


def add_column_options(parser, time: bool = True) -> None:
    """``--t-column`` / ``--u-column`` / ``--y-column``: the same flags in every command that reads a record file
    (``time`` False: no --t-column, for a source whose time is not a column)."""
    if time:
        parser.add_argument("--t-column", default=None, metavar="NAME",
                            help="time column: a CSV header name (default t or time; a unit in the header such as "
                                 "'t [ms]' converts it to seconds)")
    parser.add_argument("--u-column", default=None, metavar="NAME",
                        help="input column: a CSV header name (default u) or, in a PI GCS data-recorder file, "
                             "a NAMEi text or NAMEi itself (default NAME0 of two channels; of more, the one "
                             "named as a voltage or command)")
    parser.add_argument("--y-column", default=None, metavar="NAME",
                        help="output column: a CSV header name (default y) or a GCS NAMEi (default NAME1 of two "
                             "channels; of more, the one named as a current position or sensor)")
    if time:
        parser.add_argument("--dt", type=float, default=None, metavar="SECONDS",
                            help="sample time of a PI GCS file that has no SAMPLE_TIME line (for a CSV it must "
                                 "agree with the time column)")


def print_json(obj: Any) -> None:
    """Write one JSON document to stdout (non-finite numbers as null: ``creep_online.io.jsonable``)."""
    sys.stdout.write(json_text(obj))
    sys.stdout.write("\n")


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
    parser.add_argument("-o", "--output", default=None, metavar="MODEL.json",
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
