"""HTML report of a diagnosis: measurement vs base and extended models, residuals, spectrum, ranking.

Writes ``index.html`` and PNG plots into a directory. matplotlib is imported
here only (the ``plots`` extra); without it the report fails with a one-line
CreepOnlineError and the rest of ``diagnose`` still works.
"""
from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from ..errors import CreepOnlineError
from ..io.safe_files import report_dir


def _pyplot():
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise CreepOnlineError("the report needs matplotlib (pip install 'creep_online[plots]')") from None
    return plt


def _decimate(n: int, limit: int = 20000) -> slice:
    return slice(None, None, max(1, n // limit))


def write_report(result, directory: str | Path) -> Path:
    """Write the report of a ``Diagnosis`` into ``directory``, in full or not at all; the path of index.html.

    The folder is built beside ``directory`` and swapped in at the end (an
    interrupted run leaves the previous report as it was).
    """
    plt = _pyplot()
    with report_dir(directory) as tmp:
        _write(plt, result, tmp)
    return Path(directory) / "index.html"


def _write(plt, result, out: Path) -> None:
    """The plots and index.html of a diagnosis, into folder ``out``."""
    data, base, best = result.data, result.base, result.best
    t, y = data.t, data.y
    sl = _decimate(t.size)
    log_t = not data.uniform
    figs: list[tuple[str, str]] = []

    # 1. overlay
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(t[sl], y[sl], "k.", ms=2, label="measurement")
    ax.plot(t[sl], base.y_hat[sl], lw=1, label=f"base model ({base.fit_percent:.2f} %)")
    if best is not base:
        ax.plot(t[sl], best.y_hat[sl], lw=1, label=f"+ {'+'.join(best.effects)} ({best.fit_percent:.2f} %)")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("y")
    if log_t:
        ax.set_xscale("log")
    ax.legend(loc="best")
    ax.set_title("measurement vs base and extended models")
    figs.append(("overlay.png", "Measurement against the base and the extended model"))
    fig.tight_layout()
    fig.savefig(out / figs[-1][0], dpi=90)
    plt.close(fig)

    # 2. residuals before / after
    fig, ax = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    ax[0].plot(t[sl], base.residual[sl], lw=0.6, color="C0")
    ax[0].set_ylabel("residual, base")
    ax[1].plot(t[sl], best.residual[sl], lw=0.6, color="C1")
    ax[1].set_ylabel("residual, extended" if best is not base else "residual (no effect added)")
    for a in ax:
        for k in (-1, 1):
            a.axhline(k * result.noise_rms, color="gray", lw=0.5, ls="--")
        if log_t:
            a.set_xscale("log")
    ax[1].set_xlabel("t (s)")
    fig.suptitle(f"residual RMS {base.residual_rms:.4g} -> {best.residual_rms:.4g} (noise floor ~{result.noise_rms:.4g}, dashed)")
    figs.append(("residuals.png", "Residuals before and after adding the effect"))
    fig.tight_layout()
    fig.savefig(out / figs[-1][0], dpi=90)
    plt.close(fig)

    # 3. residual spectrum with peaks
    if data.uniform and t.size >= 64:
        from ..diagnostics.locate import spectrum
        fig, ax = plt.subplots(figsize=(10, 4))
        f, p = spectrum(t, base.residual)
        ax.loglog(f[1:], p[1:], lw=0.8, label="base residual")
        if best is not base:
            f2, p2 = spectrum(t, best.residual)
            ax.loglog(f2[1:], p2[1:], lw=0.8, label="extended residual")
        for pk in result.location.get("spectrum_peaks", []):
            ax.axvline(pk["f_hz"], color="r", lw=0.6, ls=":")
            ax.annotate(f"{pk['f_hz']:.4g} Hz", (pk["f_hz"], pk["power"]), fontsize=8, color="r")
        ax.set_xlabel("f (Hz)")
        ax.set_ylabel("PSD")
        ax.legend(loc="best")
        ax.set_title("residual spectrum (peaks marked)")
        figs.append(("spectrum.png", "Residual spectrum with its peaks marked"))
        fig.tight_layout()
        fig.savefig(out / figs[-1][0], dpi=90)
        plt.close(fig)

    # 4. (u, y - model) plane: the loop of hysteresis, the curve of a nonlinear gain
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.plot(data.u[sl], base.residual[sl], lw=0.4)
    ax.set_xlabel("u")
    ax.set_ylabel("base residual")
    ax.set_title("residual against the input")
    figs.append(("input_plane.png", "Base residual against the input (loops: hysteresis; curves: nonlinear gain)"))
    fig.tight_layout()
    fig.savefig(out / figs[-1][0], dpi=90)
    plt.close(fig)

    (out / "index.html").write_text(_html(result, figs), encoding="utf-8")


def _num(x) -> str:
    if isinstance(x, (int, float, np.floating)) and math.isfinite(float(x)):
        return f"{float(x):.4g}"
    return html.escape(str(x))


def _params(p: dict) -> str:
    items = []
    for k, v in p.items():
        if k in ("r", "w"):
            continue
        items.append(f"{html.escape(k)}={_num(v) if not isinstance(v, list) else ', '.join(_num(x) for x in v)}")
    return "; ".join(items)


def _html(result, figs: list[tuple[str, str]]) -> str:
    b = result.base
    rows = []
    for i, c in enumerate(result.candidates, 1):
        style = ' style="font-weight:bold"' if i == 1 and c.significant else ""
        rows.append(f"<tr{style}><td>{i}</td><td>{c.effect}</td><td>{_num(c.evidence)}</td>"
                    f"<td>{'yes' if c.significant else 'no'}</td><td>{_num(b.fit_percent)}</td>"
                    f"<td>{_num(c.fit.fit_percent)}</td><td>{_num(b.residual_rms)}</td><td>{_num(c.fit.residual_rms)}</td>"
                    f"<td>{html.escape(_params(c.fit.effect_params.get(c.effect, {})))}</td>"
                    f"<td>{html.escape(c.signature)}</td></tr>")
    for name, why in result.skipped.items():
        rows.append(f"<tr><td>-</td><td>{name}</td><td colspan=8>skipped: {html.escape(why)}</td></tr>")
    findings = "".join(f"<li>{html.escape(f)}</li>" for f in result.location.get("findings", []))
    notes = "".join(f"<li>{html.escape(w)}</li>" for w in result.warnings)
    images = "".join(f'<figure><img src="{name}" alt="{html.escape(cap)}"><figcaption>{html.escape(cap)}</figcaption></figure>'
                     for name, cap in figs)
    combo = ""
    if result.combination is not None:
        c = result.combination
        combo = (f"<p>Two effects together ({c.effect}): fit {_num(c.fit.fit_percent)} %, residual RMS "
                 f"{_num(c.fit.residual_rms)}; {html.escape(c.signature)}.</p>")
    ra = result.residual_analysis
    ac, xc = ra.get("autocorrelation", {}), ra.get("cross_correlation", {})
    unc = ra.get("parameter_uncertainty", {})
    unc_rows = "".join(f"<tr><td>{k}</td><td>{_num(v['value'])}</td><td>{_num(v['std'])}</td></tr>" for k, v in unc.items())
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>creep-online diagnose: {html.escape(result.source)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}} table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 6px;font-size:90%}} img{{max-width:100%}}</style></head><body>
<h1>Model discrepancy: {html.escape(result.source)}</h1>
<p><b>Verdict: {result.verdict}</b>. Base model {html.escape(str(b.model))}, offset {_num(b.offset)}.
Fit {_num(b.fit_percent)} %, residual RMS {_num(b.residual_rms)}, noise floor ~{_num(result.noise_rms)}.</p>
<p>Decided by: {html.escape(result.verdict_basis["text"])}. Hold physics (leakage / second creep / drift):
{html.escape(str(result.physics.get("verdict")))} ({html.escape(str(result.physics.get("reason")))}).</p>
<h2>Where the base model fails</h2><ul>{findings}</ul>
<h2>Which effect explains it</h2>
<table><tr><th>rank</th><th>effect</th><th>evidence (BIC drop)</th><th>significant</th><th>fit % before</th>
<th>fit % after</th><th>RMS before</th><th>RMS after</th><th>parameters</th><th>signature</th></tr>
{''.join(rows)}</table>{combo}
{images}
<h2>Residual analysis (base model)</h2>
<p>Autocorrelation: {ac.get('outside', '?')} of {len(ac.get('values', [])) - 1} lags outside the 99 % band
(+-{_num(ac.get('bound', float('nan')))}); cross-correlation with the input increments: {xc.get('outside', '?')} of
{len(xc.get('values', []))} lags outside.</p>
<table><tr><th>parameter</th><th>value</th><th>1-sigma</th></tr>{unc_rows}</table>
<h2>Notes</h2><ul>{notes}</ul>
<p>Elapsed {result.elapsed_s:.2f} s.</p></body></html>
"""
