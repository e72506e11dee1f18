"""``creep-online diagnose DATA.csv``: compare, locate, explain -- which effect is the model missing?"""
from __future__ import annotations

import argparse
import sys

from ..effects import effect_names
from ._common import add_column_options, nonempty, print_json, whole
from ._progress import for_command


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("diagnose", help="find which catalogue effect the creep model is missing",
                       description="Fits the base creep model, locates where it fails (time spans, frequency "
                                   "bands, input regimes), fits each catalogue effect as an extension "
                                   f"({', '.join(effect_names())}), ranks them by evidence (BIC drop) and names the "
                                   "missing one, or 'none'. Non-uniform (e.g. log-spaced) time is supported.")
    p.add_argument("data", type=nonempty, help="CSV file with header t,u,y, or a PI GCS data-recorder file")
    add_column_options(p)
    p.add_argument("--json", action="store_true",
                   help="print JSON (fit_percent residual_rms noise_rms verdict missing_effects ...)")
    p.add_argument("--report", metavar="DIR", default=None, type=nonempty,
                   help="write an HTML report with PNG plots into DIR (needs matplotlib; built beside DIR "
                        "and swapped in whole; an existing DIR may hold only an earlier report)")
    p.add_argument("--effects", default=None, type=nonempty,
                   help="comma-separated candidates to try (default: the whole catalogue)")
    p.add_argument("--workers", type=whole(1, 1024), default=None, metavar="N",
                   help="threads for the candidate fits (default: the available cores, or "
                        "$CREEP_ONLINE_DIAGNOSE_WORKERS; 1 = one after the other); the result does not depend on it")
    p.set_defaults(func=run)


#: glibc's ``mallopt`` parameter M_ARENA_MAX (``<malloc.h>``): how many malloc arenas the threads may have.
M_ARENA_MAX = -8


def share_malloc_arena() -> None:
    """Let the candidate fits' threads share glibc's malloc arenas instead of one each (this process only).

    A thread's own arena keeps the arrays it freed (a long record's rows, responses and spectra, 0.4-10 MB
    each) for itself, so two fitting threads hold two heaps of free blocks: the 150 V piezo record's diagnosis
    peaked at 427 MB with an arena per thread and 388 MB with one (``MALLOC_ARENA_MAX=1``, two workers,
    the same code and load). Set before the threads start; nothing where the C library is not glibc.
    """
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    try:
        libc = ctypes.CDLL(None)
        if hasattr(libc, "gnu_get_libc_version"):
            libc.mallopt(M_ARENA_MAX, 1)
    except (OSError, AttributeError):
        return


def run(args: argparse.Namespace) -> int:
    share_malloc_arena()
    from ..diagnostics import diagnose               # scipy and numba: `diagnose --help` loads neither
    from ..diagnostics.extended import check_effects
    from ..diagnostics.loading import load_for_diagnosis
    candidates = check_effects(args.effects) if args.effects else effect_names()
    if args.report is not None:
        from ..io.safe_files import check_report_dir
        check_report_dir(args.report)   # before the work, not after it
    with for_command(args.json) as progress:
        progress.stage(f"diagnose {args.data}: loading")
        inp = load_for_diagnosis(args.data, args.u_column, args.y_column, args.t_column, dt=args.dt)
        result = diagnose(inp.record, candidates=candidates, u_pre=inp.u_pre, t_pre=inp.t_pre, workers=args.workers,
                          progress=lambda stage: progress.stage(f"diagnose {args.data}: {stage}"))
    result.warnings[:0] = inp.notes
    report_path = None
    if args.report:
        from ..reports.diagnose_report import write_report
        report_path = write_report(result, args.report)
    if args.json:
        out = result.to_dict()
        out["samples"] = len(inp.record)
        if report_path:
            out["report"] = str(report_path)
        print_json(out)
        return 0
    print(format_table(result))
    if report_path:
        print(f"report: {report_path}")
    return 0


def format_table(result) -> str:
    """The before-and-after table the terminal shows."""
    b = result.base
    lines = [f"{result.source}: {result.data.n} samples; base model {b.model}",
             f"base fit {b.fit_percent:.2f} %, residual RMS {b.residual_rms:.4g}, "
             f"noise floor ~{result.noise_rms:.4g} ({b.residual_rms / result.noise_rms:.2f}x)"
             if result.noise_rms > 0 else f"base fit {b.fit_percent:.2f} %, residual RMS {b.residual_rms:.4g}",
             ""]
    for f in result.location.get("findings", []):
        lines.append(f"  where: {f}")
    lines.append("")
    head = f"  {'rank':<4} {'effect':<22} {'evidence':>10} {'fit% before':>11} {'fit% after':>10} " \
           f"{'RMS before':>11} {'RMS after':>11}  signature"
    lines += [head, "  " + "-" * (len(head) + 20)]
    for i, c in enumerate(result.candidates, 1):
        mark = "*" if c.significant else " "
        lines.append(f"  {i:<4} {c.effect:<21}{mark} {c.evidence:>10.4g} {b.fit_percent:>11.2f} "
                     f"{c.fit.fit_percent:>10.2f} {b.residual_rms:>11.4g} {c.fit.residual_rms:>11.4g}  "
                     + (f"not significant: {c.contradiction}" if c.contradiction else c.signature))
    for name, why in result.skipped.items():
        lines.append(f"  -    {name:<22} {'skipped':>10}  ({why})")
    if result.combination is not None:
        c = result.combination
        lines.append(f"  pair {c.effect:<22} {c.evidence:>10.4g} {b.fit_percent:>11.2f} {c.fit.fit_percent:>10.2f} "
                     f"{b.residual_rms:>11.4g} {c.fit.residual_rms:>11.4g}  {c.signature}")
    lines.append("")
    lines.append(f"verdict: {result.verdict}" + ("" if result.verdict == "none" else
                 "  (* = significant: BIC drop > 10 and RMS drop > 2 %)"))
    lines.append(f"decided by: {result.verdict_basis['text']}")
    ph = result.physics
    if ph.get("evidence"):
        ev = ", ".join(f"{k} {v:.4g}" for k, v in ph["evidence"].items())
        lines.append(f"hold physics: {ph['verdict']} ({ph['holds']} holds, {ph['hold_seconds']:.3g} s settled; "
                     f"BIC drop over one creep law: {ev}): {ph['reason']}")
    elif ph:
        lines.append(f"hold physics: {ph.get('verdict')} ({ph.get('reason')})")
    for w in result.warnings:
        lines.append(f"note: {w}")
    return "\n".join(lines)
