"""Model-discrepancy effects as extensions of the forward model, one module per effect (docs/diagnostics.md).

Eight built-in effects with stable names, each a term added to
``G(s) = b / (s^alpha (1 + a1 s + a2 s^2))``:

============================  ==================================================  ==========================================
name                          model term                                          parameters (``effects[name]`` dict)
============================  ==================================================  ==========================================
``hysteresis``                Prandtl-Ishlinskii play operators on the input       ``r`` thresholds, ``w`` weights:
                                                                                  ``v = u + sum_i w_i play_{r_i}[u]``
``nonlinear_gain``            static polynomial on the input                      ``k2``, ``k3``: ``v = u + k2 u^2 + k3 u^3``
``second_mode``               parallel ``g / (1 + a1' s + a2' s^2)``              ``gain``, ``fn_hz``, ``zeta``
``drift``                     ``rate * (t - t0) + offset``                        ``rate``, ``offset``
``leakage``                   ``tau s / (1 + tau s)`` on the output               ``tau_s``
``delay``                     ``e^{-s d}`` (fractional delays allowed)            ``delay_s``
``periodic_disturbance``      sinusoid(s) ``sum_k A_k sin(2 pi k f t + phi_k)``   ``f_hz``, ``amplitude``, ``phase`` (scalars
                                                                                  or lists, one per harmonic)
``second_creep``              parallel ``c / s^alpha2``                           ``gain``, ``alpha2``
============================  ==================================================  ==========================================

``base`` holds the ``Effect`` contract and the registry (more effects come
from entry points in the group ``creep_online.effects`` or from
``register_effect``); ``forward.simulate_with_effects`` is the forward model;
``responses`` the step responses and their superposition shared by every
linear path. The names below are re-exported so that
``from creep_online.effects import ...`` keeps working.
"""
from .._lazy import lazy_attributes
from .base import (BUILTIN_EFFECTS, ENTRY_POINT_GROUP, AdditiveEffect, Compensator, DelayEffect, Effect, FitView,
                   InputCompensator, InputEffect, OutputCompensator, OutputFilterEffect, ParallelEffect, ParamSpec,
                   Stage, check_effect_names, discover_entry_points, effect_names, get_effect, in_forward_order,
                   register_effect, unregister_effect)
from .hysteresis import (HYSTERESIS_COMPONENTS, HYSTERESIS_THRESHOLDS, INITIAL_STATES, SLOPE_FLOOR, hysteresis_input,
                         inverse_params, invert_hysteresis, last_direction, loop_width, partial_slopes, pi_inverse,
                         play_operators)
from .nonlinear_gain import polynomial_input
from .periodic_disturbance import periodic_columns

# The forward model and the step responses load scipy and numba (~1 s): they load on first use,
# so that importing the model (and the CLI's --help) stays light.
_LAZY = {"simulate_with_effects": "forward", "leakage_filter": "leakage", **{name: "responses" for name in (
    "MAX_PAIRS", "MULTIGRID_POINTS", "MULTIGRID_RATIO", "StepFn", "Superposer", "base_step_at", "base_step_grid",
    "creep_step", "delayed_grid", "delayed_grid_slope", "is_uniform", "resonance_step")}}

__getattr__ = lazy_attributes(__name__, _LAZY)


#: The built-in catalogue (stable names, CLI and JSON). ``effect_names()`` adds plug-ins.
EFFECTS: tuple[str, ...] = tuple(BUILTIN_EFFECTS)

__all__ = [
    "EFFECTS", "simulate_with_effects",
    "Effect", "InputEffect", "ParallelEffect", "DelayEffect", "OutputFilterEffect", "AdditiveEffect", "Stage",
    "ParamSpec", "FitView", "Compensator", "InputCompensator", "OutputCompensator",
    "ENTRY_POINT_GROUP", "BUILTIN_EFFECTS", "effect_names", "get_effect", "register_effect", "unregister_effect",
    "discover_entry_points", "check_effect_names", "in_forward_order",
    "HYSTERESIS_COMPONENTS", "HYSTERESIS_THRESHOLDS", "INITIAL_STATES", "play_operators", "hysteresis_input",
    "loop_width", "last_direction", "SLOPE_FLOOR", "partial_slopes", "pi_inverse", "inverse_params",
    "invert_hysteresis",
    "polynomial_input", "leakage_filter", "periodic_columns",
    "MAX_PAIRS", "MULTIGRID_POINTS", "MULTIGRID_RATIO", "StepFn", "Superposer", "is_uniform", "creep_step",
    "resonance_step", "base_step_grid", "base_step_at", "delayed_grid", "delayed_grid_slope",
]
