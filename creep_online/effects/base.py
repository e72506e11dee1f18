"""The ``Effect`` contract and the registry that finds effects (built in, registered, or from entry points).

An effect is one term added to the base model ``G(s) = b / (s^alpha (1 + a1 s + a2 s^2))``.
Where it acts is its *stage*; the forward model (``forward.simulate_with_effects``),
the extended fit (``creep_online.diagnostics.extended``), the diagnosis
(``creep_online.diagnostics.explain``) and the online compensation
(``creep_online.diagnostics.online``) all work through the stage's hooks, so an
effect is one module: a subclass of one of the stage classes below.

==================  =======================================================  ==========================
stage               what the effect does                                     hooks (forward, fit)
==================  =======================================================  ==========================
``input``           transforms the input before every linear path            ``transform_input``,
                    (hysteresis, nonlinear gain)                             ``design_rows``
``parallel``        a linear path beside the base model, with a gain         ``parallel_step``,
                    (second mode, second creep)                              ``unit_step`` (optional:
                                                                             ``unit_step_derivatives``)
``delay``           delays every linear path                                 ``delay_s``, ``fitted_delay``
``output_filter``   filters the sum of the linear paths (leakage)            ``filter_output``,
                                                                             ``filter_columns``
``additive``        adds a term that does not depend on the input            ``add_to_output``,
                    (drift, periodic disturbance)                            ``output_columns``
==================  =======================================================  ==========================

Every stage also has: ``nonlinear_params`` (the few parameters the fit searches,
with bounds; gains, weights and amplitudes are linear and solved in closed
form), ``start_values`` (the fit's starting grid), ``fitted_params`` (the
reported parameter dict), ``compensator`` (per-sample inverse for the online
estimator), ``applicable`` and ``signature`` (for the diagnosis),
``score_points`` (where the pair search's trigger tests the effect as a
partner; default from ``off`` and ``start_values``) and
``example_params`` (plausible values for simulated test records).

The registry: the eight built-in effects, then effects named by entry points
in the group ``creep_online.effects`` (as python-can finds its interfaces),
then effects added with :func:`register_effect`. Built-ins are named as
``module:Class`` strings and imported on first use, so this module imports no
effect.
"""
from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from enum import Enum
from importlib.metadata import entry_points
from typing import Any, Callable, Iterable

import numpy as np

from ..errors import ModelError

StepFn = Callable[[np.ndarray], np.ndarray]

#: Entry-point group a third-party package declares its effects in (``name = "module:Class"``).
ENTRY_POINT_GROUP = "creep_online.effects"
#: Most points of an effect's nonlinear parameters the pair search's trigger tries (``Effect.score_points``).
SCORE_POINTS = 64


class Stage(str, Enum):
    """Where an effect acts in the signal flow (the order of the members is the forward order)."""

    INPUT = "input"
    PARALLEL = "parallel"
    DELAY = "delay"
    OUTPUT_FILTER = "output_filter"
    ADDITIVE = "additive"


@dataclass(frozen=True)
class ParamSpec:
    """One nonlinear parameter on the fitting scale: ``"<effect>.<name>"``, bounds, and its 'switched off' value.

    ``off`` is the value at which the effect contributes nothing (e.g. a delay of
    0); the fit starts one candidate there so that the extended model is never
    worse than the base one. None: the effect has no such value (mid-range is used).
    """

    name: str
    lo: float
    hi: float
    off: float | None = None


@dataclass(frozen=True)
class FitView:
    """What an effect reads back from a solved extended-model design to report its parameters.

    ``theta``: nonlinear parameters by name; ``coef``: linear coefficients by
    column name; ``gain``: the base path's gain b (input-stage weights are
    reported relative to it); ``data``: the prepared record (``t``, ``u``,
    ``h``, ``u_range``, ``u_scale``); ``variant``: the effect's discrete variant
    (or None); ``harmonics``: harmonics per periodic term.
    """

    theta: dict[str, float]
    coef: dict[str, float]
    gain: float
    data: Any
    variant: str | None = None
    harmonics: int = 1
    solution: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- online compensators
class Compensator(ABC):
    """Per-sample inverse of one fitted effect, run by ``diagnostics.online.EffectCompensator``.

    ``start(v0, y0)`` is called once on the first sample with the input after
    the input stage and the measured output (the record starts in equilibrium
    there).
    """

    def start(self, v0: float, y0: float) -> None:
        """Remember the equilibrium the record starts in (default: nothing to remember)."""


class InputCompensator(Compensator):
    """Input and delay stages: maps the input sample to what the base model sees."""

    @abstractmethod
    def input(self, v: float) -> float:
        """The transformed (or delayed) input for this sample."""


class OutputCompensator(Compensator):
    """Parallel, output-filter and additive stages: removes the effect from the output sample."""

    @abstractmethod
    def output(self, y: float, v: float, n: int, t: float) -> float:
        """``y`` without this effect; ``v`` is the base model's input, ``n`` the sample index, ``t = n dt``."""


# --------------------------------------------------------------------------- the contract
class Effect(ABC):
    """One catalogue effect. Subclass one of the stage classes below, not this one."""

    #: Stable name (CLI, JSON, ``effects[name]`` dicts).
    name: str = ""
    #: Where it acts.
    stage: Stage
    #: The model term in one line (``--help`` texts and docs).
    term: str = ""
    #: Discrete alternatives the fit chooses between (e.g. hysteresis' initial state); () if none.
    variants: tuple[str, ...] = ()
    #: Key of ``fitted_params`` that holds the chosen variant (a warm start reuses it).
    variant_key: str = ""

    # -- the fit
    def nonlinear_params(self, data) -> list[ParamSpec]:
        """Nonlinear parameters (fitting scale) and their bounds for this record; [] if the effect is linear."""
        return []

    def start_values(self, data, peaks: list[float]) -> list[tuple[list[float], list[float]]]:
        """Per nonlinear parameter: (grid values, priority values) to start the fit from.

        ``peaks`` are the base residual's spectral peaks (Hz, uniform records).
        Priority values are always polished (a narrow line is found there and
        almost nowhere else); grid values only if they look promising.
        """
        return []

    def base_variants(self, base: np.ndarray, alpha_bounds: tuple[float, float]) -> list[np.ndarray]:
        """Extra starts for the base parameters (alpha, log10 fn, log10 zeta) this effect trades with."""
        return []

    def takeover_starts(self, base: np.ndarray) -> list[np.ndarray]:
        """Full starts (base then own parameters) for when this is the only effect with nonlinear parameters.

        For an effect that may take over what the base fit locked onto (a
        second resonance the base model found instead of the first).
        """
        return []

    def swapped(self, theta: np.ndarray, own: list[int]) -> np.ndarray | None:
        """``theta`` with this effect's parameters (at indices ``own``) exchanged with the base's they mirror.

        For a parallel path of the base path's own kind (a second creep
        exponent beside alpha, a second mode beside the first): an extended
        fit can settle with the two paths' roles exchanged, a local minimum
        the restart of the base parameters leaves only from the exchanged
        values. None (default): nothing to exchange.
        """
        return None

    def polished_starts(self, theta: np.ndarray, own: list[int], data) -> list[np.ndarray]:
        """Further starts derived from a short-polished start ``theta`` (own parameters at indices ``own``).

        For minima a polish cannot walk to from there (a mode's image across
        the Nyquist frequency); the final polish takes the best of them and
        the other finalists. Default: none.
        """
        return []

    def full_record_values(self, peaks: list[float]) -> dict[str, list[float]]:
        """Values of own parameters to retry on the whole record after exploring on a prefix."""
        return {}

    def score_points(self, data, peaks: list[float]) -> list[list[float]]:
        """Values of own nonlinear parameters (``nonlinear_params`` order) at which the pair search's trigger
        tests adding this effect to a fit that already explains the record (``diagnostics.score``).

        The test is the score statistic of the effect's parameters at the fitted model, linear ones at 0.
        Where every nonlinear parameter has an ``off`` value (a delay of 0) that is the null, and the
        statistic takes the parameters' own derivatives there; a parameter without one (a second mode's
        frequency: at gain 0 the record says nothing about it) is not identified under the null, so the
        statistic is the largest over these values (the trigger's threshold counts them). Default: the
        ``off`` point if there is one, then the fit's own starting grid (``start_values``: the grid values,
        and the priority values where every parameter has some, e.g. a residual peak), at most ``SCORE_POINTS``; ``[[]]``
        for an effect with no nonlinear parameters (its columns are the whole test).
        """
        specs = self.nonlinear_params(data)
        if not specs:
            return [[]]
        points = [[s.off for s in specs]] if all(s.off is not None for s in specs) else []
        starts = self.start_values(data, peaks)
        grids = [list(g) for g, _ in starts]
        prio = [list(p) for _, p in starts]
        for lists in (grids, prio):
            if all(lists):
                points += [list(row) for row in np.array(np.meshgrid(*lists, indexing="ij")).reshape(len(lists), -1).T]
        unique = list({tuple(np.round(p, 12)): p for p in points}.values())
        return unique[:SCORE_POINTS]

    @abstractmethod
    def fitted_params(self, fit: FitView) -> dict:
        """The reported parameters (``ExtendedFit.effect_params[name]``), a valid ``effects[name]`` dict."""

    # -- online
    @abstractmethod
    def compensator(self, dt: float, params: dict) -> Compensator:
        """The per-sample inverse of this effect with ``params``."""

    # -- the diagnosis
    def applicable(self, data) -> str | None:
        """None if the record can reveal this effect; else the reason it cannot."""
        return None

    def contradiction(self, params: dict, data, model: Any = None) -> str | None:
        """None if the fitted ``params`` agree with this effect's physics on this record; else why they do not
        (e.g. a "disturbance" locked to a periodic input). ``model``: the fit's base ``CreepModel`` (a second
        mode must lie above its resonance). ``diagnose`` never calls a contradicted fit significant, alone or
        in a pair. An override without ``model`` (written before it was passed) keeps working."""
        return None

    @abstractmethod
    def signature(self, params: dict, fit, base, where: dict, data) -> str:
        """The effect's fingerprint in the base residual, in words with the number that carries it."""

    # -- simulated records
    @abstractmethod
    def example_params(self, model, t: np.ndarray, u: np.ndarray, y_base: np.ndarray,
                       rng: np.random.Generator) -> dict:
        """Physically plausible parameters for this plant and input (``hil_sim.hidden_effects``)."""


class InputEffect(Effect):
    """Transforms the input before every linear path; its fit adds input rows (each with a linear weight).

    Several input effects act side by side, each adding its own term to the same input:
    ``v = u + sum_e (transform_input(u) - u)`` (``forward.transformed_input``), as their rows sit beside u in the fit.
    """

    stage = Stage.INPUT

    @abstractmethod
    def transform_input(self, v: np.ndarray, params: dict) -> np.ndarray:
        """The transformed input for a whole record."""

    def transform_before(self, v_pre: float, params: dict) -> float:
        """The transformed input before the record (default: unchanged)."""
        return v_pre

    @abstractmethod
    def design_rows(self, data, u: np.ndarray, variant: str | None, before: bool = False) -> np.ndarray:
        """Input rows beyond u itself (shape (k, len(u))); ``before``: ``u`` is the input before the record."""

    @abstractmethod
    def column_names(self) -> list[str]:
        """Names of the linear coefficients of ``design_rows``' rows."""

    def reported_solution(self, data, variant: str | None) -> Any:
        """None (default): the fit reports the search's linear solution. Otherwise an object whose ``rows(u,
        before=False)`` are the effect's input rows in the reported solution (``design_rows``' rows may be a
        reduced basis of them), ``names`` their coefficients' names, and ``solve(a, wy, gain, cols, gain_estimate,
        noise_var) -> (x, found)`` the weighted least squares ``a x ~ wy`` with the effect's own constraints and
        prior on its columns ``cols`` (``gain``: the base path's column on u); ``found`` reaches ``fitted_params``
        as ``FitView.solution[name]`` (hysteresis: the plays, an invertible loop, ``PlayWeights``)."""
        return None


class ParallelEffect(Effect):
    """A linear path beside the base model: ``gain x`` a unit-step response (the gain is linear)."""

    stage = Stage.PARALLEL

    @abstractmethod
    def parallel_step(self, params: dict) -> StepFn:
        """The path's step response, gain included, as a function of time since the step."""

    @abstractmethod
    def unit_step(self, theta: dict[str, float]) -> StepFn:
        """The path's unit-gain step response for nonlinear parameters ``theta``."""

    def unit_step_derivatives(self, theta: dict[str, float]) -> Callable[[np.ndarray], np.ndarray] | None:
        """Optional: d(unit_step)/d(own nonlinear parameters) as a function of tau, rows in ``nonlinear_params``
        order, shape (k, len(tau)).

        Override it to have the extended fit's Jacobian take this path
        exactly instead of one more evaluation per parameter (finite
        differences); not overridden (this default), the fit keeps the
        differences.
        """
        return None

    @property
    def gain_column(self) -> str:
        return f"{self.name}.gain"


class DelayEffect(Effect):
    """Delays every linear path."""

    stage = Stage.DELAY

    @abstractmethod
    def delay_s(self, params: dict) -> float:
        """The delay (s, >= 0) given by ``params``."""

    @abstractmethod
    def fitted_delay(self, theta: dict[str, float]) -> float:
        """The delay (s) for nonlinear parameters ``theta``."""


class OutputFilterEffect(Effect):
    """Filters the sum of the linear paths."""

    stage = Stage.OUTPUT_FILTER

    @abstractmethod
    def filter_output(self, t: np.ndarray, y: np.ndarray, params: dict) -> np.ndarray:
        """The filtered output (rows allowed)."""

    @abstractmethod
    def filter_columns(self, t: np.ndarray, cols: np.ndarray, theta: dict[str, float]) -> np.ndarray:
        """The design's dynamic columns (rows) filtered with nonlinear parameters ``theta``."""


class AdditiveEffect(Effect):
    """Adds a term that does not depend on the input (linear in its amplitudes)."""

    stage = Stage.ADDITIVE

    @abstractmethod
    def add_to_output(self, t: np.ndarray, y: np.ndarray, params: dict) -> np.ndarray:
        """``y`` plus the effect's term."""

    @abstractmethod
    def output_columns(self, t: np.ndarray, theta: dict[str, float], harmonics: int) -> tuple[list[np.ndarray], list[str]]:
        """(columns, their names): the term's regressors for nonlinear parameters ``theta``."""


# --------------------------------------------------------------------------- the registry
#: The catalogue, in forward order within each stage; imported on first use.
BUILTIN_EFFECTS: dict[str, str] = {
    "hysteresis": "creep_online.effects.hysteresis:Hysteresis",
    "nonlinear_gain": "creep_online.effects.nonlinear_gain:NonlinearGain",
    "second_mode": "creep_online.effects.second_mode:SecondMode",
    "drift": "creep_online.effects.drift:Drift",
    "leakage": "creep_online.effects.leakage:Leakage",
    "delay": "creep_online.effects.delay:Delay",
    "periodic_disturbance": "creep_online.effects.periodic_disturbance:PeriodicDisturbance",
    "second_creep": "creep_online.effects.second_creep:SecondCreep",
}


@dataclass
class _Registry:
    """Name -> effect (an instance once loaded, a ``module:attr`` spec before)."""

    entries: dict[str, Effect | str] = field(default_factory=lambda: dict(BUILTIN_EFFECTS))
    scanned: bool = False

    def scan(self) -> None:
        if self.scanned:
            return
        self.scanned = True
        for ep in entry_points(group=ENTRY_POINT_GROUP):
            self.entries.setdefault(ep.name, ep.value)


_REGISTRY = _Registry()


def discover_entry_points() -> tuple[str, ...]:
    """Re-read the ``creep_online.effects`` entry points (after installing a plug-in at run time); all names."""
    _REGISTRY.scanned = False
    _REGISTRY.scan()
    return effect_names()


def effect_names() -> tuple[str, ...]:
    """Every known effect: the built-in catalogue, then entry points, then registered ones."""
    _REGISTRY.scan()
    return tuple(_REGISTRY.entries)


def register_effect(effect: Effect | type[Effect] | str, *, replace: bool = False) -> Effect:
    """Add an effect (an instance, a class, or a ``"module:attr"`` string) and return the instance."""
    _REGISTRY.scan()
    obj = _instantiate(_load(effect) if isinstance(effect, str) else effect, str(effect))
    if obj.name in _REGISTRY.entries and not replace:
        raise ModelError(f"an effect named {obj.name!r} is already registered")
    _REGISTRY.entries[obj.name] = obj
    return obj


def unregister_effect(name: str) -> None:
    """Remove a registered or plug-in effect (the built-in catalogue stays)."""
    if name in BUILTIN_EFFECTS:
        raise ModelError(f"{name!r} is a built-in effect and cannot be removed")
    _REGISTRY.entries.pop(name, None)


def get_effect(name: str) -> Effect:
    """The effect called ``name`` (imported on first use); ModelError naming the catalogue if unknown."""
    _REGISTRY.scan()
    entry = _REGISTRY.entries.get(name)
    if entry is None:
        raise ModelError(f"unknown effect {name!r}; the catalogue is {', '.join(_REGISTRY.entries)}")
    if isinstance(entry, str):
        entry = _instantiate(_load(entry), entry)
        if entry.name != name:
            raise ModelError(f"effect plug-in {name!r} loads an effect named {entry.name!r}")
        _REGISTRY.entries[name] = entry
    return entry


def check_effect_names(names: Iterable[str]) -> None:
    """ModelError naming every unknown effect in ``names`` and the catalogue."""
    known = effect_names()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ModelError(f"unknown effect(s) {', '.join(unknown)}; the catalogue is {', '.join(known)}")


def in_forward_order(names: Iterable[str], stage: Stage | None = None) -> list[Effect]:
    """The named effects (optionally of one stage) in registry order, the order the forward model applies them."""
    wanted = set(names)
    return [get_effect(n) for n in effect_names() if n in wanted and (stage is None or get_effect(n).stage == stage)]


def _load(spec: str):
    module, _, attr = spec.partition(":")
    try:
        obj = importlib.import_module(module)
        for part in attr.split(".") if attr else []:
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise ModelError(f"cannot load effect {spec!r}: {exc}") from exc
    return obj


def _instantiate(obj, where: str) -> Effect:
    if isinstance(obj, type) and issubclass(obj, Effect):
        obj = obj()
    if not isinstance(obj, Effect) or not obj.name or not isinstance(getattr(obj, "stage", None), Stage):
        raise ModelError(f"{where} is not an Effect with a name and a stage")
    return obj


__all__ = ["Stage", "ParamSpec", "FitView", "Effect", "InputEffect", "ParallelEffect", "DelayEffect",
           "OutputFilterEffect", "AdditiveEffect", "Compensator", "InputCompensator", "OutputCompensator",
           "ENTRY_POINT_GROUP", "BUILTIN_EFFECTS", "effect_names", "get_effect", "register_effect",
           "unregister_effect", "discover_entry_points", "check_effect_names", "in_forward_order", "StepFn"]
