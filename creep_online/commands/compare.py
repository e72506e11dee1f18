"""``creep-online compare MODEL.json DATA``: a saved model's fit percent and residual on a record (MATLAB's compare)."""
from __future__ import annotations

import argparse

from ..diagnostics.compare import INITIAL_CHOICES
from ._common import add_column_options, nonempty, print_json
from ._progress import for_command


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="fit percent and residual of a saved model on a record",
                       description="Simulates a model file (from 'identify -o' or 'fit -o') for the record's input "
                                   "and prints how much of the measured output it explains: the fit percent "
                                   "(NRMSE, as identify and fit print it) and a residual summary. The output offset "
                                   "and the initial state are estimated for the record the way the model's own fit "
                                   "estimated them, so on the record it was fitted on compare gives the fit's own "
                                   "fit percent again.")
    p.add_argument("model", type=nonempty, help="model file (JSON) written by 'identify -o' or 'fit -o'")
    p.add_argument("data", type=nonempty, help="CSV file with header t,u,y, or a PI GCS data-recorder file")
    add_column_options(p)
    p.add_argument("--initial", choices=INITIAL_CHOICES, default="estimate",
                   help="estimate (default): the offset and the initial state estimated for this record; "
                        "zero: the plant at rest at the model's input offset, only the offset estimated")
    p.add_argument("--json", action="store_true", help="print JSON (fit_percent residual offset initial model ...)")
    p.add_argument("--report", metavar="DIR", default=None, type=nonempty,
                   help="write report.html with compare.png (model against measurement, and the residual) into "
                        "DIR (needs matplotlib; built beside DIR and swapped in whole; an existing DIR may hold "
                        "only an earlier report)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..diagnostics.compare import compare
    from ..diagnostics.loading import load_for_diagnosis
    from ..io.model_file import load_model
    if args.report is not None:
        from ..io.safe_files import check_report_dir
        check_report_dir(args.report)   # before the work, not after it
    model = load_model(args.model)
    with for_command(args.json) as progress:
        progress.stage(f"compare {args.data}: loading")
        inp = load_for_diagnosis(args.data, args.u_column, args.y_column, args.t_column, dt=args.dt)
        progress.stage(f"compare {args.data}: {len(inp.record)} samples, simulating")
        result = compare(model, inp.record, initial=args.initial, u_pre=inp.u_pre, t_pre=inp.t_pre)
    out = {**result.to_dict(), "model_file": args.model, "notes": inp.notes}
    if args.report:
        from ..reports.compare_report import write_report
        out["report"] = str(write_report(result, args.report, model_file=args.model))
    if args.json:
        print_json(out)
        return 0
    print(format_summary(result, args.model))
    for note in inp.notes:
        print(f"  note: {note}")
    if args.report:
        print(f"report: {out['report']}")
    return 0


def format_summary(result, model_file: str) -> str:
    """The terminal's lines: model, record, fit percent, residual, what was estimated."""
    m, r, init = result.model, result.metrics, result.initial
    fitted = m.fitted.get("fit_percent")
    effects = ", ".join(m.effects) or "none"
    units = m.units.get("y", "")
    offset_source = "estimated for this record" if init["offset_estimated"] else "the model's own"
    lines = [f"{model_file}: {m.base}; effects: {effects}",
             f"{result.source}: {result.y.size} samples",
             f"  fit      = {result.fit_percent:.2f} % (NRMSE)"
             + (f"; {fitted:.2f} % on the record it was fitted on" if fitted is not None else ""),
             f"  residual : rms {r['residual_rms']:.4g}{(' ' + units) if units else ''}, max |e| "
             f"{r['residual_max_abs']:.4g}, mean {r['residual_mean']:.3g}; " + _noise_words(r),
             f"  worst    : {r['worst_window']['t_start']:.4g}-{r['worst_window']['t_end']:.4g} s "
             f"(rms {r['worst_window']['rms']:.4g})",
             f"  estimated: offset {result.offset:.6g} ({offset_source}), "
             f"start {_start_words(init)}"]
    return "\n".join(lines)


def _noise_words(r: dict) -> str:
    """The residual against the noise: its ratio and whether it is white, or that the record is noise-free."""
    if not r["noise_rms"] > 0:
        return "noise-free record (the residual has no white noise to compare with)"
    return (f"noise ~{r['noise_rms']:.3g} ({r['residual_over_noise']:.2f}x)"
            + ("; white (at the noise floor)" if r["white"] else "; not white: the model misses something"))


def _start_words(init: dict) -> str:
    if init["free_response_terms"]:
        return f"in operation (initial state: {init['free_response_terms']} free-response terms)"
    if init["reading"] == "equilibrium":
        return "in equilibrium at the first input"
    return f"from rest at input {init['input_before']:g}"
