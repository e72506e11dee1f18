"""Which evidence decided the verdict: the BIC ranking alone, confirmed by the hold physics, or against it.

The BIC ranking (``explain.py``) weighs whole extended fits; the hold physics
check (``holds.py``) looks only at how the output moves during settled holds
and only tells leakage, second creep and drift apart. When the two disagree,
the **BIC ranking wins**: it uses the whole record (transients too) and the full
extended models, the hold check a part of the record and linearised motions.
Measured (bench/bench_diagnose_physics.py, the bands bench's records of these
three effects, seeds 0-29 per band): the BIC verdict named the hidden effect in
270 of 270, the hold check confirmed it in 216, was inconclusive in 54 and
disagreed in none; letting the check overturn a BIC lead below 10 changed no
verdict. A disagreement is reported (``decided_by``, a warning), never hidden.
"""
from __future__ import annotations

from .holds import EFFECTS

#: ``decided_by`` values (stable, JSON).
BIC = "bic_ranking"
CONFIRMED = "bic_confirmed_by_physics"
DISAGREE = "bic_over_physics"


def verdict_basis(verdict: str, evidence: dict[str, float], physics: dict) -> dict:
    """``{decided_by, physics_verdict, agrees, text}`` for a verdict, the candidates' BIC evidence and the check.

    ``agrees`` is None when the hold check has nothing to say about this
    verdict (another effect, ``none``, or the check inconclusive).
    """
    pv = physics.get("verdict", "inconclusive")
    out = {"decided_by": BIC, "physics_verdict": pv, "agrees": None}
    if verdict not in EFFECTS:
        seen = f"; the hold check points to {pv}" if pv in EFFECTS else ""
        out["text"] = (f"BIC ranking (the hold physics check tells only {', '.join(EFFECTS)} apart{seen})"
                       if verdict != "none" else f"no candidate is significant by the BIC ranking{seen}")
        return out
    if pv == verdict:
        out.update(decided_by=CONFIRMED, agrees=True,
                   text=f"BIC ranking, confirmed by the hold physics: {physics.get('reason', '')}")
    elif pv in EFFECTS:
        gap = evidence.get(verdict, float("nan")) - evidence.get(pv, float("nan"))
        out.update(decided_by=DISAGREE, agrees=False, bic_lead=gap,
                   text=(f"BIC ranking, AGAINST the hold physics: the holds point to {pv} "
                         f"({physics.get('reason', '')}), the whole-record fits to {verdict} "
                         f"(BIC lead {gap:.4g} over {pv}); the verdict follows the BIC ranking"))
    else:
        out["text"] = f"BIC ranking alone (hold physics {pv}: {physics.get('reason', '')})"
    return out
