"""The exact Jacobian of a variable-projection residual (Golub and Pereyra 1973), any number of columns.

The extended fits minimise r(theta) = y - A(theta) c(theta), where the
linear coefficients c = A^+ y are solved in closed form at every theta. The
derivative of that *projected* residual in a nonlinear parameter theta_k,
with D_k = dA/dtheta_k, is

    dr/dtheta_k = -P D_k c - (A^+)^T D_k^T r,        P = I - A A^+

(the first term alone is Kaufman's approximation; both are kept here, so the
result is the Jacobian finite differences of r approximate, without their
evaluations). A is taken column-scaled and its pseudo-inverse through a thin
SVD truncated like the fit's own least squares (``RCOND``), so a
rank-deficient design gets the Jacobian of the solution the fit uses for
every full-rank part. ``identification._projected_jacobian`` is the one- and
two-column special case identify uses.
"""
from __future__ import annotations

import numpy as np

#: Singular values below RCOND x the largest (of the column-scaled design) are dropped, as in the fit's lstsq.
RCOND = 1e-10


def projected_jacobian(a: np.ndarray, coef: np.ndarray, r: np.ndarray,
                       derivatives: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Jacobian (n, len(derivatives)) of r = y - A A^+ y from dA per nonlinear parameter.

    ``a``: the (weighted) design (n, p); ``coef``: its least-squares
    coefficients; ``r``: the (weighted) residual; ``derivatives[k]`` = (indices
    of the columns that depend on parameter k, their derivatives (n, len(indices)),
    weighted like ``a``).
    """
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    u, sv, vt = np.linalg.svd(a / scale, full_matrices=False)
    keep = sv > RCOND * (sv[0] if sv.size else 0.0)
    u, sv, vt = u[:, keep], sv[keep], vt[keep]
    jac = np.empty((a.shape[0], len(derivatives)))
    for k, (cols, d) in enumerate(derivatives):
        moved = d @ coef[cols]                       # D_k c
        moved -= u @ (u.T @ moved)                   # P D_k c
        g = np.zeros(a.shape[1])
        g[cols] = (d.T @ r) / scale[cols]            # S^-1 D_k^T r (A = U diag(sv) V^T S)
        jac[:, k] = -(moved + u @ ((vt @ g) / sv))
    return jac
