"""Report of a ``creep-online demo`` run: ``summary.json`` always, ``report.html`` + PNG plots with matplotlib.

Plots: measured output against the identified model's simulation (whole run
and the first resonance transient), the convergence of each parameter towards
the plant's true value, and the latency distribution. In a scenario where the
plant changes (``demo --scenario payload``, ``drift``) every error is measured
against the plant valid at that moment (``plant_truth``), each segment between
changes is drawn with the estimate made for it, and the changes are marked.
"""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ..io.jsonable import json_text


def plant_truth(scenario: dict, t: float) -> dict[str, float]:
    """The plant's (alpha, a1, a2, b) at plant time t in a scenario (``commands.demo.scenario_plan``): its start
    values, times the factors of every change up to t, plus a drift linear in t over the run (as hil_sim makes it)."""
    p = {k: float(scenario["start"][k]) for k in ("alpha", "a1", "a2", "b")}
    for change in scenario.get("changes", []):
        if t >= change["t"]:
            for k, factor in change["factors"].items():
                p[k] *= factor
    drift = scenario.get("drift")
    if drift:
        frac = min(max(t / scenario["t_last"], 0.0), 1.0) if scenario["t_last"] > 0 else 1.0
        p["alpha"] *= 1.0 + drift["alpha"] * frac
        p["b"] *= 1.0 + drift["b"] * frac
    return p


def _change_times(r: dict) -> list[float]:
    return [float(c["t"]) for c in (r.get("scenario") or {}).get("changes", [])]


def _mark_changes(ax, r: dict, scale: float = 1.0) -> None:
    """A vertical line at every change of the plant, labelled with what changed."""
    for k, change in enumerate((r.get("scenario") or {}).get("changes", [])):
        ax.axvline(change["t"] * scale, color="tab:red", lw=1.0, ls="--", label=change["what"] if k == 0 else None)


def write_report(out_dir: str | Path, r: dict) -> str:
    """Write the report folder in full or not at all; return a one-line description of what was written where."""
    from ..io.safe_files import report_dir
    with report_dir(out_dir) as tmp:
        text = _write(tmp, r)
    return text.replace(str(tmp), str(Path(out_dir)))


def _write(out: Path, r: dict) -> str:
    """summary.json, plots and report.html into folder ``out``."""
    public = {k: v for k, v in r.items() if not k.startswith("_")}
    (out / "summary.json").write_text(json_text(public))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return (f"{out / 'summary.json'} (matplotlib is not installed: no plots; "
                "pip install 'creep_online[plots]')")
    pngs = [_plot_fit(plt, out, r), _plot_convergence(plt, out, r), _plot_latency(plt, out, r)]
    if "compensation" in r:        # demo --compensate
        pngs.insert(0, _plot_compensation(plt, out, r))
    pngs = [p for p in pngs if p]
    page = out / "report.html"
    page.write_text(_html(r, pngs))
    return f"{page} (+ summary.json, {len(pngs)} PNG plots)"


def _plot_fit(plt, out: Path, r: dict) -> str | None:
    from ..model import CreepModel
    from ..simulate import simulate
    seq, u, y = r["_seq"], r["_u"], r["_y"]
    if r.get("model") is None or seq.size < 10:
        return None
    dt = 1.0 / r["rate_hz"]
    n = int(seq[-1]) + 1
    # the input on the full grid (zero-order hold across any lost samples)
    idx = np.searchsorted(seq, np.arange(n), side="right") - 1
    u_full = np.where(idx >= 0, u[np.clip(idx, 0, None)], 0.0)
    t = np.arange(n) * dt
    offset = float(r["estimate"].get("offset", 0.0))
    segments = _segments(r, t)
    y_hat = np.empty(n)
    first_model = None
    for (a, b), m in segments:
        model = CreepModel(m["alpha"], m["a1"], m["a2"], m["b"])
        first_model = first_model or model
        y_hat[a:b] = simulate(model, t[:b], u_full[:b])[a:b] + offset
    t_meas = seq * dt
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5))
    step = max(1, seq.size // 20000)
    axes[0].plot(t_meas[::step], y[::step], lw=0.6, label="measured (received)")
    label = "identified model" if len(segments) == 1 else "estimate made for each segment"
    axes[0].plot(t[::step], y_hat[::step], lw=1.0, label=label)
    _mark_changes(axes[0], r)
    title = "Output: measured vs identified model"
    if (r.get("scenario") or {}).get("drift"):
        title += " (the plant drifts: the final estimate, valid at the end)"
    axes[0].set(xlabel="t (s)", ylabel="y", title=title)
    axes[0].legend()
    first = int(np.argmax(u_full != 0)) if np.any(u_full != 0) else 0
    span = max(int(6 * first_model.settling_time / dt), 200)
    win = slice(first, min(n, first + span))
    sel = (seq >= win.start) & (seq < win.stop)
    axes[1].plot(t_meas[sel] * 1e3, y[sel], ".", ms=2, label="measured")
    axes[1].plot(t[win] * 1e3, y_hat[win], lw=1.0, label=label)
    axes[1].set(xlabel="t (ms)", ylabel="y", title="First step: the resonance transient")
    axes[1].legend()
    fig.tight_layout()
    path = out / "fit.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def _segments(r: dict, t: np.ndarray) -> list[tuple[tuple[int, int], dict]]:
    """(sample range, estimate) for each stretch between the plant's changes: the estimate of the trace's last
    point before the stretch ends (the final estimate for the last stretch)."""
    edges = [0] + [int(np.searchsorted(t, c)) for c in _change_times(r)] + [t.size]
    out = []
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        if b <= a:
            continue
        if k == len(edges) - 2:
            est = r["model"]
        else:
            before = [p for p in r["trace"] if p["t"] < t[b - 1] and p["quality"] != "none"]
            est = before[-1] if before else r["model"]
        out.append(((a, b), est))
    return out


def _plot_compensation(plt, out: Path, r: dict) -> str | None:
    """Reference, output compensated (measured) and uncompensated (simulated), and both creep errors."""
    ref, y_comp, y_unc = r["_r"], r["_y_full"], r["_y_uncomp"]
    c = r["compensation"]
    t = np.arange(ref.size) / r["rate_hz"]
    step = max(1, ref.size // 20000)
    fig, axes = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    ax = axes[0]
    ax.plot(t[::step], y_unc[::step], lw=0.8, color="tab:red", label="output, uncompensated (u = r/g, simulated)")
    y_creep = r.get("_y_creep")          # (a plant with hysteresis: the creep part alone, simulated)
    if y_creep is not None:
        ax.plot(t[::step], y_creep[::step], lw=0.8, color="tab:green", label="output, creep only (simulated)")
    ax.plot(t[::step], y_comp[::step], lw=0.8, color="tab:blue", label="output, compensated (measured)")
    ax.plot(t[::step], ref[::step], lw=1.0, ls="--", color="k", label="reference")
    ax.axvline(c["first_model_t"], color="0.6", lw=0.8)
    what = "Creep and hysteresis" if y_creep is not None else "Creep"
    ax.set(ylabel="y", title=f"{what} compensation: the output follows the reference")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.plot(t[::step], (y_unc - ref)[::step], lw=0.8, color="tab:red", label="uncompensated")
    if y_creep is not None:
        ax.plot(t[::step], (y_creep - ref)[::step], lw=0.8, color="tab:green", label="creep only")
        ax.axvline(r["_t_scan"], color="0.3", lw=0.8, ls=":", label="scan starts")
    ax.plot(t[::step], (y_comp - ref)[::step], lw=0.8, color="tab:blue", label="compensated")
    ax.axvline(c["first_model_t"], color="0.6", lw=0.8, label="first model")
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set(xlabel="plant time (s)", ylabel="output - reference", title="Error over time")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / "compensation.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def _plot_convergence(plt, out: Path, r: dict) -> str | None:
    tr = [p for p in r["trace"] if p["phase"] == "tracking" or p["quality"] != "none"]
    if len(tr) < 2:
        return None
    t = np.array([p["t"] for p in tr])
    est = _derived({k: np.array([p[k] for p in tr]) for k in ("alpha", "a1", "a2", "b")})
    truth = _truth_over(r, t)
    fig, ax = plt.subplots(figsize=(9, 4))
    for name in ("alpha", "fn", "zeta", "b"):
        ax.semilogy(t, np.abs(est[name] / truth[name] - 1) + 1e-9, label=name)
    _mark_changes(ax, r)
    changing = (r.get("scenario") or {}).get("name", "stationary") != "stationary"
    what = " (against the plant valid at each moment)" if changing else ""
    ax.set(xlabel="plant time (s)", ylabel="|relative error|", title=f"Convergence of the online estimate{what}")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path = out / "convergence.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def _derived(p: dict) -> dict:
    """alpha, fn, zeta, b from alpha, a1, a2, b (arrays)."""
    return {"alpha": p["alpha"], "fn": 1.0 / (2 * np.pi * np.sqrt(p["a2"])), "zeta": p["a1"] / (2 * np.sqrt(p["a2"])),
            "b": p["b"]}


def _truth_over(r: dict, t: np.ndarray) -> dict:
    """The plant's alpha, fn, zeta, b at each time of ``t`` (the scenario's plan; the final truth without one)."""
    if r.get("scenario"):
        rows = [plant_truth(r["scenario"], float(x)) for x in t]
        return _derived({k: np.array([row[k] for row in rows]) for k in ("alpha", "a1", "a2", "b")})
    truth = r["truth"]
    return {"alpha": truth["alpha"], "fn": truth["fn_hz"], "zeta": truth["zeta"], "b": truth["b"]}


def _plot_latency(plt, out: Path, r: dict) -> str | None:
    lat = np.asarray(r["_lat_us"])
    if lat.size == 0:
        return None
    fig, ax = plt.subplots(figsize=(9, 3.5))
    hi = max(float(np.percentile(lat, 99.9)), 1.0)
    ax.hist(np.clip(lat, 0, hi), bins=100)
    ax.set_yscale("log")
    p = r["latency_us"]
    ax.set(xlabel="latency (us): plant sample time -> estimator updated",
           ylabel="samples", title=f"Latency: p50 {p['p50']:.0f} us, p99 {p['p99']:.0f} us, max {p['max']:.0f} us")
    fig.tight_layout()
    path = out / "latency.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


def _compensation_html(r: dict) -> str:
    c = r.get("compensation")
    if not c:
        return ""
    m, un = c["creep_error_compensated"], c["creep_error_uncompensated_simulated"]
    return (f"<h2>Creep compensation</h2><p>Reference filter {c['bandwidth_hz']:.0f} Hz, first model at "
            f"{c['first_model_t']:.2f} s, {c['model_changes']} model updates, {c['clipped']} clipped commands. "
            f"Creep error after the resonance transient, holds after the first estimate: compensated (measured) "
            f"max {m['max_abs']:.2e}, rms {m['rms']:.2e}; uncompensated (simulated) max {un['max_abs']:.2e}, "
            f"rms {un['rms']:.2e}.</p>" + _hysteresis_html(c.get("hysteresis")))


def _hysteresis_html(h: dict | None) -> str:
    if not h:
        return ""
    tr = h["tracking_rms"]
    return (f"<p>Hysteresis: on the {h['scan_hz']:g} Hz triangle scan from {h['t_scan']:.2f} s, the rms of the output "
            f"minus the shaped reference is {tr['compensated']:.2e} compensated with the live loop and creep "
            f"(measured), {tr['creep_only_simulated']:.2e} with the creep part alone ({h['ratio_creep_only']:.1f}x) "
            f"and {tr['uncompensated_simulated']:.2e} uncompensated ({h['ratio_uncompensated']:.1f}x), both simulated "
            "exactly on the same plant.</p>")


def _scenario_html(r: dict) -> str:
    """What the plant did over the run, and what the errors are measured against."""
    sc = r.get("scenario") or {}
    parts = [f"at t = {c['t']:.4g} s, {html.escape(c['what'])}" for c in sc.get("changes", [])]
    if sc.get("drift"):
        parts.append(f"alpha {100 * sc['drift']['alpha']:+.0f} % and b {100 * sc['drift']['b']:+.0f} % over the run")
    if not parts:
        return ""
    return (f"<p>Scenario {html.escape(sc['name'])}: {'; '.join(parts)}. The table compares the final estimate with "
            "the plant at the end of the run; the plots measure every error against the plant valid at its "
            "moment, and mark the changes.</p>")


def _html(r: dict, pngs: list[str]) -> str:
    rows = []
    m, t, e = r.get("model"), r["truth"], r.get("errors", {})
    if m:
        for key, tk, ek, scale, unit in (("alpha", "alpha", "alpha_abs", 1, ""), ("fn_hz", "fn_hz", "fn_rel", 100, "%"),
                                         ("zeta", "zeta", "zeta_rel", 100, "%"), ("b", "b", "b_rel", 100, "%")):
            rows.append(f"<tr><td>{key}</td><td>{m[key]:.6g}</td><td>{t[tk]:.6g}</td>"
                        f"<td>{e[ek] * scale:+.3g} {unit}</td></tr>")
    s = r["source_stats"]
    counters = "".join(f"<tr><td>{html.escape(k)}</td><td>{v}</td></tr>" for k, v in s.items() if k != "events")
    lat = r["latency_us"]
    imgs = "".join(f'<p><img src="{p}" style="max-width:100%"></p>' for p in pngs)
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>creep-online demo</title>
<style>body{{font-family:sans-serif;max-width:960px;margin:auto}}td,th{{padding:2px 10px;text-align:right}}</style>
</head><body><h1>creep-online demo</h1>
<p>Simulated plant (hil_sim) over {html.escape(r['tty'])}, {html.escape(r['transport'])}, {r['rate_hz']:g} Hz;
{r['samples_received']} of {r['samples_sent_by_plant']} samples received in {r['wall_s']:.1f} s
({r['achieved_rate_sps'] / 1e3:.1f} kS/s). Latency (plant sample time to estimator updated):
p50 {lat['p50']:.0f} us, p99 {lat['p99']:.0f} us, max {lat['max']:.0f} us.</p>
<h2>Estimate vs truth</h2>{_scenario_html(r)}<p>phase {html.escape(r['estimate']['phase'])}, quality {html.escape(r['estimate']['quality'])}</p>
<table><tr><th>parameter</th><th>estimate</th><th>true</th><th>error</th></tr>{''.join(rows)}</table>
{_compensation_html(r)}{imgs}
<h2>Transport counters</h2><table>{counters}</table>
</body></html>"""
