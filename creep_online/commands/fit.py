"""``creep-online fit DATA.csv --effects NAME[,NAME]``: fit the creep model extended by catalogue effects."""
from __future__ import annotations

import argparse
import math

from ..effects import effect_names
from ._common import (add_column_options, add_model_output, check_model_output, nonempty, print_json, save_fitted,
                      seconds, warn_time_unit)
from ._progress import for_command


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="fit the creep model extended by catalogue effects",
                       description="Fits b / (s^alpha (1 + a1 s + a2 s^2)) plus the named effects "
                                   f"({', '.join(effect_names())}; one or several) and prints the parameters and "
                                   "the fit before and after.")
    p.add_argument("data", type=nonempty, help="CSV file with header t,u,y, or a PI GCS data-recorder file")
    add_column_options(p)
    p.add_argument("--effects", required=True, type=nonempty, help="comma-separated catalogue names, e.g. delay,drift")
    p.add_argument("--json", action="store_true", help="print JSON")
    add_model_output(p)
    p.add_argument("--online", action="store_true",
                   help="also stream the record through the online estimator, plain and with the fitted effects "
                        "compensated sample by sample, each given its batch fit's alpha as a hint, and show "
                        "the live prediction error of both (uniform time)")
    p.add_argument("--window", type=seconds, default=1.0, help="window of the live error display in s (default 1)")
    p.set_defaults(func=run)


#: Most catalogue effects fitted jointly: the joint fit's cost grows steeply with their number (on a 4000-sample
#: record four took 5 s, six 56 s, eight did not end in 900 s) while one record rarely determines more.
MAX_JOINT_EFFECTS = 4


def run(args: argparse.Namespace) -> int:
    from ..diagnostics.extended import check_effects, fit_extended   # scipy and numba: not for `fit --help`
    from ..diagnostics.loading import load_for_diagnosis
    from ..diagnostics.start import fit_base_by_rule
    from ..metrics import noise_std_estimate

    effects = check_effects(args.effects)
    if len(effects) > MAX_JOINT_EFFECTS:
        from ..errors import DataError
        raise DataError(f"{len(effects)} effects fitted jointly is more than one record determines in bounded time "
                        f"(at most {MAX_JOINT_EFFECTS}); 'creep-online diagnose' ranks them, then fit the best few")
    out_path = check_model_output(args.output, args.data)
    with for_command(args.json) as progress:
        progress.stage(f"fit {args.data}: loading")
        inp = load_for_diagnosis(args.data, args.u_column, args.y_column, args.t_column, dt=args.dt)
        rec = inp.record
        notes: list[str] = []
        data, base = fit_base_by_rule(rec.t, rec.u, rec.y, source=rec.source, u_pre=inp.u_pre, t_pre=inp.t_pre,
                                      warnings=notes, report=lambda stage: progress.stage(f"fit {args.data}: {stage}"))
        progress.stage(f"fit {args.data}: base model + {', '.join(effects)}")
        fit = fit_extended(data, effects, base)
    warn_time_unit(rec, fit.model)
    saved = save_fitted(fit, out_path, rec) if out_path else None
    noise = noise_std_estimate(fit.residual)
    out = {**fit.to_dict(), "fit_percent_before": base.fit_percent, "residual_rms_before": base.residual_rms,
           "noise_rms": noise, "samples": data.n, "file": rec.source,
           "notes": inp.notes + notes + fit.poorly_determined()}
    live = None
    if args.online:
        from ..diagnostics.online import live_error
        from ..errors import DataError
        if not data.uniform:
            raise DataError(f"{rec.source}: --online needs uniformly sampled time")
        with for_command(args.json) as progress:
            progress.stage(f"fit {args.data}: streaming through the online estimator")
            live = live_error(data.t - data.t[0], data.u, data.y, fit.effect_params, window_s=args.window,
                              base_model=base.model, extended_model=fit.model)
        out["online_live_error"] = live
    if saved:
        out["model_file"] = str(saved)
    if args.json:
        print_json(out)
        return 0
    m = fit.model
    print(f"{rec.source}: {data.n} samples; effects: {', '.join(effects)}")
    print(f"  alpha = {m.alpha:.6g}, a1 = {m.a1:.6g}, a2 = {m.a2:.6g}, b = {m.b:.6g} "
          f"(fn {m.fn:.5g} Hz, zeta {m.zeta:.4g}), offset {fit.offset:.6g}")
    if fit.uncertainty:
        print("  1-sigma " + ", ".join(f"{k} {_relative(sd, getattr(m, k))}" for k, sd in fit.uncertainty.items()))
    for name, params in fit.effect_params.items():
        shown = ", ".join(f"{k} = {_fmt(v)}" for k, v in params.items() if k not in ("r", "w"))
        print(f"  {name}: {shown}")
    print(f"  fit    {base.fit_percent:.2f} % -> {fit.fit_percent:.2f} %")
    print(f"  RMS    {base.residual_rms:.4g} -> {fit.residual_rms:.4g} (noise floor ~{noise:.4g})")
    for n in out["notes"]:
        print(f"  note: {n}")
    if saved:
        print(f"  model: {saved}")
    if live is not None:
        from ..diagnostics.online import format_live_error
        print("  live prediction error of the online estimator (RMS per window):")
        print(format_live_error(live, noise if noise > 0 else None))
    return 0


def _relative(sd: float, value: float) -> str:
    """A 1-sigma as a share of its value: ``0.12 %``, or ``not determined`` where it is unbounded."""
    return f"{100 * sd / abs(value):.3g} %" if math.isfinite(sd) and value else "not determined"


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.5g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)
