"""CreepCompensator (issue 12): the inverse against the exact simulator and closed forms, clipping with
anti-windup, hysteresis inversion, adaptation, and adaptive vs frozen on drifting random plants."""
from __future__ import annotations

import math

import numpy as np
import pytest

from creep_online.effects.hysteresis import INITIAL_STATES, hysteresis_input
from creep_online.errors import DataError, ModelError
from creep_online.model import CreepModel
from creep_online.online import compensator_kernels as CK
from creep_online.online.compensator import CreepCompensator, pi_inverse
from creep_online.online.soe import SoeBasis
from creep_online.simulate import simulate

H = 1e-4
DEMO = CreepModel.from_resonance(0.12, 420.0, 0.08, 2.5)


def shaped_step(t: np.ndarray, tau: float) -> np.ndarray:
    """Closed-form unit-step response of 1/(1 + tau s)^3 (zero for t <= 0)."""
    s = np.maximum(t, 0.0) / tau
    return 1.0 - np.exp(-s) * (1.0 + s + s * s / 2.0)


def shaped_reference(t: np.ndarray, r: np.ndarray, tau: float) -> np.ndarray:
    """The filtered staircase, by superposing closed-form step responses (independent of the kernels)."""
    out = np.zeros_like(t)
    for k in np.flatnonzero(np.diff(r, prepend=0.0)):
        out += (r[k] - (r[k - 1] if k else 0.0)) * shaped_step(t - t[k], tau)
    return out


def soe_error(beta: float, h: float) -> float:
    """Largest relative error of the SOE fractional integral of order beta (step response, 1 ms .. 1 h)."""
    basis = SoeBasis.build(h)
    t = np.logspace(-3, np.log10(3600.0), 300)
    return float(np.max(np.abs(basis.step_response(beta, t) / (t ** beta / math.gamma(1 + beta)) - 1)))


def random_plant(rng: np.random.Generator) -> CreepModel:
    return CreepModel.from_resonance(rng.uniform(0.02, 0.6), rng.uniform(150.0, 1500.0), rng.uniform(0.02, 0.5),
                                     rng.uniform(0.5, 5.0) * rng.choice([-1.0, 1.0]))


def test_weights_are_the_soe_weights():
    basis = SoeBasis.build(H)
    for beta in (0.05, 0.4, 0.88, 0.998):
        w = np.empty(basis.size)
        d = CK.soe_weights(beta, basis.lam, basis.dx, w)
        w_ref, d_ref = basis.weights(beta)
        np.testing.assert_allclose(w, w_ref, rtol=1e-13)
        assert d == pytest.approx(d_ref, rel=1e-13)


def test_exact_plant_reproduces_the_shaped_reference_on_random_plants():
    """simulate(exact) driven by the commands = filtered reference, within the SOE accuracy.

    Two error sources, both scaled by the reference's travel (sum |dr|): the SOE
    kernel's relative error eps(1 - alpha) (allowed 3x), and the zero-order hold
    of the sample-averaged command, O((h/tau)^2): inside the filter's transient
    (10 tau) allowed 0.05 (h/tau)^2 (measured <= 0.013), after it 1e-3 (h/tau)^2
    (measured <= 2.4e-4: the plant's fractional memory keeps a t^(alpha-1) tail
    of the transient's residue).
    """
    rng = np.random.default_rng(12)
    t = np.arange(int(0.6 / H)) * H
    passed = 0
    cases = 10
    for _ in range(cases):
        model = random_plant(rng)
        steps = np.sort(rng.uniform(0.01, 0.5, 3))
        r = np.zeros_like(t)
        for s in steps:
            r[t >= s] += rng.uniform(-1.0, 1.0)
        comp = CreepCompensator(H, model)
        u = comp.command_block(r)
        y = simulate(model, t, u)
        ref = shaped_reference(t, r, comp.tau)
        travel = float(np.sum(np.abs(np.diff(r, prepend=0.0))))
        settled = np.ones(t.size, bool)
        for s in steps:
            settled &= ~((t >= s) & (t < s + 10 * comp.tau))
        tol_settled = (3 * soe_error(1 - model.alpha, H) + 1e-3 * (H / comp.tau) ** 2) * travel
        tol_transient = 0.05 * (H / comp.tau) ** 2 * travel
        ok = np.max(np.abs(y - ref)[settled]) < tol_settled and np.max(np.abs(y - ref)) < tol_transient
        passed += ok
    print(f"inverse reproduces the shaped reference on {passed}/{cases} random plants")
    assert passed == cases


def test_step_command_matches_the_closed_form_tail():
    """For a unit step the command is s^(alpha-1) F(s) (1 + a1 s + a2 s^2) / b applied to a step: expanding
    F (1 + a1 s + a2 s^2) = 1 + c1 s + c2 s^2 + ... (c1 = a1 - 3 tau, c2 = a2 - 3 tau a1 + 6 tau^2) gives
    u = [t^-a - c1 a t^(-a-1) + c2 a (a+1) t^(-a-2)] / (b Gamma(1 - a)) + O((tau/t)^3)."""
    t = np.arange(int(1.0 / H)) * H
    for model in (DEMO, CreepModel.from_resonance(0.45, 200.0, 0.3, -1.5)):
        comp = CreepCompensator(H, model)
        u = comp.command_block(np.ones_like(t))
        tm = t + H / 2            # the command is the average over the sample: compare at its middle
        sel = tm > 0.15       # the O((tau/t)^3) rest: < 2e-5 from here (5e-4 at 50 ms for tau = 1.6 ms)
        a, tau, ts = model.alpha, comp.tau, tm[sel]
        c1 = model.a1 - 3 * tau
        c2 = model.a2 - 3 * tau * model.a1 + 6 * tau * tau
        closed = (ts ** -a - c1 * a * ts ** (-a - 1) + c2 * a * (a + 1) * ts ** (-a - 2)) / (model.b * math.gamma(1 - a))
        np.testing.assert_allclose(u[sel], closed, rtol=1e-4)


def test_set_model_is_the_inverse_of_the_new_model_for_the_whole_history():
    """Taken at once (``rebase="never"``; a plain creep model under the default too): the states do not depend on alpha, a1, a2, so switching gives the command
    of a compensator that always had the new model. A new gain scales the states (the plant's output of the past commands scales)."""
    t = np.arange(5000) * H
    r = np.where(t > 0.05, 1.0, 0.0) + np.where(t > 0.3, -0.4, 0.0)
    other = CreepModel.from_resonance(0.2, 400.0, 0.1, DEMO.b)
    a = CreepCompensator(H, DEMO, bandwidth_hz=200.0, rebase="never")
    a.command_block(r[:3000])
    a.set_model(other)
    b = CreepCompensator(H, other, bandwidth_hz=200.0)
    b.command_block(r[:3000])
    np.testing.assert_allclose(a.command_block(r[3000:]), b.command_block(r[3000:]), rtol=1e-12, atol=1e-15)
    assert a.model_changes == 1
    before = a.shaped_reference
    a.set_model(CreepModel(other.alpha, other.a1, other.a2, 1.1 * other.b))
    assert a.shaped_reference == pytest.approx(1.1 * before, rel=1e-12)


def test_the_first_model_replays_the_pass_through_commands():
    """Before a model the reference passes through; the first model replays those commands, so the plant
    (exact simulator of everything it received) follows the reference from then on, no leftover creep."""
    t = np.arange(int(1.0 / H)) * H
    r = np.where(t >= 0.01, 0.6, 0.0) + np.where(t >= 0.5, 0.3, 0.0)
    comp = CreepCompensator(H)
    k_model = int(0.2 / H)
    u = np.array([comp.command(v) for v in r[:k_model]])
    assert np.array_equal(u, r[:k_model])
    comp.set_model(DEMO)
    u = np.concatenate((u, comp.command_block(r[k_model:])))
    y = simulate(DEMO, t, u)
    settle = 10 * comp.tau + DEMO.settling_time
    late = (t > 0.2 + settle) & ~((t >= 0.5) & (t < 0.5 + 10 * comp.tau))
    assert np.max(np.abs(y - shaped_reference(t, r, comp.tau))[late]) < 1e-4


def test_the_first_models_replay_is_spread_over_the_calls():
    """After 0.3 s of pass-through the first model does not replay 3000 commands in one call: each command()
    replays REPLAY_CHUNK of them and passes its own reference through (remembered) until caught up. command
    and command_block agree through it, and the plant (exact simulator) then follows the shaped reference."""
    from creep_online.online.compensator import REPLAY_CHUNK
    t = np.arange(int(1.0 / H)) * H
    r = np.where(t >= 0.01, 0.6, 0.0) + np.where(t >= 0.5, 0.3, 0.0)
    k_model = 3000
    a, b = CreepCompensator(H), CreepCompensator(H)
    u = [a.command(v) for v in r[:k_model]]
    ub = b.command_block(r[:k_model])
    a.set_model(DEMO)
    b.set_model(DEMO)
    assert a.replaying == k_model and math.isnan(a.shaped_reference)
    left = [a.replaying]
    while a.replaying:
        u.append(a.command(r[len(u)]))
        left.append(a.replaying)
    caught = len(u)                  # the call that caught up compensates its own sample
    assert np.array_equal(u[:-1], r[:caught - 1]) and u[-1] != r[caught - 1]
    print(f"3000 remembered commands replayed in {caught - k_model} calls")
    assert all(x - y == REPLAY_CHUNK - 1 for x, y in zip(left[:-2], left[1:-1]))   # a chunk per call
    u = np.concatenate((u, [a.command(v) for v in r[caught:]]))
    np.testing.assert_array_equal(u, np.concatenate((ub, b.command_block(r[k_model:]))))
    y = simulate(DEMO, t, u)
    settle = 10 * a.tau + DEMO.settling_time
    late = (t > t[caught] + settle) & ~((t >= 0.5) & (t < 0.5 + 10 * a.tau))
    assert np.max(np.abs(y - shaped_reference(t, r, a.tau))[late]) < 1e-4


def pinned_spectral_radius(comp: CreepCompensator, model: CreepModel) -> float:
    """Largest |eigenvalue| of the compensator's state recursion with the command pinned (anti-windup, replay):
    the states' own update with r_eff = (u - base) / ur substituted, built from the kernel's matrices."""
    ur, Wz, Ux = comp._coefficients(model)
    q = comp._e.size
    A, bv, cv = np.zeros((3 + 3 * q, 3 + 3 * q)), np.zeros(3 + 3 * q), np.zeros(3 + 3 * q)
    A[:3, :3], bv[:3], cv[:3] = comp._phi, comp._gam, Ux
    for k in range(3):
        rows = 3 + k * q + np.arange(q)
        A[rows, rows] = comp._e
        A[rows, :3] = comp._M[:, k, :]
        bv[rows], cv[rows] = comp._m[:, k], Wz[k]
    return float(np.max(np.abs(np.linalg.eigvals(A - np.outer(bv, cv) / ur))))


def test_a_model_whose_pinned_recursion_is_unstable_is_refused():
    """Pinned (anti-windup, the first model's replay), the states' poles are the zeros of the sampled inverse;
    the one near -1 leaves the unit circle for an overdamped resonance far above the filter's corner. Such an
    estimate (called good for random drifting plant 4: fn 2694 Hz, zeta 1.36, the truth 463 Hz, 0.68) made
    the replay of 12 s of pass-through grow to 1e119. It is refused with one clear error, accepts() says so
    beforehand, and the check agrees with the pinned recursion's eigenvalues."""
    comp = CreepCompensator(H, bandwidth_hz=231.3)
    bad = CreepModel.from_resonance(0.5924, 2694.0, 1.36, 1.672)
    good = CreepModel.from_resonance(0.5908, 462.6, 0.684, 1.674)
    assert pinned_spectral_radius(comp, bad) > 1.001 and pinned_spectral_radius(comp, good) < 1 + 1e-9
    assert not comp.accepts(bad) and comp.accepts(good)
    with pytest.raises(ModelError, match="recursion would be unstable"):
        comp.set_model(bad)
    assert comp.current_model is None
    comp.set_model(good)
    assert comp.current_model == good


def test_command_and_command_block_agree():
    t = np.arange(2000) * H
    r = np.where(t > 0.02, 0.8, 0.0)
    a = CreepCompensator(H, DEMO, u_min=-0.3, u_max=0.5)
    b = CreepCompensator(**a.get_params())
    ua = np.array([a.command(v) for v in r])
    np.testing.assert_array_equal(ua, b.command_block(r))
    assert a.clipped == b.clipped > 0


def test_saturation_with_anti_windup_follows_what_the_plant_can_do():
    """A step larger than the actuator allows: the command stays in range, the compensator's shaped
    reference is what the plant really does (the exact simulator agrees), and once the reference is
    reachable again the output tracks it; without anti-windup it does not."""
    t = np.arange(int(1.0 / H)) * H
    r = np.where(t >= 0.01, 1.6, 0.0)
    r[t >= 0.4] = 0.5
    errors = {}
    for aw in (True, False):
        comp = CreepCompensator(H, DEMO, u_min=-0.2, u_max=0.5, anti_windup=aw)
        u, shaped = np.empty_like(t), np.empty_like(t)
        for k, rk in enumerate(r):
            shaped[k] = comp.shaped_reference
            u[k] = comp.command(rk)
        assert u.max() <= 0.5 and u.min() >= -0.2 and comp.clipped > 0
        y = simulate(DEMO, t, u)
        if aw:   # the internal reference is the plant's output, saturated or not (to the zero-order hold's
            # O((h/tau)^2) residue while the held command differs from the continuous inverse, as in a transient)
            assert np.max(np.abs(y - shaped)[t > 0.02]) < 0.05 * (H / comp.tau) ** 2 * 1.6
        late = t > 0.5
        errors[aw] = float(np.max(np.abs(y[late] - 0.5)))
    print(f"tracking error after saturation: anti-windup {errors[True]:.2e}, none {errors[False]:.2e}")
    assert errors[True] < 1e-4 < 1e-2 < errors[False]


@pytest.mark.parametrize("initial", list(INITIAL_STATES))
def test_pi_inverse_undoes_the_hysteresis_effect(initial):
    rng = np.random.default_rng(4)
    r = np.sort(rng.uniform(0.02, 0.6, 6))
    w = rng.uniform(-0.05, 0.2, 6)
    u = np.cumsum(rng.normal(0, 0.05, 3000))
    v = hysteresis_input(u, r, w, initial)
    rh, wh, w0h, _ = pi_inverse(r, w)
    back = hysteresis_input(v, rh, wh / w0h, initial) * w0h
    np.testing.assert_allclose(back, u, atol=1e-12)


def test_compensator_inverts_hysteresis_and_creep():
    t = np.arange(int(0.5 / H)) * H
    r = np.zeros_like(t)
    for s, level in ((0.01, 1.0), (0.15, 0.3), (0.3, 0.7)):
        r[t >= s] = level
    hyst = {"r": [0.05, 0.15, 0.3], "w": [0.15, 0.1, 0.05], "initial": "centred"}
    model = DEMO.with_effects(hysteresis=hyst)
    comp = CreepCompensator(H, model)
    u = comp.command_block(r)
    y = model.simulate(t, u)
    ref = shaped_reference(t, r, comp.tau)
    late = (t > 0.02) & ~((t >= 0.15) & (t < 0.16)) & ~((t >= 0.3) & (t < 0.31))
    assert np.max(np.abs(y - ref)[late]) < 1e-4
    without = simulate(DEMO, t, CreepCompensator(H, DEMO).command_block(r))
    assert np.max(np.abs(model.simulate(t, CreepCompensator(H, DEMO).command_block(r)) - ref)[late]) > 0.05
    assert np.max(np.abs(without - ref)[late]) < 1e-4


def test_bad_input_is_one_clear_error():
    with pytest.raises(DataError, match="u_min must be below u_max"):
        CreepCompensator(H, u_min=1.0, u_max=0.0)
    with pytest.raises(DataError, match="bandwidth_hz"):
        CreepCompensator(H, bandwidth_hz=1e5)
    with pytest.raises(DataError, match="reference must be finite"):
        CreepCompensator(H, DEMO).command(float("nan"))
    with pytest.raises(ModelError, match="cannot invert delay"):
        CreepCompensator(H, DEMO.with_effects(delay={"delay_s": 1e-3}))
    with pytest.raises(ModelError, match="not monotone"):
        CreepCompensator(H, DEMO.with_effects(hysteresis={"r": [0.1, 0.2], "w": [-0.7, -0.5]}))


def test_without_a_model_the_reference_passes_through():
    comp = CreepCompensator(H, u_max=1.0)
    assert comp.command(0.4) == 0.4 and comp.command(3.0) == 1.0 and comp.clipped == 1
    assert comp.get_params()["u_max"] == 1.0 and comp.get_params()["model"] is None


def adaptive_vs_frozen(seed: int, duration: float = 30.0, **est_kwargs) -> float:
    """frozen / adaptive creep error (max abs, holds after the first) on a random drifting plant.

    10 kHz; alpha +20 % and b +10 % over the run; a random 5-level staircase; the compensators take the
    live estimate (adaptive: every 1 ms while the estimate is good; frozen: its first good one only)."""
    from creep_online.online import OnlineEstimator
    from creep_online.metrics import creep_error
    from hil_sim.closed_loop import run_closed_loop, staircase
    rng = np.random.default_rng(seed)
    plant = CreepModel.from_resonance(rng.uniform(0.05, 0.3), rng.uniform(200.0, 800.0), rng.uniform(0.03, 0.2),
                                      rng.uniform(1.0, 4.0))
    t = np.arange(int(duration / H)) * H
    r = staircase(t, rng.uniform(0.2, 1.0, 5), duration / 5, t_start=0.05)
    alpha = plant.alpha * (1 + 0.2 * t / duration)
    b = plant.b * (1 + 0.1 * t / duration)
    err = {}
    for mode in ("frozen", "adaptive"):
        rec = run_closed_loop(t, r, plant, mode, alpha=alpha, b=b, estimator=OnlineEstimator(H, **est_kwargs),
                              compensator=CreepCompensator(H, bandwidth_hz=plant.fn / 2), block=100, seed=seed)
        err[mode] = creep_error(t, r, rec.y_clean, plant.settling_time, skip_before=duration / 5)["max_abs"]
    return err["frozen"] / err["adaptive"]


def test_adaptive_beats_frozen_on_a_drifting_random_plant():
    """The issue's goal (>= 5x smaller creep error for adaptive) on one seeded random plant (~10 s), with the
    default estimator (its change test predicts with the drift rates: no false change in compensated holds)."""
    ratio = adaptive_vs_frozen(1)
    print(f"adaptive vs frozen, seed 1: {ratio:.1f}x")
    assert ratio >= 5


@pytest.mark.slow
def test_adaptive_beats_frozen_on_drifting_random_plants():
    """Random drifting plants 0-7 over the issue's ranges (``random_drifting_plant``: alpha 0.02-0.6,
    fn 100-2000 Hz, zeta 0.02-0.7, b of either sign 0.1-10; 60 s, alpha +20 %, b +10 %), default estimator
    and ``detect_changes=False``, the adaptive loop through ``online.gate.ModelGate``. The frozen-time oracle
    (true parameters every 10 ms) bounds what any adaptive compensator can do (it reaches 5x on plants 1, 2, 4
    only: a large alpha's drift re-weights the history). Measured (bench ``random_plants``, default
    estimator; this test: the same with detect_changes=False): adaptive within 1.25x of the oracle on 8 of 8,
    5x on 1, 2 and 4. Before the gate (only
    ``good`` estimates): 6 of 8, 5x on 1 and 2; plant 4 (a wrong resonance called good, refused) and plant 5
    (never ``good``: pass-through for 60 s) missed."""
    from hil_sim.closed_loop import drifting_comparison
    seeds = range(8)
    oracle = {s: drifting_comparison(s, 60.0, modes=("oracle",))["oracle"] for s in seeds}
    for kwargs in ({}, {"detect_changes": False}):
        runs = {s: drifting_comparison(s, 60.0, kwargs, modes=("frozen", "adaptive")) for s in seeds}
        ratio = np.array([runs[s]["frozen"] / runs[s]["adaptive"] for s in seeds])
        limit = np.array([runs[s]["frozen"] / oracle[s] for s in seeds])
        near = np.array([runs[s]["adaptive"] <= 1.25 * oracle[s] for s in seeds])
        print(f"adaptive vs frozen {kwargs or 'default'}: {np.mean(ratio >= 5):.0%} of {len(seeds)} plants reach 5x "
              f"(ratios {np.round(ratio, 1).tolist()}; oracle {np.round(limit, 1).tolist()})")
        assert near.sum() >= 7 and np.sum(ratio[limit >= 5] >= 5) >= 3


def _adaptive_on_drifting_plant(seed: int, seconds: float, hold_s: float, drift_s: float):
    """Random drifting plant ``seed`` under adaptive compensation (alpha +20 %, b +10 % over ``drift_s``):
    (the estimator after the run, alpha(t), b(t))."""
    from creep_online.online import OnlineEstimator
    from hil_sim.closed_loop import random_drifting_plant, run_closed_loop, staircase
    plant, levels = random_drifting_plant(seed)
    t = np.arange(int(seconds / H)) * H
    r = staircase(t, levels, hold_s, t_start=0.05)
    alpha = plant.alpha * (1 + 0.2 * t / drift_s)
    b = plant.b * (1 + 0.1 * t / drift_s)
    est = OnlineEstimator(H)
    run_closed_loop(t, r, plant, "adaptive", alpha=alpha, b=b, estimator=est,
                    compensator=CreepCompensator(H, bandwidth_hz=plant.fn / 2), block=100, seed=seed)
    return est, alpha, b


def test_the_change_test_stays_quiet_on_a_drifting_compensated_plant():
    """Adaptive compensation of a drifting plant (random drifting plant 2: alpha 0.17 +20 %, b +10 % over
    30 s): flat holds, then steps. The change test predicts its last second with the window's drift rates;
    without them (alpha's drift over a second is ~5 noise levels here) the step at 5 s, just after the
    rates came on, was taken for a change, the window restarted, and re-searches on flat holds took a wrong
    resonance (before the fix: events at 5.5 and 11 s, b -97 % at 12 s; creep error 3787 by the end of a 30 s
    run)."""
    est, alpha, b = _adaptive_on_drifting_plant(2, seconds=12.0, hold_s=5.0, drift_s=30.0)
    e = est.estimate
    print(f"events {est.events}, quality {e.quality}, alpha {e.alpha / alpha[-1] - 1:+.2%}, b {e.b / b[-1] - 1:+.2%}")
    assert est.events == [] and e.quality == "good"
    assert abs(e.alpha / alpha[-1] - 1) < 0.01 and abs(e.b / b[-1] - 1) < 0.01


def test_an_undetermined_resonance_does_not_move_in_a_flat_hold():
    """Random drifting plant 1008 (alpha 0.12, 1142 Hz, zeta 0.17, b -9.3; drift over 60 s), compensated: in
    the flat hold after 10 s the last second barely determines the resonance (ln a2 1-sigma 0.4), and its fit
    wanders (a2 +232 %). Judged in ln a2, the scale of its 1-sigma, that is 3 sigma, not 5.9 as exp(d) - 1:
    no change. Before: an event at 14.5 s, the window restarted and no estimate was good for 25 s."""
    est, _, _ = _adaptive_on_drifting_plant(1008, seconds=16.0, hold_s=10.0, drift_s=60.0)
    print(f"events {est.events}, quality {est.estimate.quality}")
    assert est.events == [] and est.estimate.quality == "good"


def test_creep_error_windows():
    """metrics.creep_error: each hold from settle_s after its step to its end, early holds skipped."""
    from creep_online.metrics import creep_error
    t = np.arange(1000) * 0.01
    r = np.where(t >= 1.0, 1.0, 0.0) + np.where(t >= 5.0, 1.0, 0.0)
    y = r.copy()
    y[(t >= 1.0) & (t < 1.2)] += 5.0          # the transient: excluded
    y[(t >= 3.0) & (t < 5.0)] += 0.1          # creep in the first hold
    y[t >= 9.0] -= 0.3                        # creep in the second hold
    ce = creep_error(t, r, y, settle_s=0.5)
    assert [p["t"] for p in ce["per_hold"]] == [1.0, 5.0]
    assert ce["max_abs"] == pytest.approx(0.3) and ce["per_hold"][0]["max_abs"] == pytest.approx(0.1)
    assert [p["t"] for p in creep_error(t, r, y, 0.5, skip_before=2.0)["per_hold"]] == [5.0]


def test_the_gate_takes_creep_when_the_resonance_stays_undetermined(monkeypatch):
    """Random drifting plant 1015 (alpha 0.23, 616 Hz, zeta 0.46, b -0.115; drift over 60 s): in pass-through
    the estimator determines alpha and b at once but not a1 (2.8-6 % 1-sigma against the 2.5 % limit), so it
    says ``provisional``, and a compensator that waits for ``good`` never left pass-through in 60 s (before
    the gate: 0.6x the frozen compensator's creep error). The gate (``online.gate.ModelGate``) takes alpha
    and b with the estimate's resonance (a1, a2 known to within half their value) within the first second,
    while the estimate says ``provisional`` and why; the second hold's creep error is the oracle's."""
    import hil_sim.closed_loop as CL
    from creep_online.metrics import creep_error
    from creep_online.online import OnlineEstimator
    from creep_online.online.gate import ModelGate
    taken = []

    class Recording(ModelGate):
        def model(self, estimate):
            m = super().model(estimate)
            if m is not None and not taken:
                taken.append((estimate.t, estimate.quality, estimate.reason, list(estimate.determined), self.source))
            return m

    monkeypatch.setattr(CL, "ModelGate", Recording)
    plant, levels = CL.random_drifting_plant(1015)
    t = np.arange(int(20.0 / H)) * H
    r = CL.staircase(t, levels, 10.0, t_start=0.05)
    alpha, b = plant.alpha * (1 + 0.2 * t / 60.0), plant.b * (1 + 0.1 * t / 60.0)
    err = {}
    for mode in ("adaptive", "oracle"):
        rec = CL.run_closed_loop(t, r, plant, mode, alpha=alpha, b=b, estimator=OnlineEstimator(H, input_gate=0.0),
                                 block=100, seed=1015, compensator=CreepCompensator(H, bandwidth_hz=plant.fn / 2))
        err[mode] = creep_error(t, r, rec.y_clean, plant.settling_time, skip_before=10.0)["max_abs"]
    print(f"first model taken: {taken}; creep error, second hold: {err}")
    t0, quality, reason, determined, source = taken[0]
    assert t0 < 1.0 and quality == "provisional" and reason.startswith("a1 not yet determined")   # still says so
    assert {"alpha", "b"} <= set(determined) and "a1" not in determined and source == "rough"
    assert err["adaptive"] < 1.25 * err["oracle"]


def test_model_gate_rules():
    """``ModelGate`` on hand-made estimates: nothing without alpha and b or before the dwell; the estimate's
    resonance when determined (remembered), the remembered one while it is not, a rough one (1-sigma below
    half of a1 and a2) only when none was ever determined, none when the resonance is not even rough."""
    from types import SimpleNamespace
    from creep_online.online.gate import DWELL_S, ModelGate

    def est(t, determined, a1=1e-4, a2=2e-8, rel=(0.1, 0.1)):
        return SimpleNamespace(t=t, alpha=0.3, b=2.0, a1=a1, a2=a2, determined=determined,
                               uncertainty={"a1": rel[0] * a1, "a2": rel[1] * a2})
    g = ModelGate()
    assert g.model(est(0.0, ["a1", "a2"])) is None                       # no creep part: nothing
    assert g.model(est(0.1, ["alpha", "b"], rel=(0.6, 0.1))) is None     # dwell not over yet
    assert g.model(est(0.1 + DWELL_S, ["alpha", "b"], rel=(0.6, 0.1))) is None   # a1 not even rough
    m = g.model(est(0.2 + DWELL_S, ["alpha", "b"]))
    assert (m.a1, m.a2, g.source) == (1e-4, 2e-8, "rough")
    m = g.model(est(0.3 + DWELL_S, ["alpha", "b", "a1", "a2"], a1=2e-4, a2=3e-8))
    assert (m.a1, m.a2, g.source) == (2e-4, 3e-8, "determined")
    m = g.model(est(0.4 + DWELL_S, ["alpha", "b"], a1=9e-4, a2=9e-8))
    assert (m.a1, m.a2, m.alpha, m.b, g.source) == (2e-4, 3e-8, 0.3, 2.0, "held")
    assert g.model(est(0.5 + DWELL_S, [])) is None and g.model(est(0.6 + DWELL_S, ["alpha", "b"])) is None


@pytest.mark.parametrize("feed", ["block", "sample"])
def test_a_drift_before_the_drift_columns_is_not_a_change(feed, monkeypatch):
    """Random drifting plant 1010 (alpha 0.075, 498 Hz, zeta 0.64, b -4.98), compensated with the policy that
    takes only 'good' estimates: the change test of the flat hold [0.5, 1.5] s read the drift (~4 noise
    levels per second, before the window fits drift) as a1 +35 %, a2 -26 % and restarted the window;
    the re-searches on compensated holds never recovered (creep error 1.2e4 against the oracle's 0.039).
    The change test now fits the drift itself while the window does not (its own test:
    test_online_kernels.test_the_change_test_fits_a_drift_the_window_does_not). Before the drift rates
    come in the window misfits the drift (1.8x the floor at 0.2 s, 25x at 1.2 s) and reads no 'good': fed sample
    by sample (``update()``; the loop's blocks passed on one sample at a time) the loop has no model until the
    rates switch on: at 1.3 s with the default ``drift_min_s`` (1 s); with 2.5 s at 2.9 s, and the creep error is
    then 4.06 against the oracle's 0.040. Both feedings are held."""
    import creep_online.online as online
    from hil_sim.closed_loop import drifting_comparison
    if feed == "sample":
        class PerSample(online.OnlineEstimator):
            def update_block(self, u, y):
                for uk, yk in zip(u, y):
                    self.update(float(uk), float(yk))
        monkeypatch.setattr(online, "OnlineEstimator", PerSample)
    res = drifting_comparison(1010, 12.0, {"input_gate": 20.0}, modes=("oracle", "adaptive"), gate=False)
    assert res["adaptive"] < 1.25 * res["oracle"], res
