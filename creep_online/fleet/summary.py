"""What a fleet looks like: the spread of each parameter and the units that stand out.

The outlier rule (Iglewicz and Hoaglin's modified z-score) is robust, so the
outliers themselves do not widen the band that should catch them. For each of
alpha, fn, zeta and b, on log10 of the magnitude (the spread of a fleet is
multiplicative, and fn, zeta, b span decades across fleets):

    z = 0.6745 (x - median) / MAD,   flagged when |z| > 3.5,

with MAD the median absolute deviation from the median (0.6745 makes z a
standard normal score for normal data). Where more than half the records
share one value (MAD = 0), the mean absolute deviation stands in
(z = (x - median) / (1.2533 mean|x - median|)). A unit whose gain has the
minority sign is flagged on b as well (an actuator wired backwards). With
fewer than ``MIN_RECORDS`` identified records no outlier is flagged: a median
of three says little.
"""
from __future__ import annotations

from typing import Any

import numpy as np

#: Parameters whose distributions the summary shows and whose outliers it flags.
SUMMARY_PARAMETERS = ("alpha", "fn_hz", "zeta", "b")
#: |modified z| above which a record is an outlier (Iglewicz and Hoaglin's recommendation).
Z_THRESHOLD = 3.5
#: Fewest identified records for the outlier rule to apply.
MIN_RECORDS = 5


#: z = MAD_SCALE (x - median) / MAD is a standard normal score for normal data.
MAD_SCALE = 0.6745
#: Where MAD = 0: z = (x - median) / (MEAN_DEV_SCALE mean|x - median|).
MEAN_DEV_SCALE = 1.2533


def _spread(values: np.ndarray) -> tuple[float, float]:
    """(median, the deviation that is z = 1): MAD / 0.6745, else 1.2533 mean deviation, else 0 (no spread)."""
    med = float(np.median(values))
    dev = np.abs(values - med)
    mad = float(np.median(dev))
    if mad > 0:
        return med, mad / MAD_SCALE
    return med, MEAN_DEV_SCALE * float(np.mean(dev))


def robust_z(values: np.ndarray) -> np.ndarray:
    """Modified z-scores of ``values`` (the module's rule, on the values as given); 0 where no spread."""
    values = np.asarray(values, dtype=float)
    med, unit = _spread(values)
    if unit > 0:
        return (values - med) / unit
    return np.zeros_like(values)


def outlier_band(values: np.ndarray) -> tuple[float, float]:
    """(median, half-width) of the interval of ``values`` the rule flags nothing in (|z| <= ``Z_THRESHOLD``);
    half-width inf when the values have no spread (nothing is flagged)."""
    med, unit = _spread(np.asarray(values, dtype=float))
    return med, Z_THRESHOLD * unit if unit > 0 else float("inf")


def majority_sign(values: np.ndarray) -> float:
    """+1 or -1: the sign most values have (+1 on a tie); a gain of the other sign is an outlier on b."""
    values = np.asarray(values, dtype=float)
    return 1.0 if np.sum(values > 0) >= np.sum(values < 0) else -1.0


def identified(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows with a result (no error)."""
    return [r for r in rows if not r.get("error") and r.get("alpha") is not None]


def flag_outliers(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Set each row's ``outlier`` to the parameters it is flagged on ("fn_hz,b"); {id: {parameter: z}}."""
    good = identified(rows)
    for r in rows:
        r["outlier"] = ""
    if len(good) < MIN_RECORDS:
        return {}
    flags: dict[str, dict[str, float]] = {}
    for name in SUMMARY_PARAMETERS:
        x = np.array([r[name] for r in good], dtype=float)
        z = robust_z(np.log10(np.abs(x)))
        if name == "b":
            sign = np.sign(x)
            z = np.where(sign != majority_sign(x), np.inf * sign, z)
        for r, zi in zip(good, z):
            if abs(zi) > Z_THRESHOLD:
                flags.setdefault(r["id"], {})[name] = float(zi)
    for r in good:
        r["outlier"] = ",".join(flags.get(r["id"], {}))
    return flags


def distribution(values: np.ndarray) -> dict[str, float | int]:
    """n, median, MAD, 5th and 95th percentiles, min and max of ``values``."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return {"n": 0}
    med = float(np.median(values))
    p5, p95 = np.percentile(values, [5, 95])
    return {"n": int(values.size), "median": med, "mad": float(np.median(np.abs(values - med))),
            "p5": float(p5), "p95": float(p95), "min": float(values.min()), "max": float(values.max())}


def summarize(rows: list[dict[str, Any]], flags: dict[str, dict[str, float]] | None = None) -> dict[str, Any]:
    """The machine summary of a batch (``batch --json``): counts, distributions, outliers, failures."""
    good = identified(rows)
    flags = flag_outliers(rows) if flags is None else flags
    verdicts: dict[str, int] = {}
    for r in good:
        if r.get("verdict"):
            verdicts[r["verdict"]] = verdicts.get(r["verdict"], 0) + 1
    seconds = np.array([r["seconds"] for r in rows if r.get("seconds") is not None], dtype=float)
    return {
        "records": len(rows), "identified": len(good), "failed": len(rows) - len(good),
        "parameters": {name: distribution([r[name] for r in good]) for name in SUMMARY_PARAMETERS},
        "fit_percent": distribution([r["fit_percent"] for r in good]),
        "outlier_rule": f"|0.6745 (log10|x| - median) / MAD| > {Z_THRESHOLD} over the identified records "
                        f"(at least {MIN_RECORDS}); b of the minority sign",
        "outliers": [{"id": key, "z": z} for key, z in flags.items()],
        "failures": [{"id": r["id"], "error": r["error"]} for r in rows if r.get("error")],
        "with_warnings": sum(1 for r in good if r.get("warnings")),
        "verdicts": verdicts,
        "record_seconds": distribution(seconds) if seconds.size else {"n": 0},
    }
