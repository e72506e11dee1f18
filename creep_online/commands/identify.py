"""``creep-online identify DATA.csv``: two-layer batch identification of a recorded experiment."""
from __future__ import annotations

import argparse

from ._common import (add_column_options, add_model_output, check_model_output, fraction, nonempty, print_json,
                      save_fitted, seconds, warn_time_unit)
from ._progress import for_command


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("identify", help="identify alpha, a1, a2, b from a t,u,y CSV (two-layer TRF)",
                       description="Two-layer identification (Tashakori et al. 2024): layer 1 finds alpha "
                                   "from the creep regime, layer 2 a1, a2, b from the transient, then an "
                                   "optional joint polish; if the fit misses the noise floor, a multi-start global fit, "
                                   "which also estimates the initial state of a record taken in operation. "
                                   "u is held between samples.")
    p.add_argument("data", type=nonempty, help="CSV file with header t,u,y (uniform sampling), or a PI GCS data-recorder file")
    add_column_options(p)
    p.add_argument("--json", action="store_true", help="print JSON (alpha a1 a2 b fit_percent elapsed_s ...)")
    add_model_output(p)
    p.add_argument("--t-c", type=seconds, default=None, help="end of the transient in s (default: from the data)")
    p.add_argument("--alpha0", type=fraction, default=None, help="starting alpha (default: coarse creep fit)")
    p.add_argument("--layer1-step", type=seconds, default=None, help="coarse step of layer 1 in s")
    p.add_argument("--no-retune", action="store_true", help="skip the eq. 12 retune of alpha")
    p.add_argument("--no-polish", action="store_true", help="skip the joint 4-parameter polish (and the global fit)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..identification import identify        # numpy, scipy and numba: `identify --help` loads none of them
    from ..io.csvfile import load_record

    out_path = check_model_output(args.output, args.data)
    with for_command(args.json) as progress:
        progress.stage(f"identify {args.data}: loading")
        rec = load_record(args.data, args.u_column, args.y_column, t_column=args.t_column, dt=args.dt)
        progress.stage(f"identify {args.data}: {len(rec)} samples, fitting")
        res = identify(rec.t, rec.u, rec.y, t_c=args.t_c, alpha0=args.alpha0, layer1_step=args.layer1_step,
                       retune=not args.no_retune, polish=not args.no_polish, source=rec.source)
    warn_time_unit(rec, res.model)
    saved = save_fitted(res, out_path, rec) if out_path else None
    if args.json:
        out = res.to_dict()
        out["samples"] = len(rec)
        out["file"] = rec.source
        if saved:
            out["model_file"] = str(saved)
        print_json(out)
        return 0
    m, sd = res.model, res.uncertainty
    print(f"{rec.source}: {len(rec)} samples, {rec.duration:.4g} s, h = {rec.h:.4g} s")
    for name in ("alpha", "a1", "a2", "b"):
        err = f"  +/- {sd[name]:.3g}" if name in sd else ""
        print(f"  {name:<6} = {getattr(m, name):.6g}{err}")
    print(f"  fn     = {m.fn:.5g} Hz, zeta = {m.zeta:.4g}, t_c = {res.t_c:.4g} s")
    print(f"  fit    = {res.fit_percent:.2f} % (NRMSE), elapsed {res.elapsed_s * 1e3:.1f} ms")
    for w in res.warnings:
        print(f"  warning: {w}")
    if saved:
        print(f"  model  : {saved}")
    return 0
