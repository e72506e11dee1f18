"""The exact Jacobian of a variable-projection residual (Golub and Pereyra 1973), any number of columns.

The extended fits minimise r(theta) = y - A(theta) c(theta), where the
linear coefficients c = A^+ y are solved in closed form at every theta. The
derivative of that *projected* residual in a nonlinear parameter theta_k,
with D_k = dA/dtheta_k, is

    dr/dtheta_k = -P D_k c - (A^+)^T D_k^T r,        P = I - A A^+

(the first term alone is Kaufman's approximation; both are kept here, so the
result is the Jacobian finite differences of r approximate, without their
evaluations). A is taken column-scaled and its pseudo-inverse through a thin
SVD (from a QR) truncated like the fit's own least squares (``RCOND``), so a
rank-deficient design gets the Jacobian of the solution the fit uses for
every full-rank part. ``identification._projected_jacobian`` is the one- and
two-column special case identify uses.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import qr

#: Singular values below RCOND x the largest (of the column-scaled design) are dropped, as in the fit's lstsq.
RCOND = 1e-10


def projected_jacobian(a: np.ndarray, moved: np.ndarray, pulled: np.ndarray,
                       curvature: np.ndarray | None = None) -> np.ndarray:
    """Jacobian (n, m) of r = y - A A^+ y for m nonlinear parameters, from D_k = dA/dtheta_k.

    ``a``: the (weighted) design (n, p); ``moved[k]`` = D_k c (c: the fit's
    coefficients), shape (m, n); ``pulled[k]`` = D_k^T r (r: the weighted
    residual), shape (m, p). Only these products of the D_k enter, so a caller
    may form them without the derivative columns themselves.

    ``curvature`` (p, p), for an inner problem that is not linear (a model
    bilinear in its "linear" parameters x, ``a`` its tangent dy/dx at the
    solution): H = (d a / d x)^T r, the residual-weighted second derivatives.
    The inner solution then moves with theta by (a^T a - H)^{-1} instead of
    a^+, and dr/dtheta_k = -D_k c - a (a^T a - H)^{-1} (D_k^T r - a^T D_k c),
    worked out on a's kept singular subspace.
    """
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    u, sv, vt = _thin_svd(a / scale)
    keep = sv > RCOND * (sv[0] if sv.size else 0.0)
    u, sv, vt = u[:, keep], sv[keep], vt[keep]
    moved = np.atleast_2d(moved)
    pulled = np.atleast_2d(pulled) / scale
    if curvature is None:
        projected = moved - (moved @ u) @ u.T                       # P D_k c
        back = ((pulled @ vt.T) / sv) @ u.T                         # (A^+)^T D_k^T r, A = U diag(sv) V^T S
        return -(projected + back).T
    v = vt / scale                                                  # x = S^-1 V w on the kept subspace
    inner = np.diag(sv ** 2) - v @ curvature @ v.T
    w = np.linalg.solve(inner, (pulled @ vt.T - (moved @ u) * sv).T).T
    return -(moved + (w * sv) @ u.T).T


def _thin_svd(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD of a tall matrix through its QR: LAPACK's divide and conquer on the tall matrix itself
    takes ~10x longer when a column is (numerically) dependent, as a hysteresis design's often are."""
    q, r = qr(a, mode="economic", check_finite=False)
    ur, sv, vt = np.linalg.svd(r)
    return q @ ur, sv, vt
