"""Diagnosis of two effects at once (issue 9 item 2): randomized records hiding a pair of catalogue effects.

The records are ``bench_diagnose_bands``' (same plants, staircase, noise rule:
``draw_record``) with two effects hidden at once, each at its own
``example_params`` strength drawn from the record's generator; the white noise
is scaled so that the base model's best fit misses the noise-free output by
``ratio`` times the noise (``ratio`` log-uniform in the band). Per record:
whether ``Diagnosis.combination`` (the pair search, ``diagnostics/pairs.py``)
is the hidden pair, significant over the best single effect (``both_named``)
and within 1.3x the noise (``at_floor``), the verdict, whether the two best
single fits are the pair (``top_two_right``: how the combination was chosen
before the pair search), and how strong each effect is alone (the base
model's misfit of the record with that effect only, noise-free, over the
noise). Where the combination is not the hidden pair at the floor, the hidden
pair is also fitted directly (``extended.fit_extended``, warm from the better
of its two single fits) to tell a search failure from a ranking one. Each row
lists the chosen pair's ``rivals`` (pairs within the BIC threshold of it, with
how far behind) and ``named_or_rival``: the hidden pair chosen, or named as a
rival of a significant combination (the diagnosis then warns that the
combination is not firm); per cell ``right_with_rivals`` counts the right
choices that were nonetheless flagged as not firm.

Detectability (the 1.3-3x band, where the weaker effect may be below any test): each row says whether both
hidden effects can be named at all (``second_detectable``, a bound from each effect's strength alone and the
diagnosis' own BIC rule, ``detectability``; ``--given`` adds the sharper bound from each effect's strength
given the other). Per cell ``both_named_where_detectable`` and ``at_floor_where_detectable`` count over the
records that pass; ``right_where_undetectable`` counts the others diagnosed right: the detectable effect named,
no significant pair with an effect outside the hidden pair. Where a record missed, the hidden pair fitted
directly also gives its BIC drop over the better of its single fits
(``hidden_pair_fitted_evidence_over_single``: the evidence the record actually holds for the second effect).

Prints one JSON document (``--out`` also writes it) with the command line, a
table per pair and band (counts and fractions, what was named when wrong) and
every record. Usage::

    python -m bench.bench_diagnose_pairs --records 30 [--first-seed 0] [--pairs hysteresis+drift]
        [--bands 3-10x,10-100x] [--forward [--partners all]] [--out F]
    python -m bench.bench_diagnose_pairs --merge A.json B.json --out F   # consecutive seeds
    python -m bench.bench_diagnose_pairs --recheck OLD.json --which missed|above|unsearched --out F
    python -m bench.bench_diagnose_pairs --given RUN.json [--which missed|all] --out F

``--recheck`` reruns only an earlier run's misses, each beside its earlier row: a fix's effect on exactly the
records it was aimed at (a change that can move other records still needs the full table). OLD.json may be
a recheck itself: its rows' current results are then what is picked from.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import sys
import time
from collections import Counter
from functools import lru_cache

import numpy as np
from scipy.stats import chi2, ncx2


from bench.bench_diagnose_bands import BANDS, FLOOR, H, N, draw_record, emit, merge  # noqa: E402
from creep_online.diagnostics import diagnose  # noqa: E402
from creep_online.diagnostics.explain import evidence  # noqa: E402
from creep_online.diagnostics.bic import EVIDENCE_THRESHOLD  # noqa: E402
from creep_online.diagnostics.extended import Design, _default_tail, base_theta, fit_base, fit_extended, prepare  # noqa: E402,E501
from creep_online.effects import effect_names, simulate_with_effects  # noqa: E402
from creep_online.model import CreepModel  # noqa: E402

#: Pairs a piezo user meets (docs/diagnostics.md, "Two effects at once", says why each).
PAIRS = (("hysteresis", "drift"), ("hysteresis", "second_creep"), ("leakage", "drift"),
         ("second_mode", "hysteresis"), ("delay", "drift"), ("nonlinear_gain", "leakage"))
#: Bands measured by default: with two effects the weaker one needs room above the noise.
DEFAULT_BANDS = ("3-10x", "10-100x")
#: A hidden effect counts as detectable when the best any fit can do passes the diagnosis' own rule at
#: least this often (``detectability``).
DETECT_PROBABILITY = 0.5
#: The plain likelihood-ratio test reported beside it (``detectable_lr``): false-alarm rate over the seven
#: partners an effect is tried with.
LR_FALSE_ALARM = 0.01 / 7


def make_pair_record(pair: tuple[str, str], band: tuple[float, float], seed: int) -> dict:
    """One randomized record hiding both effects of ``pair``; plus each effect's strength alone."""
    keys = [list(effect_names()).index(e) + 1 for e in pair]
    rec = draw_record(np.random.default_rng([seed, 92, *keys, int(10 * band[0])]), pair, band)
    p = rec["plant"]
    m = CreepModel.from_resonance(p["alpha"], p["fn"], p["zeta"], p["b"])
    t, u = np.arange(N) * H, rec["u"]
    rec["alone_over_noise"] = {e: fit_base(prepare(t, u, simulate_with_effects(m, t, u, {e: rec["params"][e]})))
                               .residual_rms / rec["noise"] for e in pair}
    rec["y_clean"] = simulate_with_effects(m, t, u, rec["params"])
    return rec


def given_other(pair: tuple[str, str], band: tuple[float, float], seed: int) -> dict[str, float]:
    """Each hidden effect's strength *given the other*: the best fit of the base model with the other effect
    to the record without noise, its residual RMS over the noise (``detectability``'s sharper lambda: what the
    other effect absorbs is removed too). A fit that stops short of its best overstates the strength, so an
    effect found undetectable by it is undetectable."""
    rec = make_pair_record(pair, band, seed)
    data = prepare(rec["t"], rec["u"], rec["y_clean"])
    base = fit_base(data)
    return {b: fit_extended(data, (a,), base).residual_rms / rec["noise"] for a, b in (pair, pair[::-1])}


@lru_cache(maxsize=None)
def extra_params(effect: str) -> int:
    """Parameters ``effect`` adds to the base model (nonlinear and linear: the dk of ``bic.evidence``), read off
    its design on a small record (no fit)."""
    t = np.arange(2000) * H
    u = np.where(t > 0.2, 1.0, 0.0) - 0.7 * (t > 1.0)
    data = prepare(t, u, u.copy())
    theta = base_theta(CreepModel.from_resonance(0.1, 20.0, 0.5, 1.0))

    def count(effects: tuple) -> int:
        design = Design(data, effects)
        th = np.concatenate([theta, _default_tail(design)])
        design.project(th)                    # sets col_names
        return len(th) + len(design.col_names)
    return count((effect,)) - count(())


def detectability(alone_over_noise: dict[str, float], n: int = N) -> dict:
    """Whether each hidden effect can be named next to the other, from its strength alone: a bound, not a fit.

    The diagnosis names an effect B next to A when the pair beats A alone by the BIC, i.e. the likelihood ratio
    LR = n ln(RSS_A / RSS_AB) exceeds ``EVIDENCE_THRESHOLD`` + dk ln n (dk: B's parameters). With white noise
    and the fit linearized, LR is noncentral chi-square with dk degrees of freedom and noncentrality
    lambda = |P s_B|^2 / sigma^2, where s_B is B's contribution to the output and P removes what the base model
    and A can absorb. The base model alone absorbs less than the base model with A (nested), so
    lambda <= n * strength^2, strength being ``alone_over_noise`` (the base model's best misfit of B alone, noise
    free, over the noise). ``p_named`` is P(LR > threshold) at that largest lambda: an upper bound on how often
    any fit, the hidden pair's own included, names B. B is ``detectable`` when p_named >= ``DETECT_PROBABILITY``;
    below it, saying "not detectable" is the right answer. ``detectable_lr``: the same for a plain LR test at
    false-alarm ``LR_FALSE_ALARM`` (a laxer test than the diagnosis allows itself; for the record)."""
    out = {}
    for effect, strength in alone_over_noise.items():
        dk = extra_params(effect)
        lam = n * strength ** 2
        p_bic = float(ncx2.sf(EVIDENCE_THRESHOLD + dk * math.log(n), dk, lam))
        p_lr = float(ncx2.sf(chi2.isf(LR_FALSE_ALARM, dk), dk, lam))
        out[effect] = {"dk": dk, "lambda_max": lam, "p_named": p_bic, "detectable": p_bic >= DETECT_PROBABILITY,
                       "detectable_lr": p_lr >= DETECT_PROBABILITY}
    return out


def annotate(row: dict) -> dict:
    """Add the detectability fields to a row (rows of runs made before they existed get them on ``--merge``):
    ``detectability`` per hidden effect, ``second_detectable`` (both effects pass the bound from their strength
    alone: the weaker one is the question), ``second_detectable_lr`` (the laxer LR test) and, where ``--given``
    measured each effect's strength given the other, ``detectability_given`` and ``second_detectable_given``
    (the sharper bound; elsewhere the same as ``second_detectable``)."""
    if "alone_over_noise" in row and "second_detectable" not in row:
        d = row["detectability"] = detectability(row["alone_over_noise"])
        row["second_detectable"] = all(v["detectable"] for v in d.values())
        row["second_detectable_lr"] = all(v["detectable_lr"] for v in d.values())
    if "given_other_over_noise" in row and "detectability_given" not in row:
        g = row["detectability_given"] = detectability(row["given_other_over_noise"])
        row["second_detectable_given"] = row["second_detectable"] and all(v["detectable"] for v in g.values())
    row.setdefault("second_detectable_given", row.get("second_detectable"))
    if "hidden_pair_evidence_over_best" not in row and "ranking" in row:
        row["hidden_pair_evidence_over_best"] = record_evidence(row)
    return row


def record_evidence(row: dict, n: int = N) -> float | None:
    """The BIC drop of the hidden pair (the combination when it is the pair, else the pair fitted directly)
    over the best single fit, from the row's numbers (no fit): what the record itself holds for naming both.
    At most ``EVIDENCE_THRESHOLD``: even the hidden pair, fitted, would not be significant, so the diagnosis
    cannot name it whatever its search does (a noise draw the a-priori bound cannot see)."""
    pair = list(row["params"])
    over = row["combination_over_noise"] if row["combination_right"] else row.get("hidden_pair_fitted_over_noise")
    if over is None:
        return None
    top, top_ev = row["ranking"][0][0], row["ranking"][0][1]
    ln_base_top = (top_ev + extra_params(top) * math.log(n)) / n        # ln(RSS_base / RSS_top)
    ln_base_pair = 2.0 * math.log(row["base_over_noise"] / over)
    dk = max(sum(extra_params(e) for e in pair) - extra_params(top), 1)
    return n * (ln_base_pair - ln_base_top) - dk * math.log(n)


def add_given(path: str, which: str) -> dict:
    """``--given``: each hidden effect's strength given the other (``given_other``) on the rows of a run that
    missed (``which`` = missed) or on all, then the table again."""
    doc = json.load(open(path))
    for key, rows in doc["rows"].items():
        pair, band = key.split("|")
        for r in rows:
            if "error" in r or (which == "missed" and r["both_named"] and r["at_floor"]):
                continue
            r["given_other_over_noise"] = given_other(tuple(pair.split("+")), BANDS[band], r["seed"])
            for k in ("detectability_given", "second_detectable_given"):
                r.pop(k, None)
            print(f"[given] {key} seed {r['seed']}: " + ", ".join(
                f"{e} {v:.3f}x" for e, v in r["given_other_over_noise"].items()), file=sys.stderr, flush=True)
    doc["table"] = table_of(doc["rows"])
    doc.setdefault("given_command", []).append("python " + shlex.join(sys.argv))
    return doc


def _compact(params: dict) -> dict:
    """Effect parameters for the JSON: hysteresis' 30 play weights as their sum and decay scale."""
    out = {}
    for name, q in params.items():
        if name == "hysteresis":
            r, w = np.asarray(q["r"]), np.asarray(q["w"])
            q = {"w_sum": float(w.sum()), "decay_of_range": float((r[0] - r[1]) / math.log(w[1] / w[0])
                                                                   / (2.0 * r[-1]))}
        out[name] = {k: float(v) for k, v in q.items()}
    return out


def forward_selection(d, noise: float, partners: str = "significant") -> dict:
    """Ablation (``--forward``; not what ``diagnose`` does): keep the best single effect and fit it together with
    every other significant candidate in turn (warm from its own fit); then keep the partner that won and fit it
    with every other candidate but the first in the same way. The pair with the largest BIC evidence of each round
    is reported (``pair`` after the first, ``pair_swap`` over both). ``diagnose`` instead pairs the two best
    *single* fits, which ranks the second effect by how well it explains the record alone. ``partners``:
    ``significant`` (the candidates significant alone) or ``all`` (every applicable candidate)."""
    sig = [c for c in d.candidates if c.significant]
    if not sig:
        return {"pair": None, "pair_swap": None}
    if partners == "all":
        sig = sig[:1] + [c for c in d.candidates if c is not sig[0]]
    if len(sig) < 2:
        return {"pair": None, "pair_swap": None}
    tried: dict = {}

    def round_(keep, others) -> tuple:
        for c in others:
            fit = fit_extended(d.data, (keep.effect, c.effect), d.base, warm=keep.fit)
            tried[(keep.effect, c.effect)] = (evidence(d.base, fit, d.data.n)[0], fit.residual_rms / noise)
        return max((k for k in tried if k[0] == keep.effect), key=lambda k: tried[k][0])

    first = round_(sig[0], sig[1:])
    partner = next(c for c in sig if c.effect == first[1])
    round_(partner, [c for c in sig if c.effect not in first])
    best = max(tried, key=lambda k: tried[k][0])
    return {"pair": list(first), "over_noise": tried[first][1], "pair_swap": list(best),
            "over_noise_swap": tried[best][1], "fits": len(tried),
            "tried": {"+".join(k): round(v[1], 3) for k, v in tried.items()}}


def run_one(pair: tuple[str, str], band: tuple[float, float], seed: int, forward: str | None = None) -> dict:
    rec = make_pair_record(pair, band, seed)
    noise = rec["noise"]
    t0 = time.perf_counter()
    try:
        d = diagnose((rec["t"], rec["u"], rec["y"]))
    except Exception as exc:     # a failure is a result of the table
        return {"seed": seed, "error": f"{type(exc).__name__}: {exc}", "seconds": time.perf_counter() - t0}
    seconds = time.perf_counter() - t0
    top = [c.effect for c in d.candidates if c.significant][:2]
    combo = d.combination
    combo_effects = list(combo.fit.effects) if combo is not None else None
    right = combo_effects is not None and set(combo_effects) == set(pair)
    over = combo.fit.residual_rms / noise if combo is not None else None
    singles = {c.effect: c for c in d.candidates if c.effect in pair}
    row = {"seed": seed, "ratio": rec["ratio"], "plant": rec["plant"], "params": _compact(rec["params"]),
           "alone_over_noise": rec["alone_over_noise"], "verdict": d.verdict, "top_two": top,
           "both_named": bool(right and combo.significant), "top_two_right": set(top) == set(pair),
           "verdict_in_pair": d.verdict in pair, "pairs_tried": len(d.pairs_tried),
           "combination": combo_effects, "combination_right": right, "combination_over_noise": over,
           "combination_significant": bool(combo.significant) if combo is not None else None,
           "at_floor": bool(right and over <= FLOOR),
           "singles_over_noise": {e: c.fit.residual_rms / noise for e, c in singles.items()},
           "hidden_ranks": {e: [c.effect for c in d.candidates].index(e) + 1 for e in singles},
           "ranking": [[c.effect, round(c.evidence, 1), c.significant] for c in d.candidates[:4]],
           "base_over_noise": d.base.residual_rms / noise, "seconds": seconds,
           "rivals": {"+".join(r["effects"]): round(r["behind"], 2) for r in d.pair_rivals}}
    # the hidden pair chosen, or named as a rival of the chosen pair (the record cannot tell them apart)
    row["named_or_rival"] = bool(combo is not None and combo.significant
                                 and (right or any(set(r["effects"]) == set(pair) for r in d.pair_rivals)))
    if not row["at_floor"] and len(singles) == 2:
        warm = min(singles.values(), key=lambda c: c.fit.rss).fit
        fit = fit_extended(d.data, pair, d.base, warm=warm)
        row["hidden_pair_fitted_over_noise"] = fit.residual_rms / noise
        best_single = min(singles.values(), key=lambda c: c.fit.rss).fit
        row["hidden_pair_fitted_evidence_over_single"] = evidence(best_single, fit, d.data.n)[0]
    if forward:
        t1 = time.perf_counter()
        f = row["forward"] = forward_selection(d, noise, forward)
        for tag in ("", "_swap"):
            f["right" + tag] = f["pair" + tag] is not None and set(f["pair" + tag]) == set(pair)
            f["at_floor" + tag] = bool(f["right" + tag] and f["over_noise" + tag] <= FLOOR)
        f["seconds"] = time.perf_counter() - t1
    return annotate(row)


def _count(rows: list[dict], n: int, pred) -> dict:
    k = sum(1 for r in rows if pred(r))
    return {"n": k, "of": n, "fraction": k / n if n else None}


def cell(rows: list[dict]) -> dict:
    ok = [annotate(r) for r in rows if "error" not in r]
    n = len(rows)
    overs = [r["combination_over_noise"] for r in ok if r["combination_right"]]
    weaker = [min(r["alone_over_noise"].values()) for r in ok]
    detectable = [r for r in ok if r["second_detectable_given"]]
    hidden = [r for r in ok if not r["second_detectable_given"]]
    held = [r for r in ok if _in_record(r)]
    out = {"records": n, "errors": n - len(ok),
           "both_named": _count(ok, n, lambda r: r["both_named"]),
           "combination_right": _count(ok, n, lambda r: r["combination_right"]),
           "at_floor": _count(ok, n, lambda r: r["at_floor"]),
           "verdict_in_pair": _count(ok, n, lambda r: r["verdict_in_pair"]),
           "named_or_rival": _count(ok, n, lambda r: r.get("named_or_rival", r["both_named"])),
           "right_with_rivals": _count(ok, n, lambda r: r["both_named"] and bool(r.get("rivals"))),
           "top_two_right": _count(ok, n, lambda r: r.get("top_two_right", r["both_named"])),
           "named_first": dict(Counter(r["verdict"] for r in ok).most_common()),
           "combination_over_noise_max": max(overs) if overs else None,
           "weaker_alone_over_noise_min": min(weaker) if weaker else None,
           "named_when_wrong": dict(Counter("+".join(r["combination"] or ["none"]) for r in ok
                                            if not r["both_named"]).most_common()),
           "missed": sorted(({"seed": r["seed"], "top_two": r["top_two"], "combination": r["combination"],
                             "combination_over_noise": r["combination_over_noise"]}
                            for r in ok if not r["at_floor"]), key=lambda w: w["seed"]),
           "seconds_p50": float(np.median([r["seconds"] for r in rows])),
           "second_detectable": _count(ok, n, lambda r: r["second_detectable"]),
           "second_detectable_lr": _count(ok, n, lambda r: r["second_detectable_lr"]),
           "second_detectable_given": _count(ok, n, lambda r: r["second_detectable_given"]),
           "both_named_where_detectable": _count(detectable, len(detectable), lambda r: r["both_named"]),
           "at_floor_where_detectable": _count(detectable, len(detectable), lambda r: r["at_floor"]),
           # below the bound the right answer is the stronger effect alone, no significant pair, no stand-in
           "right_where_undetectable": _count(hidden, len(hidden), _right_undetectable),
           # the record's own evidence: the hidden pair, chosen or fitted directly, beats the best single by the BIC
           "second_in_record": _count(ok, n, _in_record),
           "both_named_where_in_record": _count(held, len(held), lambda r: r["both_named"])}
    fw = [r for r in ok if "forward" in r]
    if fw:
        for key in ("right", "at_floor", "right_swap", "at_floor_swap"):
            out["forward_" + key] = _count(fw, len(fw), lambda r, k=key: r["forward"][k])
    return out


def _in_record(row: dict) -> bool:
    """Whether the record holds the evidence for both effects (``record_evidence`` above the threshold; a row
    named both has it by definition)."""
    ev = row.get("hidden_pair_evidence_over_best")
    return bool(row["both_named"] or (ev is not None and ev > EVIDENCE_THRESHOLD))


def _right_undetectable(row: dict) -> bool:
    """A record whose weaker effect is below the bound is diagnosed right when the verdict is the detectable
    effect and no significant combination names an effect outside the hidden pair (no stand-in, no false pair)."""
    det = row.get("detectability_given", row["detectability"])
    strong = [e for e, v in det.items() if v["detectable"] and row["detectability"][e]["detectable"]] or [*row["params"], "none"]
    false_pair = bool(row["combination_significant"]) and not set(row["combination"] or []) <= set(row["params"])
    return row["verdict"] in strong and not false_pair


def table_of(rows: dict) -> dict:
    table: dict = {}
    for key, r in rows.items():
        pair, band = key.split("|")
        table.setdefault(pair, {})[band] = cell(r)
    return table


def run(pairs: list[tuple[str, str]], bands: list[str], first_seed: int, records: int,
        forward: str | None = None) -> dict:
    seeds = range(first_seed, first_seed + records)
    started = time.perf_counter()
    rows: dict = {}
    for pair in pairs:
        for band in bands:
            rows[f"{'+'.join(pair)}|{band}"] = r = [run_one(pair, BANDS[band], s, forward) for s in seeds]
            c = cell(r)
            print(f"[pairs] {'+'.join(pair)} {band}: both named {c['both_named']['n']}/{records}, combination "
                  f"{c['combination_right']['n']}, at floor {c['at_floor']['n']}", file=sys.stderr, flush=True)
    return {"bench": "diagnose_pairs", "command": "python " + shlex.join(sys.argv), "records_per_cell": records,
            "first_seed": first_seed, "pairs": ["+".join(p) for p in pairs],
            "bands": {b: BANDS[b] for b in bands}, "floor_factor": FLOOR, "samples": N, "fs_hz": 1 / H,
            "table": table_of(rows), "load_average": list(os.getloadavg()),
            "elapsed_s": time.perf_counter() - started, "rows": rows}


def recheck(path: str, which: str) -> dict:
    """Rerun the records of an earlier run that missed, each beside its earlier row (a fix's effect on exactly
    the records it was aimed at; the whole table needs a full run)."""
    before = json.load(open(path))
    if before["bench"] == "diagnose_pairs_recheck":     # a recheck's rows: rerun what it left missed
        grouped: dict = {}
        for r in before["rows"]:
            grouped.setdefault(r["cell"], []).append(r["now"])
        before["rows"] = grouped
    pick = {"missed": lambda x: not x["at_floor"] or not x["both_named"],
            "above": lambda x: x["combination_over_noise"] > 1.08,
            "unsearched": lambda x: not x["both_named"] and x["pairs_tried"] == 1}[which]
    started = time.perf_counter()
    out = []
    for key, rows in before["rows"].items():
        pair, band = key.split("|")
        for old in (x for x in rows if pick(x)):
            new = run_one(tuple(pair.split("+")), BANDS[band], old["seed"])
            out.append({"cell": key, "seed": old["seed"], "now": new,
                        "before": {k: old[k] for k in ("combination", "combination_over_noise", "both_named",
                                                       "at_floor", "verdict", "verdict_in_pair", "pairs_tried")}})
            print(f"[recheck] {key} seed {old['seed']}: {'+'.join(old['combination'])} "
                  f"{old['combination_over_noise']:.2f}x -> {'+'.join(new.get('combination') or ['error'])} "
                  f"{new.get('combination_over_noise') or math.nan:.2f}x", file=sys.stderr, flush=True)
    gained = {k: sum(bool(r["now"].get(k)) for r in out) - sum(bool(r["before"][k]) for r in out)
              for k in ("both_named", "at_floor", "verdict_in_pair")}
    return {"bench": "diagnose_pairs_recheck", "command": "python " + shlex.join(sys.argv), "of": path,
            "which": which, "records": len(out), "gained": gained, "load_average": list(os.getloadavg()),
            "elapsed_s": time.perf_counter() - started, "rows": out}


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--records", type=int, default=30, help="records per pair and band (the issue's goal: >= 100)")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--pairs", default=None, help="comma-separated a+b pairs (default: PAIRS)")
    ap.add_argument("--bands", default=",".join(DEFAULT_BANDS), help=f"comma-separated, of {', '.join(BANDS)}")
    ap.add_argument("--merge", nargs="+", default=None, metavar="JSON",
                    help="merge the outputs of runs over consecutive seeds instead of running")
    ap.add_argument("--forward", action="store_true",
                    help="ablation: also forward-select the second effect given the first (forward_selection)")
    ap.add_argument("--partners", choices=("significant", "all"), default="significant",
                    help="with --forward: the partners tried (the candidates significant alone, or all)")
    ap.add_argument("--recheck", default=None, metavar="JSON",
                    help="rerun only the records of a previous run's JSON that missed: 'missed' (combination not "
                         "the hidden pair within 1.3x) or 'above' (combination above 1.08x the noise), e.g. "
                         "--recheck bench/results/diagnose_pairs.json --which missed")
    ap.add_argument("--which", choices=("missed", "above", "unsearched", "all"), default="missed",
                    help="with --recheck: which records ('unsearched': missed and never searched)")
    ap.add_argument("--given", default=None, metavar="JSON",
                    help="add each hidden effect's strength given the other to a run's rows (--which missed: "
                         "the rows that missed; all: every row) and count again")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if args.given:
        doc = add_given(args.given, "all" if args.which == "all" else "missed")
    elif args.recheck:
        doc = recheck(args.recheck, args.which)
    elif args.merge:
        doc = merge(args.merge, table_of)
        parts = [json.load(open(p)).get("command") for p in args.merge]
        doc["command"] = [c for part in parts for c in (part if isinstance(part, list) else [part])]
    else:
        pairs = [tuple(p.split("+")) for p in args.pairs.split(",")] if args.pairs else list(PAIRS)
        doc = run(pairs, args.bands.split(","), args.first_seed, args.records,
                  args.partners if args.forward else None)
    return emit(doc, args.out)


if __name__ == "__main__":
    main()
