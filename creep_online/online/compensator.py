"""Feedforward creep compensation from the (live) model: the command u that makes the output follow r.

The plant is ``G(s) = b / (s^alpha (1 + a1 s + a2 s^2))``. Its exact inverse is
improper (relative degree 2 + alpha), so the reference is first shaped by a
critically damped filter of relative degree 3, ``F(s) = 1/(1 + tau s)^3``, and
the compensator realises

    u = F(s) G(s)^-1 r = (1/b) I^(1-alpha) [ (1 + a1 s + a2 s^2) s F(s) r ]

Why this shape:

* **relative degree 3 >= 2 + alpha**: ``F G^-1`` is proper (strictly, by
  1 - alpha), so the command is bounded for a step and needs no derivative of
  the raw reference;
* **critically damped** (three equal real poles): the shaped reference has no
  overshoot, so the output does not overshoot the reference either;
* **the resonance is inverted exactly**: the zeros ``1 + a1 s + a2 s^2`` of the
  inverse cancel the plant's lightly damped poles, so the command contains no
  energy at the resonance and the output is ``F r``, not ringing; with a model
  error the residual ringing is that error times ``|F(j wn)|`` (default corner
  at half the natural frequency: 0.09);
* ``s^alpha = s * s^(alpha-1)``: a derivative (taken exactly from the filter
  states) followed by the fractional *integral* of order ``1 - alpha``, which is
  the sum-of-exponentials machinery of ``soe.py`` with the same fixed nodes.

The SOE node states are filters of the shaped reference's derivatives only
(``compensator_kernels``): they do not depend on the model, and a new model's
output coefficients are K powers (~1 us). The command is the exact average of
the continuous inverse over the coming sample (zero-order hold without the
half-sample lag).

A new model for a compensator already running (``set_model``; ``rebase``):
the plant's creep and its operators remember the commands it received, not the
reference. Inverting the new model on the reference's history would assume the
past commands were the new model's; they were the old one's, and the plant's
memory of that difference stays (on a scanning plant whose live estimate walks,
a mean-level error of up to 11 % of the stroke that the model does not show).
So the new model first re-reads the commands the plant received (``replay``,
the first model's machinery) in a second state, ``REPLAY_CHUNK`` remembered
commands per command computed, while the model in force keeps commanding; once
caught up it takes over. The cost per call stays bounded; a re-reading takes
about the remembered history / (``REPLAY_CHUNK`` - 1) samples (4 s after 60 s at
10 kHz), and a newer model given meanwhile is taken after it. By default
(``rebase="loop"``) models with a hysteresis loop re-read: a live loop and the
creep part trade off on periodic inputs and move together while the plant does
not, so a new model mostly corrects the old one's errors. A plain creep model
is taken at once (its gain scaling the states exactly): a live creep estimate
mostly follows the plant's own drift, where the re-reading's delay costs more
(a creep plant drifting 20 % in alpha: 1.34x the oracle's creep error, within
1.25x at once).

Actuator range: the command is clipped to ``[u_min, u_max]``; with
``anti_windup`` the states then advance with the reference the clipped command
really achieves, so the creep integral never accumulates a history the plant
did not receive, and tracking resumes as soon as the reference is reachable.

Hysteresis: a model from ``fit --effects hysteresis`` (``ExtendedModel`` with
a ``hysteresis`` effect: ``v = u + sum_i w_i play_{r_i}[u]`` on the input) is
inverted analytically (``pi_inverse``): the creep inverse gives v, the inverse
Prandtl-Ishlinskii operator gives u.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..checks import is_real, number, positive, real_array
from ..effects.hysteresis import pi_inverse
from ..errors import DataError, ModelError
from ..model import CreepModel, ExtendedModel
from . import compensator_kernels as CK
from .checkpoint import Checkpointable
from .soe import DEFAULT_DX, DEFAULT_HORIZON_S, SoeBasis
from .stored_params import StoredParams

#: Effects the compensator inverts (the rest of an ExtendedModel is refused, by name).
INVERTIBLE_EFFECTS = ("hysteresis",)
#: Default corner of the reference filter, as a fraction of the model's natural frequency.
BANDWIDTH_FRACTION = 0.5
#: Pass-through commands remembered for the first model's replay (older ones are forgotten).
MAX_REPLAY = 1 << 22
#: Remembered commands replayed per ``command()`` call once there is a model (~0.4 us each): the replay is
#: spread over the calls instead of one ``set_model`` of O(history) (measured 36 ms after 10 s at 10 kHz).
REPLAY_CHUNK = 16
#: Which new models re-read the history before they take over (``CreepCompensator``'s ``rebase``).
REBASE = ("loop", "always", "never")
#: Commands remembered for a new model's re-reading of the history (``rebase``): the newest this many (400 s at
#: 10 kHz); a re-reading starts at rest at the oldest one remembered.
MAX_HISTORY = MAX_REPLAY


class _History:
    """The commands delivered, oldest first: the newest ``MAX_HISTORY`` in a ring. The ring is allocated whole on
    the first command (its pages are touched only as commands arrive: no copy ever stalls a call) and pickled as
    the commands it holds."""

    def __init__(self) -> None:
        self.buf: np.ndarray | None = None
        self.n = 0                           # commands delivered since the reset

    @property
    def start(self) -> int:
        """The index (since the reset) of the oldest command remembered."""
        return max(0, self.n - MAX_HISTORY)

    def append(self, x: float) -> None:
        if self.buf is None:
            self.buf = np.empty(MAX_HISTORY)
        self.buf[self.n % self.buf.size] = x
        self.n += 1

    def extend(self, u: np.ndarray) -> None:
        if self.buf is None:
            self.buf = np.empty(MAX_HISTORY)
        size = self.buf.size
        for a in range(0, u.size, size):
            part = u[a:a + size]
            i = (self.n + a) % size
            k = min(part.size, size - i)
            self.buf[i:i + k] = part[:k]
            self.buf[:part.size - k] = part[k:]
        self.n += u.size

    def pieces(self, a: int, b: int) -> list[np.ndarray]:
        """Commands a .. b-1 (indices since the reset, a >= ``start``) as at most two contiguous views."""
        size = self.buf.size
        i, j = a % size, (b - 1) % size + 1
        return [self.buf[i:j]] if b - a <= size - i else [self.buf[i:], self.buf[:j]]

    def __getstate__(self) -> dict:
        held = np.concatenate(self.pieces(self.start, self.n)) if self.n else np.empty(0)
        return {"n": self.n, "held": held}

    def __setstate__(self, state: dict) -> None:
        self.buf, self.n = None, state["n"] - state["held"].size
        if state["held"].size:
            self.extend(state["held"])


class _Rebase:
    """A new model re-reading the command history (``CreepCompensator.rebase``): its state and coefficients."""

    def __init__(self, model, base: CreepModel, offset: float, hysteresis: dict | None, coefficients: tuple,
                 states: int, start: int, first: float | None) -> None:
        self.model, self.base, self.offset = model, base, offset
        ur, Wz, Ux = coefficients
        self.ur, self.Wz, self.Ux = ur, Wz.copy(), Ux.copy()
        self.st = np.zeros(states)
        self.hy_on = hysteresis is not None
        self.hy = pack_hysteresis(hysteresis) if self.hy_on else np.zeros(4)
        if self.hy_on and first is not None:
            start_play_states(self.hy, first)     # (as the compensator started them: on its first command)
        self.pos = start                     # the next remembered command to re-read


class CreepCompensator(StoredParams, Checkpointable):
    """Command u for reference r, sample by sample, inverting creep, resonance (and hysteresis).

    Every constructor argument is stored verbatim (``get_params``).

    dt:           sampling step (s).
    model:        initial model (CreepModel, or ExtendedModel with ``hysteresis``); None: set it later.
    bandwidth_hz: corner of the reference filter ``1/(1 + s/(2 pi f))^3``; None: half the natural
                  frequency of the first model (the states then start with that model).
    u_min, u_max: actuator range (None: unbounded on that side).
    anti_windup:  when clipped, advance the states with the reference the clipped command achieves.
    horizon_s:    memory horizon of the SOE fractional integral (s).
    soe_dx:       SOE node spacing in ln(lambda).
    rebase:       which new models re-read the commands the plant received before they take over (module
                  docstring): "loop" (models with a hysteresis loop, given or in force), "always", "never" (every
                  model at once, on the reference's history).

    Before there is a model ``command(r)`` passes r through unchanged (clipped):
    the estimator needs an input to find a model. Those commands are
    remembered (up to ``MAX_REPLAY`` samples) and replayed under the first model
    (``compensator_kernels.replay``), so compensation starts from what the
    plant really received and the pass-through phase leaves no creep behind.
    The replay is bounded per call: each ``command()`` replays ``REPLAY_CHUNK``
    remembered samples and passes its own reference through (remembered too)
    until the history is caught up, so no call costs O(history); ``replaying``
    says how many are left.
    """

    def __init__(self, dt: float, model: CreepModel | ExtendedModel | None = None, *,
                 bandwidth_hz: float | None = None, u_min: float | None = None, u_max: float | None = None,
                 anti_windup: bool = True, horizon_s: float = DEFAULT_HORIZON_S, soe_dx: float = DEFAULT_DX,
                 rebase: str = "loop") -> None:
        self.dt = dt
        self.model = model
        self.bandwidth_hz = bandwidth_hz
        self.u_min = u_min
        self.u_max = u_max
        self.anti_windup = anti_windup
        self.horizon_s = horizon_s
        self.soe_dx = soe_dx
        self.rebase = rebase
        self._validate()
        self.reset()

    # ------------------------------------------------------------------ parameters
    def _validate(self) -> None:
        for name in ("dt", "horizon_s", "soe_dx"):
            _positive(name, getattr(self, name))
        if self.bandwidth_hz is not None:
            _positive("bandwidth_hz", self.bandwidth_hz)
            if self.bandwidth_hz >= 0.5 / self.dt:
                raise DataError(f"bandwidth_hz ({self.bandwidth_hz}) must be below the Nyquist frequency "
                                f"({0.5 / self.dt:g} Hz)")
        for name in ("u_min", "u_max"):
            v = getattr(self, name)
            if v is not None and (not is_real(v) or math.isnan(number(v, name))):
                raise DataError(f"{name} must be a number or None, got {v!r}")
        if self.u_min is not None and self.u_max is not None and not self.u_min < self.u_max:
            raise DataError(f"u_min must be below u_max, got {self.u_min} and {self.u_max}")
        if not isinstance(self.anti_windup, bool):
            raise DataError(f"anti_windup must be True or False, got {self.anti_windup!r}")
        if self.rebase not in REBASE:
            raise DataError(f"rebase must be one of {', '.join(REBASE)}, got {self.rebase!r}")
        if self.horizon_s <= self.dt:
            raise DataError(f"horizon_s ({self.horizon_s}) must exceed dt ({self.dt})")

    # ------------------------------------------------------------------ lifecycle
    def reset(self) -> "CreepCompensator":
        """Forget the reference history and counters; back to the constructor's model."""
        self._lo = -math.inf if self.u_min is None else float(self.u_min)
        self._hi = math.inf if self.u_max is None else float(self.u_max)
        self._basis = SoeBasis.build(float(self.dt), horizon_s=float(self.horizon_s), dx=float(self.soe_dx))
        self._tau: float | None = None
        self._st: np.ndarray | None = None
        self._current: CreepModel | ExtendedModel | None = None
        self._base: CreepModel | None = None
        self._offset = 0.0
        self._hy = np.zeros(4)
        self._hy_on = False
        self._out = np.zeros(3)
        self._pack: np.ndarray | None = None
        self._applied: deque[float] = deque(maxlen=MAX_REPLAY)   # pass-through commands not yet replayed
        self._history = _History()           # every command delivered (``rebase``)
        self._rebase: _Rebase | None = None  # a model re-reading the history
        self._pending = None                 # a newer model to re-read after the one under way
        self.samples = 0
        self._clipped = 0
        self.model_changes = 0
        if self.bandwidth_hz is not None:
            self._build(1.0 / (2.0 * math.pi * float(self.bandwidth_hz)))
        if self.model is not None:
            self.set_model(self.model)
        return self

    def _build(self, tau: float) -> None:
        """The model-independent discretisation (one matrix exponential per node) and zero states."""
        e, M, m, phi, gam, pz, P, pr, Ax, ax, C, d = node_discretization(self._basis.lam, tau, float(self.dt))
        self._tau = tau
        self._avg = (pz, P, pr, Ax, ax, C, d)
        q = self._basis.size
        # one buffer holds what command() reads (CK.command_packed: 4 arguments to dispatch, not 16);
        # the arrays below are views into it, so the replay and command_block see the same numbers
        pack = np.zeros(CK.pack_slices(q)["size"][0])
        views = {name: pack[a:b].reshape(shape) for name, (a, b, shape) in CK.pack_slices(q).items()
                 if name != "size"}
        for name, value in (("e", e), ("M", M), ("m", m), ("phi", phi), ("gam", gam)):
            views[name][...] = value
        pack[[CK.P_Q, CK.P_LO, CK.P_HI, CK.P_AW]] = (q, self._lo, self._hi, float(self.anti_windup))
        self._pack = pack
        self._st, self._e, self._M, self._m = views["st"], views["e"], views["M"], views["m"]
        self._phi, self._gam, self._Wz, self._Ux = views["phi"], views["gam"], views["Wz"], views["Ux"]
        self._spare = (np.zeros((3, q)), np.zeros(3))   # a candidate model's coefficients, copied in if taken
        self._ur = 0.0
        # the states' steady response to r = (-1)^n (model-independent): filter x, nodes z (3, K)
        x = np.linalg.solve(-np.eye(3) - phi, gam)
        self._alternating = (x, np.ascontiguousarray(((M @ x + m) / (-1.0 - e)[:, None]).T))

    # ------------------------------------------------------------------ model
    @property
    def current_model(self) -> CreepModel | ExtendedModel | None:
        """The model the commands are computed from now (None: pass-through)."""
        return self._current

    @property
    def tau(self) -> float | None:
        """Time constant (s) of each of the reference filter's three lags (None until known)."""
        return self._tau

    def set_model(self, model: CreepModel | ExtendedModel | None) -> "CreepCompensator":
        """Compute with ``model`` from now on, or once it has re-read the history (``rebase``); nothing happens if it
        is the model in force.

        Re-reading (``rebase`` "loop" and a model with a loop in force or given, or "always"; a compensator that
        already has a model): a new creep part or loop first replays the commands delivered (module docstring;
        ``current_model`` stays the old one meanwhile, ``rebasing`` says how many are left, a newer model given
        meanwhile is taken after it); a model that differs from the one in force by its offset alone is taken at
        once. At once (``rebase`` "never", or a plain creep model under "loop"): a new b scales the states, a new
        loop (``hysteresis``) with the thresholds of the current one keeps the operators' memory
        (``carry_play_states``: new weights move the command by no jump), a loop with other thresholds restarts
        its operators centred on the next command. ModelError (nothing changed) for a model it cannot take:
        effects it does not invert, a loop that is not monotone, an unstable pinned recursion.
        """
        if model is self._current or (model is not None and model == self._current):
            self._rebase = self._pending = None
            return self
        if model is None:
            self._current = None
            self._base = None
            self._rebase = self._pending = None
            return self
        if self._rebase is not None and (model is self._rebase.model or model == self._rebase.model):
            self._pending = None
            return self
        base, offset, hysteresis = _split(model)
        old_hy = self._current.effects.get("hysteresis") if isinstance(self._current, ExtendedModel) else None
        new_hy = pack_hysteresis(hysteresis) if hysteresis is not None and hysteresis != old_hy else None
        if self._tau is None:
            self._build(1.0 / (2.0 * math.pi * BANDWIDTH_FRACTION * base.fn))
        ur, Wz, Ux = self._coefficients(base)       # (into the spare buffers)
        if not self._pin_stable(ur, Wz, Ux):
            raise ModelError(f"the compensator cannot take alpha {base.alpha:.4g}, fn {base.fn:.4g} Hz, zeta "
                             f"{base.zeta:.3g} with its {1 / (2 * math.pi * self._tau):.4g} Hz reference filter: the "
                             "anti-windup and replay recursion would be unstable (a sampled zero of the inverse beyond "
                             "-1: an overdamped resonance far above the filter's corner); check with accepts()")
        if self._rereads(hysteresis, old_hy) and (base != self._base or hysteresis != old_hy):
            self._queue(model, base, offset, hysteresis, (ur, Wz, Ux))
            return self
        self._rebase = self._pending = None
        self._Wz[...] = Wz
        self._Ux[...] = Ux
        self._ur = ur
        if hysteresis != old_hy:
            self._hy_on = hysteresis is not None
            if new_hy is None:
                new_hy = np.zeros(4)
            elif old_hy is not None:
                carry_play_states(self._hy, new_hy)    # same thresholds: the operators keep their memory
            self._hy = new_hy
        if self._current is not None:
            self.model_changes += 1
        if self._base is not None and base.b != self._base.b:
            self._st *= base.b / self._base.b     # the gain scales the output of the whole history
        self._current, self._base, self._offset = model, base, offset
        pack = self._pack
        pack[CK.P_UR], pack[CK.P_HY], pack[CK.P_OFF] = ur, float(self._hy_on), offset
        return self

    def _rereads(self, hysteresis: dict | None, old_hy: dict | None) -> bool:
        """Does a new model re-read the history (``rebase``; a model in force, its first replay done)?"""
        if self._base is None or self._applied or self.rebase == "never":
            return False
        return self.rebase == "always" or hysteresis is not None or old_hy is not None

    def _queue(self, model, base: CreepModel, offset: float, hysteresis: dict | None, coefficients: tuple) -> None:
        """Start re-reading the history with ``model`` (checked), or take it after the re-reading under way."""
        if self._rebase is not None:
            self._pending = model
            return
        hist = self._history
        first = float(hist.pieces(hist.start, hist.start + 1)[0][0]) if hist.n > hist.start else None
        self._rebase = _Rebase(model, base, offset, hysteresis, coefficients, self._st.size, hist.start, first)

    def _rebase_some(self, samples: int) -> None:
        """Re-read up to ``REPLAY_CHUNK`` remembered commands per sample just computed; take over once caught up."""
        rb, hist = self._rebase, self._history
        rb.pos = max(rb.pos, hist.start)             # (a full ring forgot the oldest: the re-reading starts later)
        stop = min(hist.n, rb.pos + REPLAY_CHUNK * samples)
        for piece in hist.pieces(rb.pos, stop) if stop > rb.pos else ():
            CK.replay(rb.st, self._e, self._M, self._m, self._phi, self._gam, rb.Wz, rb.Ux, rb.ur, piece, rb.hy,
                      rb.hy_on)
        rb.pos = stop
        if stop == hist.n:
            self._take_over()

    def _take_over(self) -> None:
        """The re-read model in force: its states, coefficients and loop; then the newer model, if one waits."""
        rb, self._rebase = self._rebase, None
        self._st[...] = rb.st
        self._Wz[...] = rb.Wz
        self._Ux[...] = rb.Ux
        self._ur, self._hy, self._hy_on = rb.ur, rb.hy, rb.hy_on
        self.model_changes += 1
        self._current, self._base, self._offset = rb.model, rb.base, rb.offset
        pack = self._pack
        pack[CK.P_UR], pack[CK.P_HY], pack[CK.P_OFF] = rb.ur, float(rb.hy_on), rb.offset
        pending, self._pending = self._pending, None
        if pending is not None:
            self.set_model(pending)

    @property
    def rebasing(self) -> int:
        """Remembered commands a new model still has to re-read before it takes over (0: none under way)."""
        return 0 if self._rebase is None else self._history.n - self._rebase.pos

    def _coefficients(self, base: CreepModel) -> tuple[float, np.ndarray, np.ndarray]:
        """(ur, Wz, Ux): the output coefficients of the command for ``base`` (K powers), in the spare buffers
        (``set_model`` copies them in once the model is accepted)."""
        pz, P, pr, Ax, ax, C, d = self._avg
        Wz, Ux = self._spare
        ur = float(CK.output_coefficients(base.alpha, base.a1, base.a2, base.b, self._tau, self._basis.lam,
                                          self._basis.dx, pz, P, pr, Ax, ax, C, d, Wz, Ux))
        return ur, Wz, Ux

    def _pin_stable(self, ur: float, Wz: np.ndarray, Ux: np.ndarray) -> bool:
        """Is the recursion with the command pinned (anti-windup, the first model's replay) stable?

        Pinned, the states follow r_eff = (u - base) / ur: their poles are the zeros of the sampled
        inverse C(z). Its zero on the negative real axis near -1 (a sampling zero) leaves the unit
        circle when C(-1) / ur turns negative: for a resonance far above the filter's corner that is
        overdamped (fn 2694 Hz, zeta 1.36 with a 231 Hz filter: -1.002 per sample, a replay of 12 s
        grew to 1e119). C(-1), the response to (-1)^n, is O(K): the nodes are decoupled. Checked
        against the eigenvalues of the pinned recursion on 60 random models and filters: 59 agree;
        the one miss was a complex pair at 1.017 (zeta 0.02, fn/corner 4.9), which this test passes.
        """
        x, z = self._alternating
        return bool((float(np.dot(Ux, x)) + float(np.vdot(Wz, z)) + ur) / ur > 0.0) if ur != 0.0 else False

    def accepts(self, model: CreepModel | ExtendedModel) -> bool:
        """Can ``set_model(model)`` take this model (effects it inverts, a stable pinned recursion)?"""
        try:
            base, _, hysteresis = _split(model)
            if hysteresis is not None:
                pack_hysteresis(hysteresis)      # (an invertible loop)
        except ModelError:
            return False
        if self._tau is None:
            return True                      # (not built yet: set_model builds it for this model, then checks)
        return self._pin_stable(*self._coefficients(base))

    @property
    def replaying(self) -> int:
        """Pass-through commands still to be replayed under the model (0: the commands compensate)."""
        return len(self._applied) if self._base is not None else 0

    def _replay_some(self) -> None:
        """Replay the oldest ``REPLAY_CHUNK`` remembered commands under the current model."""
        n = min(REPLAY_CHUNK, len(self._applied))
        chunk = np.array([self._applied.popleft() for _ in range(n)])
        CK.replay(self._st, self._e, self._M, self._m, self._phi, self._gam, self._Wz, self._Ux, self._ur,
                  chunk, self._hy, self._hy_on)

    # ------------------------------------------------------------------ commands
    def command(self, r: float) -> float:
        """The command for this sample's reference r (held by the DAC until the next sample)."""
        if r.__class__ is not float:
            r = number(r, "command(): reference r")
        if not math.isfinite(r):
            raise DataError(f"reference must be finite, got {r!r}")
        self.samples += 1
        if self._base is not None and self._applied:
            self._replay_some()
        if self._base is None or self._applied:
            return self._pass(r)
        u = CK.command_packed(self._pack, self._hy, r, self._out)
        if self.rebase != "never":
            self._history.append(u)
            if self._rebase is not None:
                self._rebase_some(1)
        return u

    def command_block(self, r: np.ndarray) -> np.ndarray:
        """Commands for a block of references with the current model (same numbers as ``command`` in a loop)."""
        r = np.ascontiguousarray(real_array(r, "command_block(): reference r"))
        if not np.all(np.isfinite(r)):
            raise DataError("reference contains NaN or inf")
        u = np.empty_like(r)
        i = 0
        while i < r.size and (self._base is None or self._applied):   # pass-through, or replay pending
            u[i] = self.command(r[i])
            i += 1
        if i == r.size:
            return u
        r_eff = np.empty(r.size - i)
        self._clipped += CK.command_block(self._st, self._e, self._M, self._m, self._phi, self._gam, self._Wz,
                                         self._Ux, self._ur, r[i:] - self._offset, self._lo, self._hi,
                                         self.anti_windup, self._hy, self._hy_on, u[i:], r_eff)
        self.samples += r.size - i
        if self.rebase != "never":
            self._history.extend(u[i:])
            if self._rebase is not None:
                self._rebase_some(r.size - i)
        return u

    @property
    def clipped(self) -> int:
        """Commands clipped to [u_min, u_max] so far (pass-through, ``command`` and ``command_block``)."""
        return self._clipped + (0 if self._pack is None else int(self._pack[CK.P_CLIPS]))

    @property
    def shaped_reference(self) -> float:
        """The output the plant should show now (filtered reference, after any clipping), or nan before a model
        (and while the pass-through history is being replayed)."""
        return math.nan if self._base is None or self._applied else float(self._st[2]) + self._offset

    def _pass(self, r: float) -> float:
        """r through (clipped), remembered for the replay."""
        u = min(max(r, self._lo), self._hi)
        self._clipped += int(u != r)
        self._applied.append(u)          # (a full deque forgets the oldest: O(1))
        if self.rebase != "never":
            self._history.append(u)
        return u


# --------------------------------------------------------------------------- discretisation
def filter_matrices(tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C, d) of the reference filter 1/(1 + tau s)^3: x' = A x + B r, tau^k x3^(k) = C[k-1] x + d[k-1] r."""
    A = np.array([[-1.0, 0.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, -1.0]]) / tau
    B = np.array([1.0, 0.0, 0.0]) / tau
    C = np.array([[0.0, 1.0, -1.0], [1.0, -2.0, 1.0], [-3.0, 3.0, -1.0]])
    d = np.array([0.0, 0.0, 1.0])
    return A, B, C, d


def node_discretization(lam: np.ndarray, tau: float, h: float) -> tuple:
    """Exact zero-order-hold transitions and sample averages of the filter and of every node bank.

    For node lam, the continuous system ``x' = A x + B r``, ``z_k' = -lam z_k +
    C[k] x + d[k] r`` (k = 1..3) and its running integral are advanced over one
    sample by one matrix exponential (Van Loan); rows are read off for
    ``z(h)`` and ``(1/h) int_0^h z``. Returns (e, M, m, Phi, Gam, pz, P, pr, Ax, ax, C, d).
    """
    from scipy.linalg import expm
    A, B, C, d = filter_matrices(tau)
    q = lam.size
    n = 6
    e, pz = np.empty(q), np.empty(q)
    M, P = np.empty((q, 3, 3)), np.empty((q, 3, 3))
    m, pr = np.empty((q, 3)), np.empty((q, 3))
    for i, li in enumerate(lam):
        F = np.zeros((2 * n + 1, 2 * n + 1))   # states [x, z], input r, integrals of [x, z]
        F[:3, :3] = A
        F[:3, n] = B
        F[3:6, :3] = C
        F[3:6, 3:6] = -li * np.eye(3)
        F[3:6, n] = d
        F[n + 1:, :n] = np.eye(n)
        E = expm(F * h)
        e[i] = E[3, 3]
        M[i] = E[3:6, :3]
        m[i] = E[3:6, n]
        pz[i] = E[n + 4, 3] / h
        P[i] = E[n + 4:n + 7, :3] / h
        pr[i] = E[n + 4:n + 7, n] / h
    phi, gam = E[:3, :3].copy(), E[:3, n].copy()
    Ax, ax = E[n + 1:n + 4, :3] / h, E[n + 1:n + 4, n] / h
    return (e, np.ascontiguousarray(M), m, np.ascontiguousarray(phi), gam, pz, np.ascontiguousarray(P), pr,
            np.ascontiguousarray(Ax), ax, C, d)


# --------------------------------------------------------------------------- hysteresis
def pack_hysteresis(params: dict) -> np.ndarray:
    """The ``hy`` array of ``compensator_kernels._hysteresis``: inverse and forward PI, initial offsets."""
    from ..effects.hysteresis import INITIAL_STATES
    r = np.atleast_1d(np.asarray(params.get("r", []), dtype=float))
    w = np.atleast_1d(np.asarray(params.get("w", []), dtype=float))
    initial = params.get("initial", "centred")
    if initial not in INITIAL_STATES or r.shape != w.shape:
        raise ModelError(f"hysteresis needs matching r and w lists and initial in {', '.join(INITIAL_STATES)}")
    rh, wh, w0h, order = pi_inverse(r, w)
    c = INITIAL_STATES[initial]
    n = r.size
    return np.concatenate(([n, w0h, 1.0], rh, wh, c * rh, r[order], w[order], c * r[order], [0.0]))


def carry_play_states(old: np.ndarray, new: np.ndarray) -> bool:
    """Carry the operators' states of the packed loop ``old`` into ``new`` (both ``pack_hysteresis``) when they have
    the same thresholds (only the weights changed: a live estimate's update); returns whether it did.

    Why: a loop restarted centred on the next command forgets which branch the actuator is on, and the command
    jumps by up to the loop's width at every update of the weights. The forward plays depend on the input and the
    thresholds only, so they are copied. The inverse operator's plays follow from them: with thresholds ascending
    and ``S_j = 1 + w_1 + .. + w_j``, the play of threshold ``rh_j`` (``pi_inverse``) on ``v = u + sum_i w_i p_i``
    is ``S_(j-1) p_j + sum_(i >= j) w_i p_i`` (it is ``v - rh_j`` or ``v + rh_j`` wherever p_j moves, and it moves
    exactly when p_j does). With other thresholds nothing is carried: ``new`` starts centred on its first command.
    """
    n = int(new[0])
    if int(old[0]) != n or n == 0 or old[3 + 6 * n] == 0.0:
        return False
    o = 3
    if not np.array_equal(old[o + 3 * n:o + 4 * n], new[o + 3 * n:o + 4 * n]):
        return False
    _set_plays(new, old[o + 5 * n:o + 6 * n].copy())
    return True


def start_play_states(hy: np.ndarray, u0: float) -> None:
    """Start the operators of the packed loop ``hy`` (``pack_hysteresis``, not started) at the command u0, as the
    compensator starts them on its first command: the forward plays at u0 plus their ``initial`` offsets, the
    inverse plays from them (``carry_play_states``' relation)."""
    n = int(hy[0])
    if n == 0:
        return
    _set_plays(hy, hy[3 + 5 * n:3 + 6 * n] + u0)


def _set_plays(hy: np.ndarray, p: np.ndarray) -> None:
    """The packed loop ``hy``'s forward plays = p, its inverse plays from them (``carry_play_states``' relation:
    ``S_(j-1) p_j + sum_(i >= j) w_i p_i``), marked started."""
    n = int(hy[0])
    o = 3
    w = hy[o + 4 * n:o + 5 * n]
    s_prev = 1.0 + np.concatenate(([0.0], np.cumsum(w)[:-1]))
    hy[o + 2 * n:o + 3 * n] = s_prev * p + np.cumsum(w[::-1] * p[::-1])[::-1]
    hy[o + 5 * n:o + 6 * n] = p
    hy[o + 6 * n] = 1.0


def _split(model: CreepModel | ExtendedModel) -> tuple[CreepModel, float, dict | None]:
    """(base model, output offset, hysteresis params or None); ModelError for effects it cannot invert."""
    if isinstance(model, CreepModel):
        return model, 0.0, None
    if not isinstance(model, ExtendedModel):
        raise ModelError(f"the compensator needs a CreepModel or an ExtendedModel, got {type(model).__name__}")
    other = sorted(set(model.effects) - set(INVERTIBLE_EFFECTS))
    if other:
        raise ModelError(f"the compensator inverts creep, resonance and {', '.join(INVERTIBLE_EFFECTS)}; "
                         f"it cannot invert {', '.join(other)}")
    return model.base, float(model.offset), model.effects.get("hysteresis")


def _positive(name: str, value) -> None:
    positive(value, name)


def warm_kernels() -> None:
    """Compile (or load from numba's cache) the compensator's kernels before a real-time loop."""
    c = CreepCompensator(1e-3, CreepModel(0.1, 1e-3, 1e-6, 1.0), u_min=-1.0, u_max=1.0)
    c.command(0.5)
    c.command_block(np.array([0.5, 2.0]))
    c.set_model(CreepModel(0.2, 1e-3, 1e-6, 1.0).with_effects(hysteresis={"r": [0.1], "w": [0.1]}))
    c.command(0.5)
    c.command_block(np.array([0.5, 0.6]))
    c = CreepCompensator(1e-3)
    c.command(0.5)
    c.set_model(CreepModel(0.1, 1e-3, 1e-6, 1.0))
    c.command(0.5)                   # the replay of the pass-through command
