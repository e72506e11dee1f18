"""The online estimator's tunables in one frozen, validated object (``OnlineSettings``).

``OnlineEstimator(dt, settings=None)`` takes the defaults; pass an ``OnlineSettings`` to change one, e.g.
``OnlineSettings(quality=QualitySettings(good_ratio=1.5))`` or ``OnlineSettings().replace(quality={"good_ratio":
1.5})``. The object is stored verbatim (``get_params``, ``set_params``, ``clone``), so a changed setting travels with
the estimator's parameters. The constructor's arguments (``window_s``, ``outlier_gate``, ...) are what a user sets per
plant; these are the rules' thresholds, each documented beside its section, each checked when built (``DataError``).

Sections: ``startup`` (buffer and start-up search), ``input_gate`` (the glitch gate on the input), ``recovery``
(internal faults and outages), ``quality`` (what ``OnlineEstimate.quality`` says), ``memory`` (windows and history),
and ``trackers``: the trackers' own settings (``None``: their defaults).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from ..errors import DataError
from .policy.limits import DeterminedLimits
from .trackers.settings import TrackerSettings

#: Effects the estimator can estimate with the creep (``OnlineEstimator(effects=...)``): the Prandtl-Ishlinskii loop
#: on the input.
ONLINE_EFFECTS = ("hysteresis",)


def check_effects(effects, refit: str) -> None:
    """``OnlineEstimator(effects=...)``: a tuple of names from ``ONLINE_EFFECTS``, with the window tracker (the
    hysteresis columns are columns of its statistics). One-line ``DataError`` otherwise.

    With ``"hysteresis"`` the window has ``MemorySettings.hysteresis_operators`` play operators whose thresholds the start-up
    buffer's input range sets (the batch fit's rule), their outputs filtered by the plant as regressors of the
    window's fit, their weights tracked with alpha, a1, a2 and b; the window then models no drift."""
    if isinstance(effects, str) or not isinstance(effects, (tuple, list)) or not all(
            isinstance(e, str) and e in ONLINE_EFFECTS for e in effects):
        raise DataError(f"effects must be a tuple of names from: {', '.join(ONLINE_EFFECTS)} (or empty), got {effects!r}")
    if effects and refit != "window":
        raise DataError(f"effects {', '.join(effects)} need refit='window', got refit={refit!r}")


def _check(section: object) -> None:
    """Every numeric field of a settings section finite and positive (ints whole); one-line ``DataError`` if not."""
    for f in dataclasses.fields(section):
        value = getattr(section, f.name)
        if f.type in ("int", int):
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                raise DataError(f"{type(section).__name__}.{f.name} must be a positive integer, got {value!r}")
        elif f.type in ("float", float):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value <= 0:
                raise DataError(f"{type(section).__name__}.{f.name} must be a positive finite number, got {value!r}")


@dataclass(frozen=True)
class StartupSettings:
    """The start-up: the buffer, the search on it (``online/startup.py``)."""

    #: Largest search buffer (samples): bounds memory and the duration of the search.
    max_search_samples: int = 1 << 15
    #: Start-up buffer (samples): the search window plus what arrives while the search runs.
    buffer_samples: int = 1 << 17
    #: Before the input's first move the buffer keeps at most ``idle_buffer`` samples, then only the latest
    #: ``idle_keep`` (nothing to identify yet; a stream's distant past only adds its creep to the free responses).
    idle_buffer: int = 4096
    idle_keep: int = 1024
    #: A ready buffer waits at most this many calls for the search's grid plan (it takes ~4).
    plan_waits: int = 8
    #: The shortest search window (s), and in samples: the automatic window starts at the larger.
    first_window_s: float = 0.05
    first_window_samples: int = 200
    #: The search window grows to this many settling times (8 a2 / a1) of the resonance found ...
    settling_windows: float = 1.5
    #: ... or, when the result sits on the search box's edge (not shown by the data), to this many times the window.
    box_growth: float = 4.0
    #: At most this many longer-window searches after the first.
    search_rounds: int = 3
    #: Buffered inputs moved to another frame per unit of work (~5 us of numpy).
    reframe_chunk: int = 4096

    def __post_init__(self) -> None:
        _check(self)
        if self.idle_keep > self.idle_buffer:
            raise DataError(f"StartupSettings.idle_keep ({self.idle_keep}) must not exceed idle_buffer "
                            f"({self.idle_buffer})")
        if self.max_search_samples > self.buffer_samples // 2:
            raise DataError(f"StartupSettings.max_search_samples ({self.max_search_samples}) must be at most half "
                            f"of buffer_samples ({self.buffer_samples})")


@dataclass(frozen=True)
class InputGateSettings:
    """The input gate's release of the samples it kept back (``online/policy/input_gate.py``)."""

    #: Samples kept back are fed this many per update() once decided (with the new sample's, at most this many
    #: kernel calls and one unit of background work per call): the estimate catches up ~burst_s later.
    drain_per_update: int = 2

    def __post_init__(self) -> None:
        _check(self)


@dataclass(frozen=True)
class RecoverySettings:
    """Internal faults and lost samples (``online/recovery.py``)."""

    #: Longest run of lost samples gap() replays (held input, no output; ~1.6 us each); a longer outage restarts
    #: the tracker in constant time: the plant's state after it is unknown anyway.
    gap_replay_max: int = 4096
    #: Internal-fault events kept (the newest); ``internal_faults`` counts them all.
    max_fault_events: int = 50
    #: Consecutive faults of the start-up after which its buffer is dropped: a fault that the buffered samples
    #: cause every time is not searched on again and again.
    startup_faults: int = 3
    #: Re-searches of dropped trackers kept in ``researches``.
    max_past_researches: int = 50

    def __post_init__(self) -> None:
        _check(self)


@dataclass(frozen=True)
class QualitySettings:
    """The quality rule (``online/policy/quality.py``)."""

    #: Live error (window rms) above this multiple of the noise floor is "degraded": the model misses part of the data.
    floor_ratio: float = 2.0
    #: ... above this one the estimate is "provisional", not "good" (the model misses a little of the data:
    #: unmodeled dynamics, or parameters moving within the window faster than it follows). 1.2 is a model error of
    #: 0.66 noise levels (sqrt(1.2^2 - 1)); with the right model the window sits at 0.95-1.05x the floor.
    good_ratio: float = 1.2
    #: alpha within this relative distance of an end of ``alpha_bounds`` is held by the bound, not determined.
    bound_tol: float = 1e-3
    #: What "determined" means, parameter by parameter.
    determined: DeterminedLimits = field(default_factory=DeterminedLimits)
    #: A detected change (or a disagreeing change test) reads "changing" for this long (s) after it was found.
    change_hold_s: float = 1.5
    #: An input held constant for more than this many windows leaves the window without an input change.
    held_windows: float = 3.0
    #: A fault's re-convergence ends at the latest after this long (s) without a forgetting window.
    unwindowed_s: float = 30.0

    def __post_init__(self) -> None:
        _check(self)
        if self.good_ratio > self.floor_ratio:
            raise DataError(f"QualitySettings.good_ratio ({self.good_ratio}) must not exceed floor_ratio "
                            f"({self.floor_ratio})")
        if not isinstance(self.determined, DeterminedLimits):
            raise DataError(f"QualitySettings.determined must be a DeterminedLimits, got {self.determined!r}")


@dataclass(frozen=True)
class MemorySettings:
    """Window and history sizes."""

    #: Fewest samples a forgetting window may hold: a shorter one cannot determine the four parameters.
    min_window_samples: int = 50
    #: Largest history kept for replays (samples).
    max_history: int = 1 << 19
    #: Drift columns with ``track_drift``: 1 the gain's rate, 2 the gain's and alpha's.
    drift_columns: int = 2
    #: Play operators of the online hysteresis loop (``effects=("hysteresis",)``): thresholds evenly spaced over
    #: (0, 1/2) of the input range (``effects.hysteresis.threshold_fractions``, the batch fit's rule with fewer of
    #: them); each is one more column of the window's statistics (the per-sample update grows as their square).
    hysteresis_operators: int = 8

    def __post_init__(self) -> None:
        _check(self)
        if self.drift_columns > 2:
            raise DataError(f"MemorySettings.drift_columns must be 1 or 2, got {self.drift_columns!r}")
        if not 1 <= self.hysteresis_operators <= 24:
            raise DataError(f"MemorySettings.hysteresis_operators must be 1 to 24, got {self.hysteresis_operators!r}")


_SECTIONS = {"startup": StartupSettings, "input_gate": InputGateSettings, "recovery": RecoverySettings,
             "quality": QualitySettings, "memory": MemorySettings}


@dataclass(frozen=True)
class OnlineSettings:
    """Every estimator-level tunable, by section (module docstring). Frozen: change one with ``replace``."""

    startup: StartupSettings = field(default_factory=StartupSettings)
    input_gate: InputGateSettings = field(default_factory=InputGateSettings)
    recovery: RecoverySettings = field(default_factory=RecoverySettings)
    quality: QualitySettings = field(default_factory=QualitySettings)
    memory: MemorySettings = field(default_factory=MemorySettings)
    #: The trackers' own settings (``online/trackers/settings.py``, ``TrackerSettings``); None: their defaults.
    trackers: TrackerSettings | None = None

    def __post_init__(self) -> None:
        for name, kind in _SECTIONS.items():
            if not isinstance(getattr(self, name), kind):
                raise DataError(f"OnlineSettings.{name} must be a {kind.__name__}, got {getattr(self, name)!r}")
        if self.trackers is not None:
            if not isinstance(self.trackers, TrackerSettings):
                raise DataError(f"OnlineSettings.trackers must be a TrackerSettings or None, got {self.trackers!r}")

    def replace(self, **sections: Any) -> "OnlineSettings":
        """A copy with some sections changed: each given as its settings object or a dict of its fields to change
        (``replace(quality={"good_ratio": 1.5})``). Unknown names are a one-line ``DataError``."""
        changed = {}
        for name, value in sections.items():
            if name not in _SECTIONS and name != "trackers":
                raise DataError(f"OnlineSettings has no section {name!r}; its sections: "
                                f"{', '.join([*_SECTIONS, 'trackers'])}")
            if isinstance(value, dict) and name == "trackers":
                current = self.trackers or TrackerSettings()
                unknown = set(value) - {f.name for f in dataclasses.fields(current)}
                if unknown:
                    raise DataError(f"TrackerSettings has no setting {sorted(unknown)[0]!r}")
                value = dataclasses.replace(current, **value)
            elif isinstance(value, dict) and name in _SECTIONS:
                current = getattr(self, name)
                unknown = set(value) - {f.name for f in dataclasses.fields(current)}
                if unknown:
                    raise DataError(f"{type(current).__name__} has no setting {sorted(unknown)[0]!r}")
                value = dataclasses.replace(current, **value)
            changed[name] = value
        return dataclasses.replace(self, **changed)


#: The defaults (``settings=None``).
DEFAULT_SETTINGS = OnlineSettings()
