"""CreepModel: validation, derived quantities, frequency response."""
import math

import numpy as np
import pytest

from creep_online import CreepModel, ModelError


def test_derived_quantities_match_definitions():
    m = CreepModel(alpha=0.05, a1=0.02, a2=4e-4, b=2.0)
    assert m.fn == pytest.approx(1 / (2 * math.pi * 0.02))
    assert m.zeta == pytest.approx(0.02 / (2 * 0.02))
    back = CreepModel.from_resonance(0.05, m.fn, m.zeta, 2.0)
    assert back.a1 == pytest.approx(m.a1, rel=1e-12) and back.a2 == pytest.approx(m.a2, rel=1e-12)


@pytest.mark.parametrize("kwargs, word", [
    (dict(alpha=0.0, a1=1, a2=1), "alpha"), (dict(alpha=1.0, a1=1, a2=1), "alpha"),
    (dict(alpha=0.5, a1=0, a2=1), "a1"), (dict(alpha=0.5, a1=1, a2=-1), "a2"),
    (dict(alpha=float("nan"), a1=1, a2=1), "alpha"), (dict(alpha=0.5, a1=1, a2=1, b=0), "b"),
    (dict(alpha="0.5", a1=1, a2=1), "alpha"),
])
def test_invalid_parameters_are_refused_with_the_name(kwargs, word):
    with pytest.raises(ModelError, match=word):
        CreepModel(**kwargs)


def test_frequency_response_matches_direct_formula_and_limits():
    m = CreepModel(alpha=0.3, a1=0.01, a2=1e-4, b=2.5)
    f = np.array([0.01, 1.0, m.fn, 1e3])
    s = 2j * np.pi * f
    direct = 2.5 / (s**0.3 * (1 + 0.01 * s + 1e-4 * s**2))
    np.testing.assert_allclose(m.frequency_response(f), direct, rtol=1e-14)
    # low frequency: pure creep, phase -alpha * 90 degrees
    assert np.angle(m.frequency_response(1e-6), deg=True) == pytest.approx(-27.0, abs=1e-3)


def test_creep_law_and_settling_time():
    m = CreepModel.from_resonance(0.2, 10.0, 0.1, b=3.0)
    assert m.creep(2.0, amplitude=0.5) == pytest.approx(0.5 * 3.0 * 2.0**0.2 / math.gamma(1.2))
    # envelope exp(-zeta wn t) falls to 1e-3 at the settling time
    assert math.exp(-m.zeta * m.wn * m.settling_time) == pytest.approx(1e-3)
    over = CreepModel.from_resonance(0.2, 10.0, 3.0)
    slow = over.wn * (3.0 - math.sqrt(8.0))
    assert math.exp(-slow * over.settling_time) == pytest.approx(1e-3)
