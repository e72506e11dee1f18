"""The evidence one fit carries over another: the drop of the Bayesian information criterion.

    evidence = N ln(RSS_base / RSS_fit) - dk ln N      (dk = extra parameters)

which is also the likelihood-ratio statistic ``N ln(RSS_base/RSS_fit)``
(chi-square with dk degrees of freedom under "nothing added") minus the BIC
penalty. One module so that the single-effect ranking (``explain``) and the
pair search (``pairs``) weigh fits the same way.
"""
from __future__ import annotations

import math

from scipy.special import chdtrc

from . import extended as ext

#: BIC drop a fit needs over another to count (Kass-Raftery "very strong" is 10).
EVIDENCE_THRESHOLD = 10.0


def chi2_sf(x: float, dk: float) -> float:
    """P(chi-square with ``dk`` degrees of freedom > x): ``scipy.stats.chi2.sf(x, dk)`` for scalars (its checks
    around the same ``scipy.special.chdtrc``), without importing scipy.stats (~19 MB resident)."""
    if not dk > 0 or math.isnan(x):
        return math.nan
    if x <= 0.0:
        return 1.0
    return 0.0 if x == math.inf else float(chdtrc(dk, x))


def evidence(base: ext.ExtendedFit, fit: ext.ExtendedFit, n: int) -> tuple[float, float, float, int]:
    """(BIC drop, LR statistic, LR p-value, extra parameters) of ``fit`` against ``base``."""
    dk = max(fit.n_params - base.n_params, 1)
    rss0, rss1 = max(base.rss, 1e-300), max(min(fit.rss, base.rss), 1e-300)
    lr = n * math.log(rss0 / rss1)
    return lr - dk * math.log(n), lr, chi2_sf(lr, dk), dk
