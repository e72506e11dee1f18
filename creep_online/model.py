"""The fractional-order creep model G(s) = b / (s^alpha (1 + a1 s + a2 s^2)), and its extension by effects.

The parameters are kept plain (scikit-learn style): four floats, validated once,
and everything else (natural frequency, damping, creep law, frequency response)
is derived from them on demand. ``ExtendedModel`` is the same model plus
effects from ``creep_online.effects`` (docs/diagnostics.md); the fitter that
finds one from data lives above, in ``creep_online.diagnostics.extended``.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from .effects.base import check_effect_names
from .errors import ModelError

# --------------------------------------------------------------------------- alpha search bounds
# alpha lives in the open interval (0, 1) (``CreepModel`` rejects the ends). Each estimator searches a
# closed sub-interval of it. The three intervals differ, and are kept as they are because a bounded
# trust-region (or grid) search follows a different path when a bound moves: changing one would change
# the measured numbers (docs/diagnostics.md, docs/online.md, bench/results/).

#: ``identify``: layer 1 (alpha from the creep tail) and the joint polish. Almost the whole interval: the
#: creep-law fit stays well conditioned for a nearly elastic actuator (t^1e-4 still rises by 0.14 % over
#: six decades) and near an integrator.
IDENTIFY_ALPHA_BOUNDS = (1e-4, 0.999)
#: The extended-model fit (``diagnostics.extended``): alpha is one of several nonlinear parameters there,
#: and below 1e-3 the s^-alpha path is a pure gain within the noise of any record it sees (t^1e-3 rises
#: by 1.4 % over six decades), so a lower bound would only add a flat valley to the search.
EXTENDED_FIT_ALPHA_BOUNDS = (1e-3, 0.999)
#: The online estimator's default ``alpha_bounds``: 0.95 is where its sum-of-exponentials fractional
#: integral is validated (error < 1.2e-4 up to alpha = 0.95, ``online/soe.py``); 0.002 the smallest alpha
#: of its start-up grid's range.
ONLINE_ALPHA_BOUNDS = (0.002, 0.95)
#: The online estimator's two Remark-3 strategies (``OnlineEstimator(refit=...)``, ``--refit``), default first:
#: re-fit over the forgetting window, or carry on recursively with the newest estimate (docs/online.md).
ONLINE_REFITS = ("window", "recursive")


@dataclass(frozen=True)
class CreepModel:
    """Creep (``s^-alpha``) in series with the first mechanical resonance.

    ``alpha`` is the creep exponent (0 < alpha < 1), ``a1`` and ``a2`` the
    coefficients of ``1 + a1 s + a2 s^2`` (both > 0) and ``b`` the gain (any
    non-zero real).
    """

    alpha: float
    a1: float
    a2: float
    b: float = 1.0

    def __post_init__(self) -> None:
        for name in ("alpha", "a1", "a2", "b"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.floating, np.integer)) or not math.isfinite(value):
                raise ModelError(f"{name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if not 0.0 < self.alpha < 1.0:
            raise ModelError(f"alpha must satisfy 0 < alpha < 1, got {self.alpha}")
        if self.a1 <= 0.0:
            raise ModelError(f"a1 must be > 0, got {self.a1}")
        if self.a2 <= 0.0:
            raise ModelError(f"a2 must be > 0, got {self.a2}")
        if self.b == 0.0:
            raise ModelError("b must be non-zero")

    # ------------------------------------------------------------------ derived
    @classmethod
    def from_resonance(cls, alpha: float, fn: float, zeta: float, b: float = 1.0) -> "CreepModel":
        """Build the model from the natural frequency ``fn`` (Hz) and damping ``zeta``."""
        if fn <= 0 or zeta <= 0:
            raise ModelError(f"fn and zeta must be > 0, got fn={fn}, zeta={zeta}")
        wn = 2.0 * math.pi * fn
        return cls(alpha=alpha, a1=2.0 * zeta / wn, a2=1.0 / wn**2, b=b)

    @property
    def wn(self) -> float:
        """Natural angular frequency (rad/s)."""
        return 1.0 / math.sqrt(self.a2)

    @property
    def fn(self) -> float:
        """Natural frequency (Hz): 1 / (2 pi sqrt(a2))."""
        return self.wn / (2.0 * math.pi)

    @property
    def zeta(self) -> float:
        """Damping ratio: a1 / (2 sqrt(a2))."""
        return self.a1 / (2.0 * math.sqrt(self.a2))

    @property
    def settling_time(self) -> float:
        """Time (s) for the resonance transient to decay to ~1e-3 of its start.

        For an under-damped pair the envelope decays as exp(-zeta wn t); for an
        over-damped pair the slower pole sets the pace.
        """
        zeta, wn = self.zeta, self.wn
        rate = zeta * wn if zeta < 1.0 else wn * (zeta - math.sqrt(zeta * zeta - 1.0))
        return math.log(1e3) / rate

    def poles(self) -> np.ndarray:
        """Poles of 1 + a1 s + a2 s^2 (complex)."""
        return np.roots([self.a2, self.a1, 1.0]).astype(complex)

    def creep(self, t: np.ndarray | float, amplitude: float = 1.0) -> np.ndarray:
        """Creep law y = amplitude b t^alpha / Gamma(1 + alpha): the step response for t >> t_c."""
        t = np.asarray(t, dtype=float)
        return amplitude * self.b * np.power(np.maximum(t, 0.0), self.alpha) / math.gamma(1.0 + self.alpha)

    def frequency_response(self, f: np.ndarray | float) -> np.ndarray:
        """Complex G(j 2 pi f) for frequencies f in Hz (f > 0)."""
        s = 2j * np.pi * np.asarray(f, dtype=float)
        return self.b / (s**self.alpha * (1.0 + self.a1 * s + self.a2 * s * s))

    def with_effects(self, **effects: dict) -> "ExtendedModel":
        """This model extended by effects, e.g. ``model.with_effects(delay={"delay_s": 2e-3})``."""
        return with_effects(self, **effects)

    def params(self) -> dict[str, float]:
        """The four parameters as a plain dict (JSON-ready)."""
        return asdict(self)

    def describe(self) -> dict[str, float]:
        """Parameters plus the derived quantities a control engineer reads first."""
        return {**self.params(), "fn_hz": self.fn, "zeta": self.zeta}

    def __str__(self) -> str:
        return (f"CreepModel(alpha={self.alpha:.6g}, a1={self.a1:.6g}, a2={self.a2:.6g}, "
                f"b={self.b:.6g}; fn={self.fn:.4g} Hz, zeta={self.zeta:.3g})")


@dataclass(frozen=True)
class ExtendedModel:
    """A base CreepModel plus effects: ``ExtendedModel(model, {"delay": {"delay_s": 1e-3}})``.

    ``effects`` maps effect names (``creep_online.effects.effect_names()``) to
    their parameter dicts; ``offset`` is added to the output.
    """

    base: CreepModel
    effects: dict = field(default_factory=dict)
    offset: float = 0.0

    def simulate(self, t: np.ndarray, u: np.ndarray, u_pre: float | None = 0.0,
                 t_pre: float | None = None) -> np.ndarray:
        """Output for a zero-order-held input (from rest by default, like ``simulate``)."""
        from .effects.forward import simulate_with_effects
        return simulate_with_effects(self.base, t, u, self.effects, offset=self.offset, u_pre=u_pre, t_pre=t_pre)

    def with_effects(self, **effects: dict) -> "ExtendedModel":
        """A copy with more (or replaced) effects."""
        check_effect_names(effects)
        return ExtendedModel(self.base, {**self.effects, **effects}, self.offset)


def with_effects(model: CreepModel, **effects: dict) -> ExtendedModel:
    """``with_effects(model, delay={"delay_s": 2e-3})``: the model extended by effects (ModelError if unknown)."""
    check_effect_names(effects)
    return ExtendedModel(model, dict(effects))


#: How a fit treats a record that does not start at rest (``FittedModel.initial_state``): ``identify`` adds
#: the free response of an unknown initial state (``creep_online.initial_state``) where the data call for
#: it; the extended fit (``fit``, ``diagnose``) reads the record as starting from rest or in equilibrium at
#: its first input, whichever the start rule (``creep_online.diagnostics.start``) picks.
INITIAL_STATE_METHODS = ("free_response", "reading")


@dataclass(frozen=True)
class FittedModel:
    """A model as a fit found it: the extended model and the conventions of the record it was fitted under.

    ``model`` holds the base parameters, the effects and ``offset``, the output at rest.
    ``input_offset`` is the input the plant rests at before a record (the jump to the first input
    happens at the first sample); None: the plant rests at the record's own first input (the model
    sees u - u[0]). ``initial_state`` says how the fit treated a record that did not start at rest
    (``INITIAL_STATE_METHODS``); ``compare`` estimates a new record's initial state the same way.
    ``units`` names the units of t, u and y where the data said them; ``fitted`` describes the fit
    (its command, record, samples and fit percent); ``version`` the creep_online that made it.
    """

    model: ExtendedModel
    input_offset: float | None = 0.0
    initial_state: str = "reading"
    units: dict = field(default_factory=dict)
    fitted: dict = field(default_factory=dict)
    version: str = ""

    def __post_init__(self) -> None:
        if self.initial_state not in INITIAL_STATE_METHODS:
            raise ModelError(f"initial_state must be one of {', '.join(INITIAL_STATE_METHODS)}, "
                             f"got {self.initial_state!r}")
        if self.input_offset is not None and not (isinstance(self.input_offset, (int, float, np.floating))
                                                  and math.isfinite(self.input_offset)):
            raise ModelError(f"input_offset must be a finite number or None, got {self.input_offset!r}")

    @property
    def base(self) -> CreepModel:
        return self.model.base

    @property
    def effects(self) -> dict:
        return self.model.effects

    @property
    def offset(self) -> float:
        return self.model.offset

    def simulate(self, t: np.ndarray, u: np.ndarray, t_pre: float | None = None) -> np.ndarray:
        """The output for input u at times t under the model's conventions: the plant at rest at
        ``input_offset`` before the first sample (or in equilibrium at u[0] when it is None), output
        ``offset`` there. ``t_pre``: when the input jumped to u[0], if before t[0]."""
        return self.model.simulate(t, u, u_pre=self.input_offset, t_pre=t_pre)
