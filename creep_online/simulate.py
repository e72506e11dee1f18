"""Simulate the creep model for a sampled input.

Methods (all take a uniformly sampled input, held constant between samples as
a DAC does):

``exact`` (default)
    The sampled output of the continuous model for a zero-order-held input:
    the exact step response S (``discretize.step_response_grid``) superposed at
    every input change, ``y[n] = sum_k du_k S(t_n - t_k)``. Exact to ~1e-14.
``paper``
    Eq. 13 of the paper, the multi-term Grunwald-Letnikov recursion, exactly as
    FOMCON's ``lsim`` computes it (first order in h, O(N^2) with full memory).
``split``
    Fractional integral with exact ZOH weights, then the resonance discretized
    exactly for a piecewise-linear intermediate signal (first-order hold).

``memory`` (samples) truncates the fractional memory for ``paper`` and
``split`` (the short-memory principle); ``None`` keeps all of it.
"""
from __future__ import annotations

import math

import numpy as np

from .checks import count, real_array
from .errors import DataError
from .model import CreepModel

METHODS = ("exact", "paper", "split")
#: Above this many input changes the superposition switches to FFT convolution.
SPARSE_STEP_LIMIT = 64


#: Largest step-to-step variation (relative to the mean step) still taken as uniform sampling:
#: timestamps written with 8 significant digits jitter by ~1e-4 of the step.
UNIFORM_RTOL = 1e-2


def uniform_step(t: np.ndarray, rtol: float = UNIFORM_RTOL) -> float:
    """The mean sampling step of a uniform time vector, or DataError saying why it is not uniform."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise DataError("need at least 2 time samples")
    if not np.all(np.isfinite(t)):
        raise DataError("time contains NaN or inf")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise DataError(f"time is not strictly increasing (first at sample {int(np.argmax(dt <= 0)) + 1})")
    h = (t[-1] - t[0]) / (t.size - 1)
    worst = float(np.max(np.abs(dt - h)))
    if worst > rtol * h:
        raise DataError(f"time is not uniformly sampled (step varies by {worst / h:.2%}, more than "
                        f"{rtol:.0%}); resample to a uniform grid first")
    return float(h)


def increments(u: np.ndarray) -> np.ndarray:
    """u[k] - u[k-1] with u[-1] taken as 0: ``np.diff(u, prepend=0.0)`` bit for bit, without the
    concatenated copy of u (that path cost ~1 ms per 100,000 samples against ~0.05 ms)."""
    u = np.asarray(u, dtype=float)
    du = np.empty_like(u)
    if u.size:
        du[0] = u[0] - 0.0
        np.subtract(u[1:], u[:-1], out=du[1:])
    return du


def input_changes(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(indices, sizes) of the non-zero increments of u, with u[-1] taken as 0."""
    du = increments(u)
    idx = np.flatnonzero(du)
    return idx.astype(np.int64), du[idx]


def fast_length(n: int) -> int:
    """Smallest 2^a 3^b 5^c >= n: an FFT length numpy transforms quickly."""
    best = 1 << max(int(n - 1).bit_length(), 0)
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            v = p35
            while v < n:
                v *= 2
            best = min(best, v)
            p35 *= 3
        p5 *= 5
    return best


def causal_convolve(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """The first len(x) samples of the full convolution x * kernel, by real FFT.

    numpy's FFT rather than scipy.signal.fftconvolve: importing scipy.signal
    costs about a second, which a command-line call pays every time.
    """
    n = x.shape[0]
    m = fast_length(n + min(kernel.shape[0], n) - 1)
    k = kernel[:n]
    return np.fft.irfft(np.fft.rfft(x, m) * np.fft.rfft(k, m), m)[:n]


#: The last inputs and their changes: fits simulate the same input dozens of times (identify alternates
#: between a record's input and its first samples), and comparing it with a copy is cheaper than a
#: diff + nonzero over it (a copy, so in-place edits are seen). Most recent first.
_LAST_CHANGES: list = []
_CACHED_INPUTS = 2


def _changes_cached(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """input_changes(u), reused when u equals one of the last inputs seen."""
    for k, (copy, changes) in enumerate(_LAST_CHANGES):
        if copy.shape == u.shape and np.array_equal(copy, u):
            _LAST_CHANGES.insert(0, _LAST_CHANGES.pop(k))
            return changes
    changes = input_changes(u)
    _LAST_CHANGES.insert(0, (np.array(u, dtype=float), changes))
    del _LAST_CHANGES[_CACHED_INPUTS:]
    return changes


def superpose(step_response: np.ndarray, u: np.ndarray) -> np.ndarray:
    """ZOH response from a unit-step response: sparse sum for few changes, FFT for many."""
    from . import kernels  # numba: loaded on first use, so that importing the package stays light
    idx, size = _changes_cached(u)
    n = u.shape[0]
    if idx.size <= SPARSE_STEP_LIMIT:
        return kernels.superpose_steps(step_response, idx, size, n)
    du = np.zeros(n)
    du[idx] = size
    return causal_convolve(du, step_response)


def superpose_rows(step_responses: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``superpose`` of every row of ``step_responses`` (k, >= len(u)) for one input: (k, len(u)).

    The input's changes are found once; each row's result equals ``superpose``'s.
    """
    from . import kernels
    idx, size = _changes_cached(u)
    n = u.shape[0]
    if idx.size <= SPARSE_STEP_LIMIT:
        return kernels.superpose_steps_rows(step_responses, idx, size, n)
    du = np.zeros(n)
    du[idx] = size
    kernels_ = step_responses[:, :n]
    m = fast_length(n + kernels_.shape[1] - 1)     # as causal_convolve: the input's spectrum once for all rows
    return np.fft.irfft(np.fft.rfft(du, m)[None, :] * np.fft.rfft(kernels_, m, axis=1), m, axis=1)[:, :n]


def simulate(model: CreepModel, t: np.ndarray, u: np.ndarray, method: str = "exact",
             memory: int | None = None) -> np.ndarray:
    """Output y(t) of ``model`` for the input u sampled on the uniform grid t (zero initial state)."""
    if not isinstance(model, CreepModel):
        raise DataError(f"simulate() needs a CreepModel, got {type(model).__name__}")
    if not (isinstance(method, str) and method in METHODS):
        raise DataError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if memory is not None:
        memory = count(memory, "memory (samples of fractional memory)")
        if method == "exact":
            raise DataError("the exact method has full memory; 'memory' applies to paper and split")
    t = real_array(t, "t")
    u = np.ascontiguousarray(real_array(u, "u"))
    h = uniform_step(t)
    if u.shape != np.shape(t):
        raise DataError(f"t and u differ in length ({np.size(t)} vs {u.size})")
    if not np.all(np.isfinite(u)):
        raise DataError("input u contains NaN or inf")
    from . import kernels
    from .discretize import step_response_grid
    if method == "exact":
        if memory is not None:
            raise ValueError("the exact method has full memory; 'memory' applies to paper and split")
        s = step_response_grid(model.alpha, model.a1, model.a2, h, u.size)
        return model.b * superpose(s, u)
    mem = -1 if memory is None else int(memory)
    if method == "paper":
        return model.b * kernels.gl_paper(u, h, model.alpha, model.a1, model.a2, mem)
    if method == "split":
        return model.b * split_form(model, h, u, memory)
    raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")


def fractional_integral(u: np.ndarray, h: float, alpha: float, memory: int | None = None) -> np.ndarray:
    """z = D^-alpha u at the samples for a zero-order-held u: exact (full memory) or truncated."""
    from . import kernels
    n = u.size
    length = n if memory is None else min(n, int(memory) + 1)
    c = kernels.zoh_integral_weights(alpha, h, math.gamma(1.0 + alpha), length)
    if memory is None and n > 2048:
        return causal_convolve(u, c)
    return kernels.fractional_integral_zoh(u, c)


def split_form(model: CreepModel, h: float, u: np.ndarray, memory: int | None = None) -> np.ndarray:
    """Split form with gain 1: exact ZOH fractional integral, then the FOH-exact resonance."""
    from . import kernels
    from .discretize import foh_matrices
    z = fractional_integral(u, h, model.alpha, memory)
    phi, g0, g1 = foh_matrices(model.a1, model.a2, h)
    return kernels.resonance_foh(z, phi, g0, g1, h)


def step_response(model: CreepModel, t: np.ndarray) -> np.ndarray:
    """Exact unit-step response on a uniform grid t starting at 0."""
    from .discretize import step_response_grid
    if not isinstance(model, CreepModel):
        raise DataError(f"step_response() needs a CreepModel, got {type(model).__name__}")
    h = uniform_step(real_array(t, "t"))
    return model.b * step_response_grid(model.alpha, model.a1, model.a2, h, np.size(t))
