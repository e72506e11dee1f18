"""What keeps a long diagnosis' memory down must not change a number: the PI weights solved on the design's
triangular factor, LAPACK's gelsy called directly, a superposer without its rows' spectra, superposers shared by
the designs that hold them, released caches and designs, rows differenced in place."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import lstsq

from creep_online.diagnostics import extended as ext
from creep_online.effects import hysteresis as hy
from creep_online.effects.responses import Superposer


@pytest.mark.parametrize("seed", range(6))
def test_pi_weights_on_the_triangular_factor_match_the_full_design(seed, monkeypatch):
    """Random designs, half of them with a loop whose unconstrained optimum breaks a branch slope (the bounded
    solve), a closed operator pinned: weights, determined count and penalty as on the n x p design itself."""
    rng = np.random.default_rng(seed)
    n, k = 2000, 8
    base = rng.normal(size=(n, 1))
    a = np.hstack([base, base + 0.3 * rng.normal(size=(n, k)), np.ones((n, 1))])
    w = rng.normal(scale=0.3, size=k) if seed % 2 else np.array([0.4, -0.9, -0.6, 0.2, 0.1, 0.05, -0.3, 0.2])
    wy = a @ np.concatenate([[2.0], 2.0 * w, [0.3]]) + 0.05 * rng.normal(size=n)
    opened = np.ones(k, bool)
    opened[-2] = False
    args = (0, np.arange(1, k + 1), opened, 2.0, 0.05 ** 2)
    x, found = hy.solve_pi_weights(a, wy, *args)
    monkeypatch.setattr(hy, "COMPRESS_ROWS", 10 ** 9)           # never compressed: the n x p design throughout
    x_full, found_full = hy.solve_pi_weights(a, wy, *args)
    np.testing.assert_allclose(x, x_full, rtol=1e-10, atol=1e-12 * np.max(np.abs(x_full)))
    assert found["determined"] == pytest.approx(found_full["determined"], rel=1e-10)
    assert found["penalty"] == pytest.approx(found_full["penalty"], rel=1e-8)


@pytest.mark.parametrize("shape", [(6000, 27), (51, 30), (5, 8), (300, 3)])
def test_gelsy_called_directly_is_scipys_lstsq_bit_for_bit(shape):
    rng = np.random.default_rng(shape[0])
    a = rng.normal(size=shape)
    a[:, -1] = a[:, 0]                                             # rank-deficient: the cut-off matters
    b = rng.normal(size=shape[0])
    for m in (a, np.asfortranarray(a)):
        expected = lstsq(m, b, cond=ext.RCOND, lapack_driver="gelsy", check_finite=False)[0]
        assert np.array_equal(ext._gelsy(m, b), expected)


def test_a_superposer_without_spectra_gives_the_same_columns():
    rng = np.random.default_rng(3)
    n = 4000
    x = np.cumsum(rng.normal(size=(5, n)), axis=1)
    t = np.arange(n) * 1e-3
    step = 1.0 - np.exp(-np.arange(n) * 1e-3 / 0.05)
    kept, lean = Superposer(t, x, x_pre=np.zeros(5)), Superposer(t, x, x_pre=np.zeros(5), keep_spectra=False)
    assert lean.spectra is None
    assert np.array_equal(lean.apply(step), kept.apply(step))
    assert np.array_equal(lean.apply(np.vstack([step, step ** 2])), kept.apply(np.vstack([step, step ** 2])))


def test_released_caches_are_built_again_with_the_same_values():
    rng = np.random.default_rng(4)
    n = 3000
    t = np.arange(n) * 1e-3
    u = np.repeat(rng.uniform(-1, 1, size=n // 300), 300)
    y = np.cumsum(u) * 1e-3 + 0.01 * rng.normal(size=n)
    data = ext.prepare(t, u, y)
    design = ext.Design(data, ("second_creep",))
    theta = np.array([0.3, 1.0, -0.5, 0.6, -1.0])[:len(design.names)]
    before = design.cost(theta)
    window = data.explore_data()
    data.release()
    assert set(data._cache) <= {"explore", "superposer"} and data.explore_data() is window
    assert ext.Design(data, ("second_creep",)).cost(theta) == before


def _long_record(n: int = 20_000, seed: int = 5):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    u = np.repeat(rng.uniform(-1, 1, size=n // 250), 250)
    y = np.cumsum(u) * 1e-3 + 0.01 * rng.normal(size=n)
    return ext.prepare(t, u, y)


def test_release_forgets_the_exploration_windows_responses_too():
    data = _long_record()
    window = data.explore_data()
    assert window is not data
    design = ext.Design(data, ("second_creep",))
    theta = np.array([0.3, 1.0, -0.5, 0.6, -1.0])[:len(design.names)]
    before = (design.cost(theta), design.explored().cost(theta))
    assert window._cache                                          # the window's fit remembered its responses
    data.release()
    assert set(data._cache) <= {"explore", "superposer"} and data.explore_data() is window
    assert set(window._cache) <= {"superposer"}
    again = ext.Design(data, ("second_creep",))
    assert (again.cost(theta), again.explored().cost(theta)) == before


def test_designs_on_the_same_rows_share_one_superposer_freed_with_the_last_of_them():
    """A superposer lives as long as a design holds it: two designs (a design and its copy, as on two threads)
    on the same input rows share one, another variant gets its own, and none stays once no design holds it;
    one built again gives the same columns."""
    import gc
    import weakref
    data = _long_record()
    theta_of = (lambda d: np.concatenate([[0.3, 1.0, -0.5], 0.5 * (d.lo[3:] + d.hi[3:])]))
    first = ext.Design(data, ("hysteresis",))
    twin = first.copy()
    other = ext.Design(data, ("hysteresis",), variants={"hysteresis": "ascending"})
    costs = [d.cost(theta_of(d)) for d in (first, twin, other)]
    assert twin.superposer() is first.superposer() and other.superposer() is not first.superposer()
    held = weakref.ref(first.superposer())
    del first, twin
    gc.collect()
    assert held() is None and len(data._cache["superposer"]) == 1       # the ascending variant's: other holds it
    again = ext.Design(data, ("hysteresis",))
    assert again.cost(theta_of(again)) == costs[0]


def test_a_released_design_answers_its_points_and_evaluates_new_ones_the_same():
    """``Design.release`` lets go of the superposer, the weighted design and a coupled design's tangents: the
    points evaluated are answered from the remembered solutions without an evaluation, and the Jacobian (the
    tangent computed again) and a new point give the same numbers as a design that kept everything."""
    data = _long_record(6000)
    for effects in (("hysteresis",), ("hysteresis", "second_creep")):
        kept, freed = ext.Design(data, effects), ext.Design(data, effects)
        theta = np.concatenate([[0.3, 1.0, -0.5], 0.5 * (kept.lo[3:] + kept.hi[3:])])
        moved = theta + 1e-3
        assert kept.cost(theta) == freed.cost(theta)
        freed.release()
        count = freed.nfev
        assert freed.cost(theta) == kept.cost(theta) and freed.nfev == count
        assert np.array_equal(freed.jacobian(theta), kept.jacobian(theta))
        assert freed.cost(moved) == kept.cost(moved)


def test_rows_overwritten_in_place_and_written_into_a_given_array_are_the_same_numbers():
    """``Superposer(overwrite_x=True)`` computes the steps in the rows themselves, and ``apply(out=...)`` writes
    the superposition into the caller's array: both the numbers of the plain superposer, uniform or not."""
    rng = np.random.default_rng(8)
    n = 3000
    x = np.cumsum(rng.normal(size=(4, n)), axis=1)
    for t in (np.arange(n) * 1e-3, np.cumsum(rng.uniform(0.5, 1.5, size=n)) * 1e-3):
        for pre in (None, np.zeros(4)):
            plain = Superposer(t, x, x_pre=pre)
            rows = x.copy()
            inplace = Superposer(t, rows, x_pre=pre, overwrite_x=True)
            assert inplace.dx is rows and np.array_equal(inplace.dx, plain.dx)
            step = (lambda tt: 1.0 - np.exp(-tt / 0.05))
            expected = plain.apply(step)
            out = np.full((6, n), np.nan)
            assert inplace.apply(step, out=out[1:5]) is not None and np.array_equal(out[1:5], expected)


def test_row_spectra_a_few_rows_at_a_time_are_all_rows_at_once(monkeypatch):
    """The superposer's steps (without np.diff's concatenated copy) and spectra computed in batches of rows
    (``Superposer.row_spectra``) are np.diff's and the one transform of every row bit for bit, for batches that
    divide the rows and batches that do not."""
    from scipy.fft import rfft

    from creep_online.effects import responses
    rng = np.random.default_rng(6)
    n = 3000
    x = np.cumsum(rng.normal(size=(11, n)), axis=1)
    sup = Superposer(np.arange(n) * 1e-3, x, x_pre=np.zeros(11))
    assert np.array_equal(sup.dx, np.diff(x, axis=1, prepend=np.zeros((11, 1))))
    assert np.array_equal(Superposer(np.arange(n) * 1e-3, x).dx, np.diff(x, axis=1, prepend=x[:, :1]))
    expected = rfft(sup.dx, sup.nfft, axis=1)
    assert np.array_equal(sup.spectra, expected)
    for rows in (1, 2, 4, 11):
        monkeypatch.setattr(responses, "SCRATCH_BYTES", 8 * sup.nfft * rows)
        assert np.array_equal(sup.row_spectra(), expected)


def test_sharing_the_malloc_arena_is_harmless_anywhere(monkeypatch):
    """The diagnose command's mallopt call runs on glibc and is skipped elsewhere, never raising."""
    from creep_online.commands import diagnose as command
    command.share_malloc_arena()
    monkeypatch.setattr(command.sys, "platform", "darwin")
    command.share_malloc_arena()
