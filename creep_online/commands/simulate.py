"""``creep-online simulate``: output of a given model for the input column of a CSV."""
from __future__ import annotations

import argparse

import numpy as np

from ..errors import CreepOnlineError, DataError
from ..io import save_csv
from ..io.safe_files import check_output
from ..io.csvfile import read_columns
from ..record import Record
from ..simulate import METHODS, simulate
from ._common import nonempty, parse_params, print_json, whole


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate the model for the input of a t,u CSV",
                       description="Writes t,u,y. Methods: 'exact' (default, the most accurate: the "
                                   "closed-form step response superposed at every input change, exact "
                                   "for a zero-order-held input to ~1e-14), 'paper' (eq. 13, the multi-term "
                                   "Grunwald-Letnikov recursion exactly as FOMCON lsim computes it), "
                                   "'split' (exact ZOH fractional integral + exact FOH resonance).")
    p.add_argument("--params", required=True, type=nonempty, help="alpha=..,a1=..,a2=..,b=.. or alpha=..,fn=..,zeta=..,b=.. "
                                                    "(fn in Hz; b defaults to 1)")
    p.add_argument("--input", required=True, type=nonempty, help="CSV with header t,u (uniform sampling)")
    p.add_argument("-o", "--output", required=True, type=nonempty,
                   help="CSV to write (t,u,y; written atomically, never over the input)")
    p.add_argument("--method", choices=METHODS, default="exact", help="simulator (default: exact)")
    p.add_argument("--memory", type=whole(1), default=None, help="truncate the fractional memory to L samples "
                                                             "(paper and split only)")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    model = parse_params(args.params)
    check_output(args.output, inputs=[args.input])
    cols = read_columns(args.input, ("t", "u"))
    rec = Record(cols["t"], cols["u"], cols["t"] * 0.0, source=args.input)
    if len(rec) < 2:
        raise DataError(f"{args.input}: need at least 2 samples")
    try:
        y = simulate(model, rec.t, rec.u, method=args.method, memory=args.memory)
    except ValueError as exc:
        raise CreepOnlineError(f"{args.input}: {exc}") from None
    if not np.all(np.isfinite(y)):
        raise DataError(f"{args.input}: the simulated output is not finite (NaN/inf from sample "
                        f"{int(np.argmin(np.isfinite(y))) + 1}); {model} is numerically out of range "
                        f"for this sampling step; nothing written")
    save_csv(args.output, rec.t, rec.u, y)
    summary = {**model.describe(), "method": args.method, "samples": len(rec), "output": args.output}
    if args.json:
        print_json(summary)
    else:
        print(f"wrote {len(rec)} samples to {args.output} ({args.method}; {model})")
    return 0
