"""HTML summary of a fleet batch: one self-contained file, the plots drawn by matplotlib as inline SVG.

For each of alpha, fn, zeta and b: a histogram over the identified records on
a logarithmic axis (the scale of the outlier rule: log10 of the magnitude),
with a value axis and a count axis, each bar's count above it, the median
(dashed), the band inside which a record is not an outlier (shaded; the rule's
own ``outlier_band``) and every outlier as a red line named by its id. The gain
is plotted signed: a symmetric-log axis shows a unit of the minority sign (an
actuator wired backwards) on its own side of zero, away from the band, which
lies on the majority's side. Then the distribution table, the outliers with
their z-scores, the records that failed (with their one-line error) and those
with warnings. The page holds everything (SVG inline), so it opens anywhere and
can be mailed.
"""
from __future__ import annotations

import html
import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CreepOnlineError
from ..fleet.summary import SUMMARY_PARAMETERS, Z_THRESHOLD, identified, majority_sign, outlier_band
from ..io.safe_files import WRITTEN_BY, atomic_write

LABELS = {"alpha": "alpha", "fn_hz": "fn (Hz)", "zeta": "zeta", "b": "b (signed)"}
#: Rows with warnings listed at most (the table holds them all).
MAX_LISTED = 200
#: Histogram bins over the plotted range; outliers named on the plot at most (the table lists them all).
BINS = 30
MAX_NAMED = 8
#: Figure size (inches) and resolution of each histogram.
FIGSIZE, DPI = (4.8, 2.9), 96


def pyplot() -> Any:
    """matplotlib's pyplot on the Agg backend, or a one-line error naming the extra."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise CreepOnlineError("the HTML summary needs matplotlib (pip install 'creep_online[fleet]'), "
                               "or give no --out/--html") from None
    return plt


def write_fleet_report(rows: list[dict[str, Any]], summary: dict[str, Any], path: str | Path,
                       title: str = "creep-online batch") -> Path:
    """Write the summary page of a batch to ``path`` (atomically); the path."""
    with atomic_write(path) as fh:
        fh.write(render(rows, summary, title))
    return Path(path)


def render(rows: list[dict[str, Any]], summary: dict[str, Any], title: str) -> str:
    """The page's HTML."""
    good = identified(rows)
    esc = html.escape
    parts = [f"<!doctype html><!-- {WRITTEN_BY} --><html><head><meta charset='utf-8'><title>{esc(title)}</title>",
             "<style>body{font-family:sans-serif;margin:2em;max-width:1000px}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:2px 8px;"
             "text-align:right}td.l,th.l{text-align:left}.plots{display:flex;flex-wrap:wrap;gap:12px}"
             "svg{border:1px solid #eee}</style></head><body>",
             f"<h1>{esc(title)}</h1>",
             f"<p>{summary['records']} records: {summary['identified']} identified, {summary['failed']} failed, "
             f"{summary['with_warnings']} with warnings, {len(summary['outliers'])} outliers.</p>",
             f"<p>Outlier rule: {esc(summary['outlier_rule'])}. Each plot: records per bin (the count above "
             f"each bar) on a logarithmic axis; shaded: the band inside which a record is not an outlier; dashed: "
             f"the median; red: outliers. The gain is signed: a unit wired backwards is on the other side of "
             f"zero.</p>",
             "<div class='plots'>"]
    for name in SUMMARY_PARAMETERS:
        parts.append(_histogram(name, good))
    parts.append("</div>")
    parts.append(_distribution_table(summary))
    parts.append(_outlier_table(summary, {r["id"]: r for r in good}))
    parts.append(_listing("Failed records", [(r["id"], r["error"]) for r in rows if r.get("error")]))
    parts.append(_listing("Records with warnings", [(r["id"], r["warnings"]) for r in good if r.get("warnings")]))
    if summary.get("verdicts"):
        parts.append(_listing("Diagnosis verdicts", sorted(summary["verdicts"].items())))
    parts.append("</body></html>")
    return "\n".join(parts)


def _histogram(name: str, good: list[dict[str, Any]]) -> str:
    """The SVG of one parameter's histogram (module docstring)."""
    plt = pyplot()
    values = np.array([r[name] for r in good], dtype=float)
    fig, ax = plt.subplots(figsize=FIGSIZE, dpi=DPI)
    try:
        if values.size == 0:
            ax.set_axis_off()
            ax.text(0.5, 0.5, f"{LABELS[name]}: no identified records", ha="center", transform=ax.transAxes)
        else:
            outliers = [(str(r["id"]), r[name]) for r in good if name in r.get("outlier", "").split(",")]
            _draw(ax, name, values, outliers)
        fig.tight_layout()
        buf = io.StringIO()
        fig.savefig(buf, format="svg")
    finally:
        plt.close(fig)
    text = buf.getvalue()
    return text[text.index("<svg"):]


def _draw(ax: Any, name: str, values: np.ndarray, outliers: list[tuple[str, float]]) -> None:
    from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator, NullLocator
    mags = np.log10(np.abs(values))
    med, half = outlier_band(mags)
    sign = majority_sign(values) if name == "b" else 1.0
    edges, ticks = [], []
    for side in sorted({float(np.sign(v)) for v in values} | {sign}):
        mine = mags[np.sign(values) == side]
        lo, hi = float(mine.min(initial=med)), float(mine.max(initial=med))
        if side == sign and math.isfinite(half):      # the majority's side: the band too
            lo, hi = min(lo, med - half), max(hi, med + half)
        pad = max(0.04 * (hi - lo), 0.005)
        magnitudes = 10 ** np.linspace(lo - pad, hi + pad, BINS + 1 if side == sign else 4)
        edges.append(side * (magnitudes[::-1] if side < 0 else magnitudes))
        ticks += [side * t for t in _ticks(magnitudes[0], magnitudes[-1], 5)] if side == sign \
            else [side * float(np.median(10 ** mine))]       # the minority's side: its own value
    bins = np.concatenate(edges)
    if name == "b" or len(edges) > 1 or sign < 0:
        ax.set_xscale("symlog", linthresh=float(np.abs(bins).min()), linscale=0.1)
    else:
        ax.set_xscale("log")
    counts, _, patches = ax.hist(values, bins=bins, color="#4a78b0", edgecolor="white", linewidth=0.5)
    ax.bar_label(patches, labels=[str(int(c)) if c else "" for c in counts], fontsize=7, padding=1)
    if math.isfinite(half):
        ends = sorted(sign * 10 ** np.array([med - half, med + half]))
        ax.axvspan(ends[0], ends[1], color="#2e8b57", alpha=0.15, lw=0,
                   label=f"not an outlier (|z| <= {Z_THRESHOLD:g})")
    ax.axvline(sign * 10 ** med, color="black", ls="--", lw=1, label=f"median {sign * 10 ** med:.4g}")
    for k, (rid, value) in enumerate(outliers):
        ax.axvline(value, color="red", lw=1.5, label="outlier" if k == 0 else None)
        if k < MAX_NAMED:
            ax.annotate(rid, (value, 0.97), xycoords=("data", "axes fraction"), fontsize=7, color="red",
                        rotation=90, ha="right", va="top")
    ax.xaxis.set_major_locator(FixedLocator(sorted(ticks)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.3g}"))
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xlim(bins[0], bins[-1])
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylim(0, max(counts.max(), 1) * 1.3)
    ax.set_xlabel(LABELS[name], fontsize=8)
    ax.set_ylabel("records", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title(f"{LABELS[name]}: {values.size} records, median {sign * 10 ** med:.4g}", fontsize=9)
    ax.legend(fontsize=6, loc="best", framealpha=0.8)


def _ticks(lo: float, hi: float, n: int) -> list[float]:
    """About ``n`` readable values in [lo, hi] (0 < lo): 1-2-5 steps within a decade or so, decades beyond."""
    from matplotlib.ticker import MaxNLocator
    if hi / lo > 30:
        first, last = math.ceil(math.log10(lo)), math.floor(math.log10(hi))
        step = max(1, (last - first + 1) // n)
        return [10.0 ** k for k in range(first, last + 1, step)]
    return [float(t) for t in MaxNLocator(n).tick_values(lo, hi) if lo <= t <= hi]


def _distribution_table(summary: dict[str, Any]) -> str:
    head = "<tr><th class='l'>parameter</th><th>n</th><th>median</th><th>MAD</th><th>5 %</th><th>95 %</th>" \
           "<th>min</th><th>max</th></tr>"
    body = []
    for name, d in [*summary["parameters"].items(), ("fit_percent", summary["fit_percent"])]:
        if not d.get("n"):
            continue
        cells = "".join(f"<td>{d[k]:.4g}</td>" for k in ("median", "mad", "p5", "p95", "min", "max"))
        body.append(f"<tr><td class='l'>{html.escape(name)}</td><td>{d['n']}</td>{cells}</tr>")
    return "<h2>Distributions</h2><table>" + head + "".join(body) + "</table>"


def _outlier_table(summary: dict[str, Any], by_id: dict[str, dict[str, Any]]) -> str:
    if not summary["outliers"]:
        return "<h2>Outliers</h2><p>none</p>"
    rows = []
    for o in summary["outliers"]:
        r = by_id.get(o["id"], {})
        flagged = ", ".join(f"{k} = {r.get(k, float('nan')):.4g} (z = {z:+.1f})" for k, z in o["z"].items())
        rows.append(f"<tr><td class='l'>{html.escape(str(o['id']))}</td><td class='l'>{html.escape(flagged)}</td></tr>")
    return "<h2>Outliers</h2><table><tr><th class='l'>id</th><th class='l'>flagged on</th></tr>" + "".join(rows) + \
        "</table>"


def _listing(title: str, items: list[tuple[Any, Any]]) -> str:
    if not items:
        return ""
    shown = items[:MAX_LISTED]
    more = f"<p>... and {len(items) - len(shown)} more (see the table)</p>" if len(items) > len(shown) else ""
    rows = "".join(f"<tr><td class='l'>{html.escape(str(a))}</td><td class='l'>{html.escape(str(b))}</td></tr>"
                   for a, b in shown)
    return f"<h2>{html.escape(title)} ({len(items)})</h2><table>{rows}</table>{more}"
