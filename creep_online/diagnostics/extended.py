"""Extended-model fits: the base creep model plus catalogue effects, by variable projection.

Every effect in ``creep_online.effects`` enters the output linearly once its
few *nonlinear* parameters are fixed (a frequency, a delay, a time constant,
an exponent). So each fit is a small ``least_squares`` (trust-region
reflective, bounded) over the nonlinear parameters -- the base model's
(alpha, fn, zeta) plus at most two per effect -- with all gains, weights,
amplitudes and the offset solved in closed form at every evaluation
(variable projection). Starting points: the base fit (warm start) and short
grid searches for each effect's nonlinear parameters.

Python API: :func:`prepare` a record once, :func:`fit_base`, then
:func:`fit_extended` for any effects (one or several, e.g. two at once);
:class:`ExtendedModel` (also via :func:`with_effects`) simulates the result.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import lstsq as scipy_lstsq
from scipy.optimize import least_squares

from .. import effects as fx
from ..errors import DataError, ModelError
from ..metrics import fit_percent, rms
from ..model import CreepModel
from ..record import check_amplitudes, check_time_and_output

#: Play-operator thresholds used for hysteresis, as fractions of the input range (denser where
#: real loops put most of their weight, at small thresholds).
HYSTERESIS_THRESHOLDS = (0.02, 0.04, 0.07, 0.1, 0.14, 0.19, 0.25, 0.32, 0.4, 0.48)
#: Time stamps whose step varies by less than this (relative) are snapped to a uniform grid.
SNAP_RTOL = 1e-2
#: Play-operator states before the record: centred on u[0], or as left by a rise to / fall to u[0].
INITIAL_STATES = {0: "centred", -1: "ascending", 1: "descending"}
#: Bounds of the base model's nonlinear parameters.
ALPHA_BOUNDS = (1e-3, 0.999)
ZETA_BOUNDS = (1e-3, 20.0)
#: Largest delay searched, in samples (uniform) of the record.
MAX_DELAY_SAMPLES = 40
#: Evaluations allowed per least-squares fit.
MAX_NFEV = 40
#: Extended fits: this many grid starts get a short polish of SHORT_NFEV evaluations first.
SHORT_STARTS = 4
SHORT_NFEV = 8
#: ... and this many priority starts (spectral peaks, swapped modes) too.
PRIORITY_STARTS = 5
#: Long records explore starting points on a prefix of at least EXPLORE_SAMPLES samples that also
#: holds EXPLORE_EXCITATION of the input's total variation (used when it is < 2/3 of the record).
EXPLORE_SAMPLES = 6000
EXPLORE_EXCITATION = 0.3
#: Relative tolerance (ftol, xtol) of the final polish: RSS to ~1e-7 is ample for the evidence.
FULL_TOL = 1e-7
#: Evaluations of the final polish on the whole record after exploring on a prefix.
FULL_NFEV = 8


# --------------------------------------------------------------------------- prepared data
@dataclass
class Prepared:
    """A record made ready for repeated fits: time, input, output, weights and cached input transforms."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    weights: np.ndarray | None = None
    u_pre: float | None = None
    t_pre: float | None = None
    source: str = "<array>"
    notes: list[str] = field(default_factory=list)
    u_range: float | None = None   # input range (sets the hysteresis thresholds); default from u
    u_scale: float | None = None   # max |u| (scales the polynomial columns); default from u
    _cache: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self.t = np.ascontiguousarray(self.t, dtype=float)
        self.u = np.ascontiguousarray(self.u, dtype=float)
        self.y = np.ascontiguousarray(self.y, dtype=float)
        self.n = self.t.size
        self.uniform = fx.is_uniform(self.t) and (self.t_pre is None or self.t_pre == self.t[0])
        self.h = (self.t[-1] - self.t[0]) / max(self.n - 1, 1) if self.uniform else float(np.min(np.diff(self.t)))
        if self.u_range is None:
            self.u_range = float(np.ptp(self.u))
        if self.u_scale is None:
            self.u_scale = max(float(np.max(np.abs(self.u))), 1e-300)
        self.wy = self.y if self.weights is None else self.y * self.weights

    def explore_data(self) -> "Prepared":
        """A window for cheap exploration: long enough and excited enough; the record itself if not shorter.

        It starts at the record's start, or (record in equilibrium before its
        first input change) shortly before that change: the samples before it
        only carry the offset.
        """
        if "explore" not in self._cache:
            a = 0
            if self.u_pre is None and self.t_pre is None:
                moved = np.flatnonzero(self.u != self.u[0])
                if moved.size:
                    a = max(0, int(moved[0]) - EXPLORE_SAMPLES // 10)
            du = np.abs(np.diff(self.u[a:], prepend=self.u[a] if self.u_pre is None else self.u_pre))
            tv = np.cumsum(du)
            need = int(np.searchsorted(tv, EXPLORE_EXCITATION * tv[-1])) + 1 if tv[-1] > 0 else self.n
            n = max(EXPLORE_SAMPLES, need)
            self._cache["explore"] = self.window(a, a + n) if n < 2 * self.n // 3 else self
        return self._cache["explore"]

    def window(self, a: int, b: int) -> "Prepared":
        """Samples a..b-1 (a > 0 only for records in equilibrium until after a), same input scaling."""
        w = None if self.weights is None else self.weights[a:b]
        return Prepared(self.t[a:b], self.u[a:b], self.y[a:b], w, self.u_pre, self.t_pre, self.source,
                        list(self.notes), self.u_range, self.u_scale)

    def prefix(self, n: int) -> "Prepared":
        """The first n samples, with the same input scaling (a shorter record of the same experiment)."""
        w = None if self.weights is None else self.weights[:n]
        return Prepared(self.t[:n], self.u[:n], self.y[:n], w, self.u_pre, self.t_pre, self.source,
                        list(self.notes), self.u_range, self.u_scale)

    @property
    def fs(self) -> float:
        return 1.0 / self.h

    def superposer(self, key: str) -> fx.Superposer:
        """Cached superposer of the input features named by ``key`` (built on first use)."""
        if key not in self._cache:
            x = self.features(key)
            pre = None
            if self.u_pre is not None:
                pre = self.features(key, np.array([self.u_pre]))[:, 0]
            self._cache[key] = fx.Superposer(self.t, x, x_pre=pre, t_pre=self.t_pre)
        return self._cache[key]

    def features(self, key: str, u: np.ndarray | None = None) -> np.ndarray:
        """Input rows for a path: 'u' (the input), 'hyst' (u and play operators), 'poly' (u, u^2, u^3)."""
        u = self.u if u is None else u
        if key == "u":
            return u[None, :]
        if key == "poly":
            scale = self.u_scale
            x = u / scale
            return np.array([u, scale * x * x, scale * x * x * x])
        if key.startswith("hystpoly"):  # generalised PI: play operators plus a polynomial (asymmetric loops)
            return np.vstack([self.features("hyst" + key[8:], u), self.features("poly", u)[1:]])
        if key.startswith("hyst"):
            init = int(key[4:])
            if u is not self.u:  # the state before the record
                return np.repeat(u[None, :], 1 + len(HYSTERESIS_THRESHOLDS), axis=0)
            r = self.thresholds
            return np.vstack([u[None, :], fx.play_operators(u, r, initial=u[0] + init * r)])
        raise KeyError(key)

    @property
    def thresholds(self) -> np.ndarray:
        return np.asarray(HYSTERESIS_THRESHOLDS) * self.u_range


def prepare(t: np.ndarray, u: np.ndarray, y: np.ndarray, *, source: str = "<array>",
            weights: str | np.ndarray | None = "auto", u_pre: float | None = None,
            t_pre: float | None = None) -> Prepared:
    """Make a record ready for fitting.

    ``u_pre``/``t_pre``: the input before the record and the time it jumped to
    u[0] (default: none -- the record starts in equilibrium at u[0], deviation
    variables). ``weights='auto'`` weights non-uniform (log-spaced) records by
    1/|y| (a relative, log-domain fit) and leaves uniform ones unweighted.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    check_time_and_output(t, y, source)
    check_amplitudes(np.asarray(u, dtype=float), y, source)
    w = None
    notes: list[str] = []
    if not fx.is_uniform(t) and fx.is_uniform(t, rtol=SNAP_RTOL):
        h = (t[-1] - t[0]) / (t.size - 1)
        jitter = float(np.max(np.abs(np.diff(t) - h)) / h)
        t = t[0] + np.arange(t.size) * h
        notes.append(f"time stamps jitter by up to {100 * jitter:.2g} % of the step: treated as uniform (h = {h:.6g} s)")
    if isinstance(weights, str):
        if weights != "auto":
            raise DataError(f"weights must be 'auto', None or an array, got {weights!r}")
        if not fx.is_uniform(t):
            floor = 1e-3 * float(np.max(np.abs(y)))
            w = 1.0 / np.maximum(np.abs(y), max(floor, 1e-300))
            notes.append("non-uniform time: residuals weighted by 1/|y| (relative, log-domain fit)")
    elif weights is not None:
        w = np.asarray(weights, dtype=float)
    return Prepared(t, u, y, w, u_pre, t_pre, source, notes)


# --------------------------------------------------------------------------- the design
@dataclass
class ParamSpec:
    name: str      # internal name
    lo: float
    hi: float


def _effect_specs(data: Prepared, name: str) -> list[ParamSpec]:
    """Nonlinear parameters (internal scale) of one effect, with bounds."""
    if name == "second_mode":
        hi = math.log10(0.5 * data.fs) if data.uniform else math.log10(1.0 / data.h)
        lo = math.log10(1.0 / (data.t[-1] - data.t[0]))
        return [ParamSpec("second_mode.log10_fn", lo, hi), ParamSpec("second_mode.log10_zeta", -3.0, 0.5)]
    if name == "leakage":
        dur = data.t[-1] - data.t[0]
        return [ParamSpec("leakage.log10_tau", math.log10(dur / 1e3), math.log10(dur * 1e3))]
    if name == "delay":
        hi = MAX_DELAY_SAMPLES * data.h if data.uniform else 0.05 * (data.t[-1] - data.t[0])
        return [ParamSpec("delay.d", 0.0, hi)]
    if name == "periodic_disturbance":
        # fewer than ~3 cycles over the record is a trend, not a periodic disturbance
        return [ParamSpec("periodic_disturbance.f", 3.0 / (data.t[-1] - data.t[0]), 0.5 * data.fs)]
    if name == "second_creep":
        return [ParamSpec("second_creep.alpha2", 1e-3, 1.0)]
    if name in ("hysteresis", "nonlinear_gain", "drift"):
        return []
    raise ModelError(f"unknown effect {name!r}; the catalogue is {', '.join(fx.EFFECTS)}")


class Design:
    """Columns of the extended model for given nonlinear parameters, and their projection."""

    def __init__(self, data: Prepared, effects: tuple[str, ...] = (), harmonics: int = 1,
                 hysteresis_initial: int = 0) -> None:
        for e in effects:
            if e not in fx.EFFECTS:
                raise ModelError(f"unknown effect {e!r}; the catalogue is {', '.join(fx.EFFECTS)}")
        self.data = data
        self.effects = tuple(effects)
        self.harmonics = harmonics
        fmax = 0.5 * data.fs if data.uniform else 1.0 / data.h
        fmin = 1.0 / (data.t[-1] - data.t[0])
        self.specs = [ParamSpec("alpha", *ALPHA_BOUNDS),
                      ParamSpec("log10_fn", math.log10(fmin), math.log10(2.0 * fmax)),
                      ParamSpec("log10_zeta", math.log10(ZETA_BOUNDS[0]), math.log10(ZETA_BOUNDS[1]))]
        for e in self.effects:
            self.specs += _effect_specs(data, e)
        self.names = [s.name for s in self.specs]
        self.lo = np.array([s.lo for s in self.specs])
        self.hi = np.array([s.hi for s in self.specs])
        hyst, poly = "hysteresis" in effects, "nonlinear_gain" in effects
        self.hysteresis_initial = int(hysteresis_initial)
        init = f"{self.hysteresis_initial:+d}"
        key = "hystpoly" + init if hyst and poly else "hyst" + init if hyst else "poly" if poly else "u"
        self.key = key
        self.col_names: list[str] = []
        self.nfev = 0

    def index(self, name: str) -> int:
        return self.names.index(name)

    def columns(self, theta: np.ndarray) -> np.ndarray:
        """Design matrix (n, p): dynamic paths (delayed, leaked) then offset, drift and sinusoids."""
        data = self.data
        p = dict(zip(self.names, theta))
        alpha, fn, zeta = p["alpha"], 10 ** p["log10_fn"], 10 ** p["log10_zeta"]
        wn = 2 * math.pi * fn
        a1, a2 = 2 * zeta / wn, 1 / wn**2
        d = p.get("delay.d", 0.0)
        sup = data.superposer(self.key)
        names: list[str] = []
        if data.uniform:
            s = fx.delayed_grid(fx.base_step_grid(alpha, a1, a2, data.h, data.n), data.h, d)
            dyn = [sup.apply(s)]
            tau = sup.grid_tau - d
        else:
            dyn = [sup.apply(lambda tt: fx.base_step_at(alpha, a1, a2, tt - d))]
            tau = None
        w_names = [f"w{i}" for i in range(1, len(HYSTERESIS_THRESHOLDS) + 1)]
        names += ["b"] + {"u": [], "hyst": w_names, "poly": ["c2", "c3"],
                          "hystpoly": w_names + ["c2", "c3"]}[self.key.rstrip("+-01")]
        usup = data.superposer("u")
        if "second_mode" in self.effects:
            f2, z2 = 10 ** p["second_mode.log10_fn"], 10 ** p["second_mode.log10_zeta"]
            fn_ = (lambda tt: fx.resonance_step(f2, z2, tt - d))
            dyn.append(usup.apply(fn_(tau + d) if tau is not None else fn_))
            names.append("second_mode.gain")
        if "second_creep" in self.effects:
            a_2 = p["second_creep.alpha2"]
            fn_ = (lambda tt: fx.creep_step(a_2, tt - d))
            dyn.append(usup.apply(fn_(tau + d) if tau is not None else fn_))
            names.append("second_creep.gain")
        cols = np.vstack(dyn)
        if "leakage" in self.effects:
            cols = fx.leakage_filter(data.t, cols, 10 ** p["leakage.log10_tau"])
        static = [np.ones(data.n)]
        names.append("offset")
        if "drift" in self.effects:
            static.append(data.t - data.t[0])
            names.append("drift.rate")
        if "periodic_disturbance" in self.effects:
            static += list(fx.periodic_columns(data.t, p["periodic_disturbance.f"], self.harmonics))
            for k in range(1, self.harmonics + 1):
                names += [f"periodic.sin{k}", f"periodic.cos{k}"]
        self.col_names = names
        return np.vstack([cols, np.array(static)]).T

    def project(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(coefficients, model output, weighted residual) with the linear parameters solved exactly."""
        self.nfev += 1
        phi = self.columns(theta)
        data = self.data
        wphi = phi if data.weights is None else phi * data.weights[:, None]
        scale = np.linalg.norm(wphi, axis=0)
        scale[scale == 0] = 1.0
        coef = scipy_lstsq(wphi / scale, data.wy, cond=1e-10, lapack_driver="gelsy", check_finite=False)[0]
        coef = coef / scale
        y_hat = phi @ coef
        return coef, y_hat, data.wy - wphi @ coef

    def residual(self, theta: np.ndarray) -> np.ndarray:
        return self.project(theta)[2]

    def cost(self, theta: np.ndarray) -> float:
        r = self.residual(theta)
        return float(r @ r)


# --------------------------------------------------------------------------- results
@dataclass
class ExtendedFit:
    """One fitted model: base parameters, effect parameters, output and residual."""

    effects: tuple[str, ...]
    model: CreepModel
    offset: float
    effect_params: dict[str, dict]
    theta: np.ndarray
    coef: np.ndarray
    y_hat: np.ndarray
    residual: np.ndarray          # y - y_hat (unweighted)
    rss: float                    # weighted residual sum of squares (what was minimised)
    n_params: int                 # nonlinear + linear parameters
    fit_percent: float
    residual_rms: float
    nfev: int = 0
    u_pre: float | None = None
    t_pre: float | None = None
    alternatives: list = field(default_factory=list, repr=False)  # other polished base starts
    names: list = field(default_factory=list, repr=False)         # names of theta's entries

    def simulate(self, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        """This model's output for another input (same conventions as the fitted record)."""
        return fx.simulate_with_effects(self.model, t, u, self.effect_params, offset=self.offset,
                                        u_pre=self.u_pre, t_pre=self.t_pre)

    def to_dict(self) -> dict:
        return {"effects": list(self.effects), **self.model.describe(), "offset": self.offset,
                "effect_params": self.effect_params, "fit_percent": self.fit_percent,
                "residual_rms": self.residual_rms, "n_params": self.n_params}


def _result(design: Design, theta: np.ndarray) -> ExtendedFit:
    data = design.data
    coef, y_hat, wres = design.project(theta)
    p = dict(zip(design.names, theta))
    c = dict(zip(design.col_names, coef))
    b = c["b"]
    if b == 0.0 or not math.isfinite(b):
        b = 1e-300
    model = CreepModel.from_resonance(p["alpha"], 10 ** p["log10_fn"], 10 ** p["log10_zeta"], b)
    eff: dict[str, dict] = {}
    for e in design.effects:
        if e == "hysteresis":
            w = np.array([c[f"w{i}"] for i in range(1, len(HYSTERESIS_THRESHOLDS) + 1)]) / b
            width = fx.loop_width(data.thresholds, w, data.u_range)
            eff[e] = {"r": data.thresholds.tolist(), "w": w.tolist(), "loop_width": width,
                      "loop_width_rel": width / data.u_range if data.u_range else float("nan"),
                      "initial": INITIAL_STATES[design.hysteresis_initial]}
        elif e == "nonlinear_gain":
            scale = data.u_scale
            k2, k3 = c["c2"] / b / scale, c["c3"] / b / scale**2
            lo, hi = float(data.u.min()), float(data.u.max())
            g = lambda x: 1 + 2 * k2 * x + 3 * k3 * x * x  # noqa: E731  incremental gain
            gains = [g(x) for x in np.linspace(lo, hi, 21)]
            eff[e] = {"k2": k2, "k3": k3, "gain_change": float(max(gains) / min(gains) - 1)
                      if min(gains) > 0 else float("inf")}
        elif e == "second_mode":
            eff[e] = {"gain": c["second_mode.gain"], "fn_hz": 10 ** p["second_mode.log10_fn"],
                      "zeta": 10 ** p["second_mode.log10_zeta"]}
        elif e == "drift":
            eff[e] = {"rate": c["drift.rate"]}
        elif e == "leakage":
            eff[e] = {"tau_s": 10 ** p["leakage.log10_tau"]}
        elif e == "delay":
            eff[e] = {"delay_s": p["delay.d"], "delay_samples": p["delay.d"] / data.h}
        elif e == "periodic_disturbance":
            amps, phases = [], []
            for k in range(1, design.harmonics + 1):
                s_, c_ = c[f"periodic.sin{k}"], c[f"periodic.cos{k}"]
                amps.append(math.hypot(s_, c_))
                phases.append(math.atan2(c_, s_))
            eff[e] = {"f_hz": p["periodic_disturbance.f"], "amplitude": amps if len(amps) > 1 else amps[0],
                      "phase": phases if len(phases) > 1 else phases[0]}
        elif e == "second_creep":
            eff[e] = {"gain": c["second_creep.gain"], "alpha2": p["second_creep.alpha2"]}
    res = data.y - y_hat
    return ExtendedFit(design.effects, model, c["offset"], eff, np.array(theta), coef, y_hat, res,
                       float(wres @ wres), len(theta) + len(coef), fit_percent(data.y, y_hat), rms(res),
                       design.nfev, data.u_pre, data.t_pre, names=list(design.names))


def base_theta(model: CreepModel) -> np.ndarray:
    """The base model's nonlinear parameters on the fitting scale."""
    return np.array([model.alpha, math.log10(model.fn), math.log10(model.zeta)])


def _optimise(design: Design, theta0: np.ndarray, max_nfev: int = MAX_NFEV, tol: float = 1e-8) -> np.ndarray:
    x0 = np.clip(theta0, design.lo, design.hi)
    span = design.hi - design.lo
    x0 = np.minimum(np.maximum(x0, design.lo + 1e-9 * span), design.hi - 1e-9 * span)
    try:
        sol = least_squares(design.residual, x0, bounds=(design.lo, design.hi), method="trf",
                            x_scale="jac", max_nfev=max_nfev, diff_step=1e-7, ftol=tol, xtol=tol)
    except (ValueError, np.linalg.LinAlgError, ModelError):
        return x0
    return sol.x if design.cost(sol.x) <= design.cost(x0) else x0


# --------------------------------------------------------------------------- base fit
def _frf_peaks(data: Prepared, count: int = 3) -> list[float]:
    """Frequencies (Hz) of the largest peaks of |Y/U| * f (uniform records), strongest first."""
    if not data.uniform or data.n < 64:
        return []
    from scipy.signal import csd, find_peaks, welch
    nper = int(min(data.n, 2 ** int(math.log2(max(64, data.n // 8)))))
    du = np.diff(data.u, prepend=data.u[0])
    dy = np.diff(data.y, prepend=data.y[0])
    f, puu = welch(du, data.fs, nperseg=nper)
    _, puy = csd(du, dy, data.fs, nperseg=nper)
    ok = (f > 2 * f[1]) & (puu > 1e-12 * puu.max())
    if ok.sum() < 8:
        return []
    mag = np.zeros_like(f)
    mag[ok] = np.abs(puy[ok]) / puu[ok]
    peaks, props = find_peaks(mag, prominence=0.1 * mag.max())
    order = np.argsort(props["prominences"])[::-1]
    return [float(f[peaks[i]]) for i in order[:count]]


def fit_base(data: Prepared, start: CreepModel | None = None, max_nfev: int = MAX_NFEV,
             grid: bool = True) -> ExtendedFit:
    """The base creep model (plus offset) by variable projection from several starts.

    Starts: ``start`` (e.g. the result of ``identify``), and (``grid``) a
    small grid over alpha, the resonance frequency (peaks of the empirical
    frequency response, and a default) and the damping. The two best starts
    are polished.
    """
    design = Design(data)
    # long records: choose and pre-polish the starts on a prefix (same experiment, cheaper), finish on all
    small = data.explore_data()
    explore = Design(small) if small is not data else design
    starts: list[np.ndarray] = []
    if start is not None:
        starts.append(base_theta(start))
    fmax = 10 ** design.hi[1] / 2.0
    fns = (_frf_peaks(data) + [fmax / 10.0, fmax / 100.0]) if grid or start is None else []
    for alpha in (0.15, 0.4, 0.7, 0.95):
        for fn in fns:
            for zeta in (0.05, 0.3, 1.0):
                starts.append(np.array([alpha, math.log10(fn), math.log10(zeta)]))
    costs = []
    for th in starts:
        th = np.clip(th, explore.lo, explore.hi)
        try:
            costs.append(explore.cost(th))
        except (ValueError, ModelError, np.linalg.LinAlgError):
            costs.append(np.inf)
    order = np.argsort(costs)
    polished = []
    for i in order[:2]:
        th = _optimise(explore, starts[i], max_nfev)
        if explore is not design:
            th = _optimise(design, th, FULL_NFEV, FULL_TOL)
        polished.append((design.cost(th), th))
    polished.sort(key=lambda ct: ct[0])
    fit = _result(design, polished[0][1])
    fit.alternatives = [th for _, th in polished[1:]]
    return fit


# --------------------------------------------------------------------------- extended fit
def _grid_starts(design: Design, base: ExtendedFit, peaks: list[float]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(grid starts, priority starts) for the effects' nonlinear parameters.

    Grids cover each parameter's range; priority starts put a frequency
    parameter on a residual-spectrum peak (always polished, since a narrow
    resonance or line is found there and almost nowhere else). Every start is
    combined with the base fit and its runner-up.
    """
    data = design.data
    grids: list[list[float]] = []
    prio: list[list[float]] = []
    names = design.names[3:]
    for name in names:
        lo, hi = design.lo[design.index(name)], design.hi[design.index(name)]
        if name == "second_mode.log10_fn":
            cand = [math.log10(f) for f in peaks if 10 ** lo < f < 10 ** hi]
            grids.append(list(np.linspace(lo + 0.05 * (hi - lo), hi - 0.01 * (hi - lo), 24)))
            prio.append(cand)
        elif name == "second_mode.log10_zeta":
            grids.append([math.log10(0.05)])
            prio.append([math.log10(0.02), math.log10(0.08)])
        elif name == "leakage.log10_tau":
            grids.append(list(np.linspace(lo + 0.5, hi - 0.5, 9)))
            prio.append([])
        elif name == "delay.d":
            grids.append(list(np.unique(np.concatenate([np.array([0.3, 1, 2, 3, 5, 8, 13, 20, 30]) * data.h, [hi * 0.99]]))))
            prio.append([])
        elif name == "periodic_disturbance.f":
            grids.append([f for f in peaks if lo <= f <= hi] or [0.05 * data.fs])
            prio.append([f for f in peaks if lo <= f <= hi])
        elif name == "second_creep.alpha2":
            grids.append([0.05, 0.15, 0.3, 0.5, 0.7, 0.85, 0.97])
            prio.append([])
    bases = [base.theta[:3]] + [np.asarray(a)[:3] for a in base.alternatives
                                if np.max(np.abs(np.asarray(a)[:3] - base.theta[:3])) > 1e-3]
    if "second_creep" in design.effects:  # the two exponents trade places: move alpha too
        for b_ in list(bases):
            for shift in (-0.2, 0.2):
                v = b_.copy()
                v[0] = float(np.clip(v[0] + shift, ALPHA_BOUNDS[0] + 0.01, ALPHA_BOUNDS[1] - 0.01))
                bases.append(v)
    if not grids:
        return [b_ for b_ in bases], []

    def mesh(lists: list[list[float]]) -> list[np.ndarray]:
        if any(len(x) == 0 for x in lists):
            return []
        m = np.array(np.meshgrid(*lists, indexing="ij")).reshape(len(lists), -1).T
        return [np.concatenate([b_, row]) for b_ in bases for row in m]

    # a priority start keeps the grid for the parameters that have no priority values
    prio_lists = [p_ if p_ else g for p_, g in zip(prio, grids)] if any(prio) else []
    prio_starts = mesh(prio_lists) if prio_lists else []
    if "second_mode" in design.effects and len(names) == 2:
        # the base may have locked onto the higher mode: hand it to the second mode, move the base down
        i_fn = design.index("second_mode.log10_fn")
        for factor in (0.25, 0.4, 0.6):
            th = np.concatenate([base.theta[:3], np.zeros(2)])
            th[i_fn], th[i_fn + 1] = base.theta[1], base.theta[2]
            th[1], th[2] = base.theta[1] + math.log10(factor), math.log10(0.2)
            prio_starts.append(th)
    return mesh(grids), prio_starts


def _null_start(design: Design, base: ExtendedFit) -> np.ndarray:
    """The base fit inside the extended model (effects switched off): the nested model, never worse than base."""
    tail = _default_tail(design)
    for i, name in enumerate(design.names[3:], start=3):
        if name == "leakage.log10_tau":
            tail[i - 3] = design.hi[i]
        elif name == "delay.d":
            tail[i - 3] = 0.0
    return np.concatenate([base.theta[:3], tail])


def _default_tail(design: Design) -> np.ndarray:
    """Mid-range values of the effects' nonlinear parameters (for quick comparisons)."""
    return 0.5 * (design.lo[3:] + design.hi[3:])


def _merge(design: Design, theta: np.ndarray, warm: ExtendedFit) -> np.ndarray:
    """theta with every parameter that ``warm`` also has replaced by warm's value."""
    out = np.array(theta, dtype=float)
    for name, value in zip(warm.names, warm.theta):
        if name in design.names:
            out[design.index(name)] = value
    return out


def fit_extended(data: Prepared, effects: tuple[str, ...] | list[str] | str, base: ExtendedFit | None = None,
                 harmonics: int = 1, max_nfev: int = MAX_NFEV, n_starts: int = 2,
                 warm: ExtendedFit | None = None) -> ExtendedFit:
    """Fit the base model extended by ``effects``, warm-started from ``base`` (fitted if not given).

    The effects' nonlinear parameters start from a grid (residual-spectrum
    peaks for frequencies); the ``SHORT_STARTS`` most promising grid values
    (each with its best base variant) get a short joint polish, and the
    ``n_starts`` best of those a full one (bounded least squares). ``warm``
    (e.g. the fit of one of the effects alone) seeds further starts with its
    values, so a combination is never worse than that fit.
    """
    if isinstance(effects, str):
        effects = tuple(e.strip() for e in effects.split(",") if e.strip())
    effects = tuple(dict.fromkeys(effects))
    if base is None:
        base = fit_base(data)
    if not effects:
        return base
    from .locate import spectrum_peaks
    init = 0
    warm_h = (warm.effect_params.get("hysteresis") or {}).get("initial") if warm is not None else None
    if warm_h is not None:
        init = {v: k for k, v in INITIAL_STATES.items()}[warm_h]
    elif "hysteresis" in effects:  # the operators' state before the record is unknown: best of three after a short polish
        small = data.explore_data()
        costs = {}
        for k in INITIAL_STATES:
            d = Design(small, effects, harmonics, k)
            th = _optimise(d, np.concatenate([base.theta[:3], _default_tail(d)]), SHORT_NFEV, 1e-6)
            costs[k] = d.cost(th)
        init = min(costs, key=costs.get)
    design = Design(data, effects, harmonics, init)
    peaks = [p["f_hz"] for p in spectrum_peaks(data.t, base.residual, max_peaks=4, ratio=3.0)] if data.uniform else []
    # explore (grids, short polishes) on a prefix of long records: the same experiment, cheaper evaluations
    small = data.explore_data()
    explore = Design(small, effects, harmonics, init) if small is not data else design
    grid, prio = _grid_starts(explore, base, peaks)

    def ranked(d: Design, starts: list[np.ndarray]) -> list[tuple[float, np.ndarray]]:
        out = []
        for th in starts:
            th = np.clip(th, d.lo, d.hi)
            try:
                out.append((d.cost(th), th))
            except (ValueError, ModelError, np.linalg.LinAlgError):
                out.append((np.inf, th))
        out.sort(key=lambda ct: ct[0])
        return out

    # best base variant per effect-parameter value, the most promising few, plus the priority starts
    groups: dict[tuple, np.ndarray] = {}
    for _, th in ranked(explore, grid):
        groups.setdefault(tuple(np.round(th[3:], 9)), th)
    chosen = list(groups.values())[:SHORT_STARTS] + [th for _, th in ranked(explore, prio)[:PRIORITY_STARTS]]
    if warm is not None:
        chosen += [_merge(explore, th, warm) for th in list(groups.values())[:2]]
    short = [_optimise(explore, th, SHORT_NFEV, 1e-6) for th in chosen]
    finalists = [th for _, th in ranked(explore, short)[:n_starts]] + [_null_start(design, base)]
    if warm is not None:
        finalists.append(_merge(design, _null_start(design, base), warm))
    if explore is not design and "periodic_disturbance" in effects:
        i_f = design.index("periodic_disturbance.f")  # a line's frequency is sharper on the whole record
        for th in list(finalists):
            for f in peaks:
                v = th.copy()
                v[i_f] = f
                finalists.append(v)
    best, best_cost = None, np.inf
    for _, th in ranked(design, finalists)[:n_starts if explore is design else 1]:
        th = _optimise(design, th, max_nfev if explore is design else FULL_NFEV, FULL_TOL)
        c = design.cost(th)
        if c < best_cost:
            best, best_cost = th, c
    return _result(design, best)


# --------------------------------------------------------------------------- model object
@dataclass(frozen=True)
class ExtendedModel:
    """A base CreepModel plus catalogue effects: ``ExtendedModel(model, {"delay": {"delay_s": 1e-3}})``."""

    base: CreepModel
    effects: dict = field(default_factory=dict)
    offset: float = 0.0

    def simulate(self, t: np.ndarray, u: np.ndarray, u_pre: float | None = 0.0,
                 t_pre: float | None = None) -> np.ndarray:
        """Output for a zero-order-held input (from rest by default, like ``simulate``)."""
        return fx.simulate_with_effects(self.base, t, u, self.effects, offset=self.offset, u_pre=u_pre, t_pre=t_pre)

    def with_effects(self, **effects: dict) -> "ExtendedModel":
        """A copy with more (or replaced) effects."""
        return ExtendedModel(self.base, {**self.effects, **effects}, self.offset)

    def fit(self, t: np.ndarray, u: np.ndarray, y: np.ndarray) -> ExtendedFit:
        """Refit this model's structure (base + the named effects) to a record, warm-started here."""
        data = prepare(t, u, y)
        base = fit_base(data, start=self.base)
        return fit_extended(data, tuple(self.effects), base)


def with_effects(model: CreepModel, **effects: dict) -> ExtendedModel:
    """``with_effects(model, delay={"delay_s": 2e-3})``: the model extended by catalogue effects."""
    for name in effects:
        if name not in fx.EFFECTS:
            raise ModelError(f"unknown effect {name!r}; the catalogue is {', '.join(fx.EFFECTS)}")
    return ExtendedModel(model, dict(effects))


def check_effects(names: str | list[str]) -> tuple[str, ...]:
    """Parse 'a,b' into catalogue names; DataError-free ModelError naming the unknown ones."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    bad = [n for n in names if n not in fx.EFFECTS]
    if bad:
        raise ModelError(f"unknown effect(s) {', '.join(bad)}; the catalogue is {', '.join(fx.EFFECTS)}")
    if not names:
        raise ModelError("no effect named; the catalogue is " + ", ".join(fx.EFFECTS))
    return tuple(dict.fromkeys(names))


__all__ = ["Prepared", "prepare", "Design", "ExtendedFit", "ExtendedModel", "fit_base", "fit_extended",
           "with_effects", "check_effects", "DataError"]
