"""scikit-learn and river conventions of the online objects: get_params, set_params, clone, repr, number inputs."""
import math

import numpy as np
import pytest
from sklearn.base import clone as sk_clone

from creep_online import CreepModel, DataError
from creep_online.online import CreepCompensator, ModelGate, OnlineEstimator
from creep_online.online.stored_params import StoredParams

H = 1e-3
MODEL = CreepModel(0.1, 1e-3, 1e-6, 1.0)


def _fed(n: int = 3000) -> OnlineEstimator:
    est = OnlineEstimator(H, window_s=2.0)
    t = np.arange(n) * H
    u = np.where(t > 0.1, 1.0, 0.0)
    est.update_block(u, 0.5 * u + 1e-3 * np.sin(t))
    return est


class Outer(StoredParams):
    """A holder of a compensator: the nested names of scikit-learn's pipelines (``inner__u_max``)."""

    def __init__(self, inner: CreepCompensator, gain: float = 1.0) -> None:
        self.inner = inner
        self.gain = gain

    def _validate(self) -> None:
        if not isinstance(self.gain, float):
            raise DataError(f"gain must be a float, got {self.gain!r}")

    def reset(self) -> "Outer":
        return self


@pytest.mark.parametrize("obj", [OnlineEstimator(H, window_s=5.0, refit="recursive", alpha_bounds=(0.01, 0.9)),
                                 CreepCompensator(H, MODEL, u_min=-1.0, u_max=2.0), ModelGate()],
                         ids=["estimator", "compensator", "gate"])
def test_sklearn_clone_makes_a_new_object_with_the_same_parameters(obj):
    copy = sk_clone(obj)
    assert type(copy) is type(obj) and copy is not obj
    assert copy.get_params(deep=False) == obj.get_params(deep=False)
    assert repr(copy) == repr(obj)
    assert obj.get_params(deep=True) == obj.get_params(deep=False)      # no argument has parameters of its own


def test_constructor_arguments_are_stored_verbatim():
    bounds = (0.01, 0.9)
    est = OnlineEstimator(H, alpha_bounds=bounds, work_units=3)
    assert est.get_params()["alpha_bounds"] is bounds
    comp = CreepCompensator(H, MODEL)
    assert comp.get_params(deep=False)["model"] is MODEL


def test_clone_forgets_what_was_learned():
    est = _fed()
    assert est.samples == 3000
    for copy in (sk_clone(est), est.clone()):
        assert copy.samples == 0 and copy.estimate.phase == "buffering"
        assert copy.get_params() == est.get_params()


def test_river_clone_replaces_the_given_parameters():
    est = OnlineEstimator(H, window_s=5.0)
    copy = est.clone({"window_s": 2.0, "refit": "recursive"})
    assert copy.window_s == 2.0 and copy.refit == "recursive" and copy.dt == H
    assert est.window_s == 5.0
    with pytest.raises(DataError, match="no parameter 'windw_s'"):
        est.clone({"windw_s": 1.0})


def test_set_params_returns_self_and_starts_again():
    est = _fed()
    assert est.set_params(window_s=3.0, refit="recursive") is est
    assert est.window_s == 3.0 and est.refit == "recursive"
    assert est.samples == 0 and est.estimate.phase == "buffering"
    assert est.get_params() == OnlineEstimator(H, window_s=3.0, refit="recursive").get_params()
    comp = CreepCompensator(H, MODEL, u_max=1.0)
    assert comp.set_params(u_max=0.5) is comp
    assert comp.command(2.0) <= 0.5
    assert est.set_params() is est


@pytest.mark.parametrize("params, words", [({"windowS": 1.0}, "no parameter 'windowS'"),
                                           ({"dt": "0.001"}, "dt must be a positive finite number"),
                                           ({"dt": 1e-3, "refit": "rls"}, "refit must be one of"),
                                           ({"refit__x": 1}, "has no parameters of its own")])
def test_set_params_refuses_in_one_line_and_changes_nothing(params, words):
    est = _fed()
    before = est.get_params()
    with pytest.raises(DataError) as info:
        est.set_params(**params)
    message = str(info.value)
    assert words in message and "\n" not in message
    assert est.get_params() == before and est.samples == 3000


def test_nested_parameters_as_scikit_learn_names_them():
    comp = CreepCompensator(H, MODEL, u_max=1.0)
    outer = Outer(comp)
    deep = outer.get_params(deep=True)
    assert deep["inner"] is comp and deep["inner__u_max"] == 1.0 and deep["inner__model"] is MODEL
    assert set(outer.get_params(deep=False)) == {"inner", "gain"}
    assert outer.set_params(inner__u_max=2.0, gain=3.0) is outer
    assert comp.u_max == 2.0 and outer.gain == 3.0
    copy = sk_clone(outer)
    assert copy.inner is not comp and copy.inner.get_params() == comp.get_params()
    with pytest.raises(DataError, match="CreepCompensator has no parameter 'u_mx'"):
        outer.set_params(gain=5.0, inner__u_mx=1.0)
    assert outer.gain == 3.0                                   # nothing changed


def test_repr_names_the_parameters_that_differ_from_the_defaults():
    assert repr(OnlineEstimator(H)) == "OnlineEstimator(dt=0.001)"
    assert repr(OnlineEstimator(H, window_s=None, refit="recursive", alpha0=0.3)) == \
        "OnlineEstimator(dt=0.001, window_s=None, alpha0=0.3, refit='recursive')"
    assert repr(OnlineEstimator(H, window_s=10.0)) == "OnlineEstimator(dt=0.001)"     # the default, given
    assert repr(CreepCompensator(H, u_min=-1)) == "CreepCompensator(dt=0.001, u_min=-1)"
    assert repr(ModelGate()) == "ModelGate()"
    est = OnlineEstimator(2e-4, window_s=5.0, detect_changes=False)
    again = eval(repr(est), {"OnlineEstimator": OnlineEstimator})
    assert again.get_params() == est.get_params()


@pytest.mark.parametrize("bad", ["1.0", b"1", None, True, 1 + 0j, [1.0]])
def test_update_refuses_what_is_not_a_number(bad):
    est = OnlineEstimator(H)
    for args in ((bad, 0.5), (0.5, bad)):
        with pytest.raises(DataError) as info:
            est.update(*args)
        assert "must be a number" in str(info.value) and "\n" not in str(info.value)
    assert est.samples == 0
    comp = CreepCompensator(H, MODEL)
    with pytest.raises(DataError, match="must be a number"):
        comp.command(bad)


@pytest.mark.parametrize("bad", [["1.0", "2.0"], np.array([True, False]), np.array([1j, 2j]), "12"])
def test_blocks_refuse_what_is_not_numbers(bad):
    est = OnlineEstimator(H)
    with pytest.raises(DataError):
        est.update_block(bad, np.zeros(2))
    with pytest.raises(DataError):
        CreepCompensator(H, MODEL).command_block(bad)
    assert est.samples == 0


def test_numbers_of_every_numeric_type_are_taken():
    est = OnlineEstimator(H)
    for u, y in ((1, 2), (np.float32(0.5), np.float64(0.25)), (np.int64(1), 0.5), (math.nan, 1.0)):
        est.learn_one(u, y)
    assert est.samples == 3 and est.skipped_nonfinite == 1
    assert isinstance(CreepCompensator(H, MODEL).command(np.float32(0.5)), float)
