"""HTML summary of a fleet batch: one self-contained file, no plotting library needed.

For each of alpha, fn, zeta and b: a histogram over the identified records on
the scale the outlier rule uses (log10 of the magnitude), the median, the band
inside which a record is not an outlier (shaded), and every outlier as a red
mark (hover: its id). Then the distribution table, the outliers with their
z-scores, the records that failed (with their one-line error) and those with
warnings. The plots are inline SVG, so the page opens anywhere and can be mailed.
"""
from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..fleet.summary import SUMMARY_PARAMETERS, Z_THRESHOLD, identified
from ..io.safe_files import WRITTEN_BY, atomic_write

LABELS = {"alpha": "alpha", "fn_hz": "fn (Hz)", "zeta": "zeta", "b": "|b|"}
#: Rows with warnings listed at most (the table holds them all).
MAX_LISTED = 200
_W, _H, _PAD = 440, 190, 36


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
             f"<p>Outlier rule: {esc(summary['outlier_rule'])}. Shaded: the band inside which a record is "
             f"not an outlier; red marks: outliers.</p>",
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
    """SVG histogram of log10|value| with the median, the non-outlier band and the outliers."""
    values = np.array([r[name] for r in good], dtype=float)
    label = html.escape(LABELS[name])
    if values.size == 0:
        return f"<svg width='{_W}' height='{_H}'><text x='10' y='20'>{label}: no identified records</text></svg>"
    x = np.log10(np.abs(values))
    med = float(np.median(x))
    mad = float(np.median(np.abs(x - med)))
    half = Z_THRESHOLD * mad / 0.6745
    lo, hi = float(min(x.min(), med - half)), float(max(x.max(), med + half))
    if hi - lo < 1e-9:
        lo, hi = lo - 0.01, hi + 0.01
    span = hi - lo
    lo, hi = lo - 0.03 * span, hi + 0.03 * span
    counts, edges = np.histogram(x, bins=30, range=(lo, hi))

    def px(v: float) -> float:
        return _PAD + (v - lo) / (hi - lo) * (_W - 2 * _PAD)

    base, top = _H - _PAD, 20
    scale = (base - top) / max(int(counts.max()), 1)
    out = [f"<svg width='{_W}' height='{_H}' xmlns='http://www.w3.org/2000/svg' font-size='11'>",
           f"<text x='{_PAD}' y='14' font-weight='bold'>{label}</text>"]
    if mad > 0:
        out.append(f"<rect x='{px(med - half):.1f}' y='{top}' width='{px(med + half) - px(med - half):.1f}' "
                   f"height='{base - top}' fill='#e6f4e6'/>")
    for c, e0, e1 in zip(counts, edges[:-1], edges[1:]):
        if c:
            out.append(f"<rect x='{px(e0):.1f}' y='{base - c * scale:.1f}' width='{max(px(e1) - px(e0) - 1, 1):.1f}' "
                       f"height='{c * scale:.1f}' fill='#4a78b0'/>")
    out.append(f"<line x1='{px(med):.1f}' x2='{px(med):.1f}' y1='{top}' y2='{base}' stroke='black' "
               f"stroke-dasharray='3,2'><title>median {10 ** med:.4g}</title></line>")
    out.append(f"<line x1='{_PAD}' x2='{_W - _PAD}' y1='{base}' y2='{base}' stroke='black'/>")
    for r, xv in zip(good, x):
        if name in r.get("outlier", "").split(","):
            out.append(f"<line x1='{px(xv):.1f}' x2='{px(xv):.1f}' y1='{base + 2}' y2='{base + 12}' stroke='red' "
                       f"stroke-width='2'><title>{html.escape(str(r['id']))}: {r[name]:.4g}</title></line>")
    for tick in _ticks(lo, hi):
        out.append(f"<text x='{px(tick):.1f}' y='{base + 26}' text-anchor='middle'>{10 ** tick:.3g}</text>")
    out.append(f"<text x='{_W - _PAD}' y='14' text-anchor='end'>{values.size} records, median "
               f"{10 ** med:.4g}</text></svg>")
    return "".join(out)


def _ticks(lo: float, hi: float, n: int = 4) -> list[float]:
    """About ``n`` evenly spaced tick positions (log10 units) inside [lo, hi]."""
    step = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(step))
    step = min((m * mag for m in (1, 2, 5, 10) if m * mag >= step), default=step)
    first = math.ceil(lo / step) * step
    return [first + k * step for k in range(n + 2) if first + k * step <= hi]


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
