"""``creep-online simulate``: output of a given model for the input column of a CSV."""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..errors import CreepOnlineError, DataError
from ..io.csvfile import in_seconds, read_table
from ..io.signal_file import check_signal_output, save_signals
from ..record import Record
from ..simulate import METHODS, simulate
from ._common import parse_params, print_json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate the model for the input of a t,u CSV",
                       description="Writes t,u,y. Methods: 'exact' (default, the most accurate: the "
                                   "closed-form step response superposed at every input change, exact "
                                   "for a zero-order-held input to ~1e-14), 'paper' (eq. 13, the multi-term "
                                   "Grunwald-Letnikov recursion exactly as FOMCON lsim computes it), "
                                   "'split' (exact ZOH fractional integral + exact FOH resonance). A model "
                                   "file (--model) is simulated with its effects, offset and input offset "
                                   "(exact method).")
    given = p.add_mutually_exclusive_group(required=True)
    given.add_argument("--params", help="alpha=..,a1=..,a2=..,b=.. or alpha=..,fn=..,zeta=..,b=.. (fn in Hz; b "
                                        "defaults to 1), or a JSON file: the --json output of identify or fit "
                                        "(its offsets and effects included) or a model file")
    given.add_argument("--model", metavar="MODEL.json",
                       help="a model file written by 'identify -o' or 'fit -o' (effects and offsets included)")
    p.add_argument("--input", required=True, help="CSV with header t,u (uniform sampling for --params)")
    p.add_argument("-o", "--output", required=True,
                   help="file to write (t,u,y): .csv (or no suffix), .tsv, or .parquet (pyarrow); written "
                        "atomically, never over the input")
    p.add_argument("--method", choices=METHODS, default="exact", help="simulator (default: exact)")
    p.add_argument("--memory", type=int, default=None, help="truncate the fractional memory to L samples "
                                                             "(paper and split only)")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=run)


def _model(args: argparse.Namespace):
    """The FittedModel of --model or of a --params JSON file, or the CreepModel of --params text."""
    from ..io.model_file import load_model, read_model_json
    if args.model is not None:
        return load_model(args.model)
    text = args.params.strip()
    if text.lower().endswith(".json") or Path(text).is_file():
        return read_model_json(text)
    return parse_params(text)


def run(args: argparse.Namespace) -> int:
    model = _model(args)
    out = check_signal_output(args.output, inputs=[args.input])
    cols, units = read_table(args.input, ("t", "u"))
    t, _ = in_seconds(args.input, cols["t"], units["t"])
    rec = Record(t, cols["u"], t * 0.0, source=args.input)
    if len(rec) < 2:
        raise DataError(f"{args.input}: need at least 2 samples")
    fitted = not hasattr(model, "alpha")
    if fitted and (args.method != "exact" or args.memory is not None):
        raise DataError("a model file or a fit's JSON is simulated exactly (with its effects): drop --method/--memory")
    try:
        y = model.simulate(rec.t, rec.u) if fitted else simulate(model, rec.t, rec.u, method=args.method,
                                                                memory=args.memory)
    except ValueError as exc:
        raise CreepOnlineError(f"{args.input}: {exc}") from None
    base = model.base if fitted else model
    if not np.all(np.isfinite(y)):
        raise DataError(f"{args.input}: the simulated output is not finite (NaN/inf from sample "
                        f"{int(np.argmin(np.isfinite(y))) + 1}); {base} is numerically out of range "
                        f"for this sampling step; nothing written")
    save_signals(out, {"t": rec.t, "u": rec.u, "y": y})
    summary = {**base.describe(), "method": args.method, "samples": len(rec), "output": str(out)}
    if fitted:
        summary.update(effects=model.effects, offset=model.offset, input_offset=model.input_offset)
    if args.json:
        print_json(summary)
    else:
        extra = f"; effects {', '.join(model.effects)}" if fitted and model.effects else ""
        print(f"wrote {len(rec)} samples to {out} ({args.method}; {base}{extra})")
    return 0
