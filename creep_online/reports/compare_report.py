"""Report of ``creep-online compare``: ``report.html`` with ``compare.png`` and ``compare.json``.

The plot: the measured output with the model's simulation over it (top), and
the residual with the noise band and the worst stretch marked (bottom), on the
record's time axis in the units the data named. matplotlib is imported here
only (the ``plots`` extra); without it the report fails with a one-line
CreepOnlineError and the comparison itself still prints.
"""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ..errors import CreepOnlineError
from ..io.jsonable import json_text
from ..io.safe_files import report_dir

#: Most points drawn per curve (longer records are decimated for the plot only).
PLOT_POINTS = 20000


def write_report(result, directory: str | Path, model_file: str = "") -> Path:
    """Write the report of a ``Comparison`` into ``directory``, in full or not at all; the path of report.html."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise CreepOnlineError("the report needs matplotlib (pip install 'creep_online[plots]')") from None
    with report_dir(directory) as tmp:
        (tmp / "compare.json").write_text(json_text({**result.to_dict(), "model_file": model_file}))
        _plot(plt, result, tmp / "compare.png")
        (tmp / "report.html").write_text(_html(result, model_file))
    return Path(directory) / "report.html"


def _plot(plt, result, path: Path) -> None:
    """Model over measurement, and the residual with the noise band and the worst stretch."""
    t, y, y_hat = result.t, result.y, result.y_hat
    r = y - y_hat
    sl = slice(None, None, max(1, t.size // PLOT_POINTS))
    units = result.model.units
    y_label = f"y ({units['y']})" if units.get("y") else "y"
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    axes[0].plot(t[sl], y[sl], color="0.25", lw=0.7, label="measured")
    axes[0].plot(t[sl], y_hat[sl], color="tab:orange", lw=1.0, label=f"model ({result.fit_percent:.2f} %)")
    axes[0].set(ylabel=y_label, title=f"{Path(result.source).name}: model against measurement")
    axes[0].legend(loc="best")
    noise = result.metrics["noise_rms"]
    axes[1].plot(t[sl], r[sl], color="tab:blue", lw=0.6, label="residual")
    if np.isfinite(noise):
        axes[1].axhspan(-2 * noise, 2 * noise, color="0.85", label="+-2 sigma noise")
    worst = result.metrics["worst_window"]
    axes[1].axvspan(worst["t_start"], worst["t_end"], color="tab:red", alpha=0.15, label="worst stretch")
    axes[1].set(xlabel="t (s)", ylabel=f"measured - model{(' (' + units['y'] + ')') if units.get('y') else ''}")
    axes[1].legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _html(result, model_file: str) -> str:
    m, r, init = result.model, result.metrics, result.initial
    rows = "".join(f"<tr><td>{html.escape(k)}</td><td>{v:.6g}</td></tr>" for k, v in m.base.describe().items())
    effects = "".join(f"<tr><td>{html.escape(name)}</td><td>{html.escape(str(p))}</td></tr>"
                      for name, p in m.effects.items()) or "<tr><td colspan=2>none</td></tr>"
    fitted = m.fitted.get("fit_percent")
    fitted_text = f" ({fitted:.2f} % on the record it was fitted on)" if fitted is not None else ""
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>creep-online compare</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:auto}}td,th{{padding:2px 10px;text-align:left}}</style>
</head><body><h1>creep-online compare</h1>
<p>Model {html.escape(model_file)} on {html.escape(result.source)} ({result.y.size} samples):
<b>fit {result.fit_percent:.2f} %</b>{fitted_text}. Residual rms {r['residual_rms']:.4g}, max |e|
{r['residual_max_abs']:.4g}, noise ~{r['noise_rms']:.3g}; {'white' if r['white'] else 'not white'}.
Offset {result.offset:.6g} ({'estimated' if init['offset_estimated'] else "the model's"}); start:
{html.escape(init['reading'])}, {init['free_response_terms']} free-response terms.</p>
<p><img src="compare.png" style="max-width:100%"></p>
<h2>Model</h2><table>{rows}</table><h2>Effects</h2><table>{effects}</table>
</body></html>"""
