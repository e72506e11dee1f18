"""The evidence one fit carries over another: the drop of the Bayesian information criterion.

    evidence = N ln(RSS_base / RSS_fit) - dk ln N      (dk = extra parameters)

which is also the likelihood-ratio statistic ``N ln(RSS_base/RSS_fit)``
(chi-square with dk degrees of freedom under "nothing added") minus the BIC
penalty. One module so that the single-effect ranking (``explain``) and the
pair search (``pairs``) weigh fits the same way.
"""
from __future__ import annotations

import math

from scipy.stats import chi2

from . import extended as ext

#: BIC drop a fit needs over another to count (Kass-Raftery "very strong" is 10).
EVIDENCE_THRESHOLD = 10.0


def evidence(base: ext.ExtendedFit, fit: ext.ExtendedFit, n: int) -> tuple[float, float, float, int]:
    """(BIC drop, LR statistic, LR p-value, extra parameters) of ``fit`` against ``base``."""
    dk = max(fit.n_params - base.n_params, 1)
    rss0, rss1 = max(base.rss, 1e-300), max(min(fit.rss, base.rss), 1e-300)
    lr = n * math.log(rss0 / rss1)
    return lr - dk * math.log(n), lr, float(chi2.sf(lr, dk)), dk
