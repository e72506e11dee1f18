"""``creep-online batch DIR|GLOB|LONG.csv``: identify (and diagnose) a fleet of records on Dask.

One row per record to ``--out`` (CSV or Parquet), an HTML summary, ``--json``
for machines. A bad record is a row with its error, never the end of the
batch; Ctrl-C, SIGTERM or SIGHUP keeps the rows done. Exit codes: 0 every
record identified, 1 the batch ran but some records failed (their rows say
why), 2 bad arguments or input, 128 + N stopped by signal N (130 Ctrl-C,
143 SIGTERM, 129 SIGHUP; the rows done are written).
"""
from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path
from typing import Any, Callable

from .._signals import STOP_SIGNALS, exit_code
from .. import _signals
from ..errors import CreepOnlineError
from ._progress import for_command
from ._common import nonempty, print_json, whole

SUMMARY = "identify a fleet of records (folder, glob or long id,t,u,y CSV) on Dask"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("batch", help=SUMMARY,
                       description="Runs identify (and with --diagnose also diagnose) on every record of a fleet "
                                   "over dask.distributed: a local cluster of one single-threaded worker process "
                                   "per core by default, or an existing cluster (--scheduler). One row per "
                                   "record (parameters, uncertainties, fit, warnings, verdict, error, time); "
                                   "outliers are flagged by a robust z-score (median/MAD of log10|x| > 3.5). "
                                   "Needs the fleet extra: pip install 'creep_online[fleet]'.")
    p.add_argument("records", metavar="DIR|GLOB|LONG.csv", type=nonempty,
                   help="a folder of t,u,y CSV files, a glob of them (quote it), or one CSV with columns "
                        "id,t,u,y (one record per id)")
    p.add_argument("--out", metavar="TABLE", default=None, type=nonempty,
                   help="write the table here (.csv, or .parquet with pyarrow)")
    p.add_argument("--html", metavar="FILE", default=None, type=nonempty,
                   help="write the HTML summary here (default: beside --out, same name with .html)")
    p.add_argument("--json", action="store_true",
                   help="print the machine summary as JSON (counts, distributions, outliers, failures, rows)")
    p.add_argument("--diagnose", action="store_true", help="also diagnose every record (the verdict column)")
    p.add_argument("--workers", type=whole(1, 1024), default=None,
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None, type=nonempty,
                   help="use an existing Dask scheduler (e.g. tcp://host:8786); its workers need creep_online "
                        "and must see the record files")
    p.add_argument("--send-records", action="store_true",
                   help="read each record file here and send its samples with its task (workers that cannot see "
                        "the files: no shared file system); by default the workers read them by absolute path")
    p.add_argument("--no-retune", action="store_true", help="as identify: skip the eq. 12 retune of alpha")
    p.add_argument("--no-polish", action="store_true", help="as identify: skip the joint polish (and the global fit)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..fleet.runner import distributed
    from ..fleet.table import check_table_path
    from ..io.fleet_records import find_records
    from ..io.safe_files import check_default_output, check_output
    if args.scheduler and args.workers is not None:
        raise CreepOnlineError("--workers sizes the local cluster; with --scheduler the cluster has its own workers")
    outputs = _outputs(args)
    if args.out:
        check_table_path(args.out)   # suffix and pyarrow, before any work
    distributed()                    # the one-line hint before any work when Dask is missing
    if outputs[1] is not None:
        from ..reports.fleet_report import pyplot
        pyplot()                     # the summary page's plots: matplotlib, before any work
    jobs = [j for j in find_records(args.records) if not _is_batch_table(j.path)]
    if not jobs:
        raise CreepOnlineError(f"{args.records}: holds only batch tables, no records")
    inputs = [j.path for j in jobs if j.path] + ([args.records] if Path(args.records).is_file() else [])
    table, page = outputs
    if table is not None:
        check_output(table, inputs)   # never over a record
        sidecar = _sidecar(table)     # (its name is the tool's choice: never over a file of the user's)
        if sidecar is not None:
            check_default_output(sidecar, inputs, flag="--out")
    if page is not None:              # the page's default name: never over a file of the user's
        (check_output if args.html else check_default_output)(page, inputs, **({} if args.html else
                                                                               {"flag": "--html"}))
    with _signals.flagged() as pressed:   # (held while the rows are written too: a signal then waits for them)
        rows, times, interrupted = _run(args, jobs, pressed)
        return _finish(args, jobs, rows, times, interrupted, outputs)


def _is_batch_table(path: str | None) -> bool:
    """True for a table an earlier batch wrote (its header is the table's columns): not a record.

    So ``--out records/fleet.csv`` can be run again over ``records/``.
    """
    from ..fleet import COLUMNS
    if path is None:
        return False
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            return fh.readline(4096).strip() == ",".join(COLUMNS)
    except OSError:
        return False


def _outputs(args: argparse.Namespace) -> tuple[Path | None, Path | None]:
    """(table, html) paths; the HTML defaults to the table's name with .html."""
    html = args.html or (str(Path(args.out).with_suffix(".html")) if args.out else None)
    return (Path(args.out) if args.out else None, Path(html) if html else None)


def _sidecar(table: Path | None) -> Path | None:
    """The metadata sidecar a CSV table gets (none for Parquet: its metadata is inside)."""
    from ..fleet.table import sidecar_path
    return sidecar_path(table) if table is not None and table.suffix.lower() == ".csv" else None


def table_options(args: argparse.Namespace) -> dict[str, Any]:
    """The batch's settings as the table's metadata records them."""
    return {"records": args.records, "diagnose": args.diagnose, "retune": not args.no_retune,
            "polish": not args.no_polish, "scheduler": args.scheduler, "workers": args.workers,
            "send_records": args.send_records}


def _run(args: argparse.Namespace, jobs: list,
         pressed: Callable[[], int | None]) -> tuple[list[dict[str, Any]], dict[str, float], int | None]:
    """The rows (input order), the times (startup_s: cluster up and workers warm; elapsed_s: the records)
    and the stop signal that ended the batch early, if any (``pressed``: ``_signals.flagged``'s flag).

    The first Ctrl-C, SIGTERM or SIGHUP only sets the flag, which the batch asks between records: a
    KeyboardInterrupt raised wherever the main thread happens to be could land inside Dask's client code
    (a submit, a future's release) and leave its event loop a half-done call, whose traceback Dask's loop
    thread then printed. A second signal raises as usual."""
    from ..fleet.runner import dask_client, run_on_dask
    options = {"retune": not args.no_retune, "polish": not args.no_polish}
    rows: list[dict[str, Any]] = []
    start = t0 = time.perf_counter()
    signum = pressed()
    with for_command(args.json) as progress:
        try:   # start-up takes seconds; Ctrl-C is taken once the workers run (docs/fleet.md)
            where = f"connecting to {args.scheduler}" if args.scheduler else "starting the local Dask cluster"
            progress.stage(f"{where} and warming up its workers ...")
            with dask_client(args.scheduler, args.workers) as client:
                t0 = time.perf_counter()
                progress.stage(bar_text(0, len(jobs), 0, 0.0))
                failed = 0
                for row in run_on_dask(jobs, client, diagnose_it=args.diagnose, identify_options=options,
                                       stop=lambda: pressed() is not None, send_records=args.send_records):
                    rows.append(row)
                    failed += bool(row["error"])
                    progress.show(bar_text(len(rows), len(jobs), failed, time.perf_counter() - t0))
        except KeyboardInterrupt as exc:   # (a second signal)
            signum = exit_code(exc) - 128
        else:
            signum = pressed() if len(rows) < len(jobs) else None
    order = {job.id: i for i, job in enumerate(jobs)}
    rows.sort(key=lambda r: order[r["id"]])
    return rows, {"startup_s": t0 - start, "elapsed_s": time.perf_counter() - t0}, signum


def _finish(args: argparse.Namespace, jobs: list, rows: list[dict[str, Any]], times: dict[str, float],
            signum: int | None, outputs: tuple[Path | None, Path | None]) -> int:
    """Write the table and the page, print the summary; the exit code."""
    from ..fleet import summarize, write_table
    from ..reports.fleet_report import write_fleet_report
    summary = summarize(rows)
    elapsed = times["elapsed_s"]
    interrupted = signum is not None
    summary.update(planned=len(jobs), interrupted=interrupted, **times,
                   records_per_s=len(rows) / elapsed if elapsed > 0 else None,
                   scheduler=args.scheduler or "local")
    table, page = outputs
    if table is not None and rows:
        summary["table"] = str(write_table(rows, table, table_options(args)))
    if page is not None and rows:
        summary["html"] = str(write_fleet_report(rows, summary, page, title=f"creep-online batch {args.records}"))
    if args.json:
        summary["rows"] = rows
        print_json(summary)
    else:
        print(format_summary(summary))
    if interrupted:
        what = "interrupted" if signum == signal.SIGINT else STOP_SIGNALS.get(signum, "stopped")
        print(f"creep-online batch: {what} after {len(rows)} of {len(jobs)} records"
              f"{'; their rows are in ' + summary['table'] if 'table' in summary else ''}", file=sys.stderr)
        return 128 + signum
    return 1 if summary["failed"] else 0


def format_summary(summary: dict[str, Any]) -> str:
    """The terminal's summary: counts, medians and spreads, outliers, failures, files written."""
    lines = [f"{summary['records']} of {summary['planned']} records: {summary['identified']} identified, "
             f"{summary['failed']} failed, {summary['elapsed_s']:.1f} s (cluster start {summary['startup_s']:.1f} s)"
             + (f" ({summary['records_per_s']:.2f} records/s)" if summary.get("records_per_s") else "")]
    for name, d in summary["parameters"].items():
        if d.get("n"):
            lines.append(f"  {name:<6} median {d['median']:.5g}  (5-95 %: {d['p5']:.5g} .. {d['p95']:.5g})")
    for o in summary["outliers"]:
        lines.append(f"  outlier {o['id']}: " + ", ".join(f"{k} z = {z:+.1f}" for k, z in o["z"].items()))
    for f in summary["failures"]:
        lines.append(f"  failed {f['id']}: {f['error']}")
    for key in ("table", "html"):
        if key in summary:
            lines.append(f"{key}: {summary[key]}")
    return "\n".join(lines)


def bar_text(done: int, total: int, failed: int, elapsed: float) -> str:
    """The batch's status line: a bar, done/total, rate, time left, failures."""
    width = 30
    filled = int(width * done / max(total, 1))
    rate = done / elapsed if elapsed > 0 and done else 0.0
    left = f", {(total - done) / rate:.0f} s left" if rate else ""
    return f"[{'#' * filled}{'.' * (width - filled)}] {done}/{total} records, {rate:.1f}/s{left}" \
        + (f", {failed} failed" if failed else "")