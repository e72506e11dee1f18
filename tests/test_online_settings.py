"""The estimator's tunables as one settings object (``online/settings.py``): validated, stored verbatim, used."""
from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from creep_online.errors import DataError
from creep_online.model import CreepModel
from creep_online.online import OnlineEstimator
from creep_online.online.trackers.recursive import RecursiveTracker
from creep_online.online.settings import (DEFAULT_SETTINGS, DeterminedLimits, OnlineSettings, QualitySettings,
                                          RecoverySettings, StartupSettings)
from creep_online.online.trackers.settings import TrackerSettings
from creep_online.online.trackers.window import WindowTracker
from creep_online.online.trackers import Tracker
from creep_online.simulate import simulate


def _staircase(h: float = 1e-3, seconds: float = 6.0):
    t = np.arange(int(seconds / h)) * h
    rng = np.random.default_rng(7)
    u = np.where(t < 0.05, 0.0, rng.uniform(-1, 1, 64)[np.floor(t / 0.4).astype(int)])
    y = simulate(CreepModel.from_resonance(0.15, 30.0, 0.2, 1.2), t, u)
    return u, y + rng.normal(0, 1e-3 * np.std(y), t.size)


@pytest.mark.parametrize("build", [
    lambda: StartupSettings(idle_keep=0),
    lambda: StartupSettings(idle_keep=5000),
    lambda: StartupSettings(box_growth=float("nan")),
    lambda: StartupSettings(max_search_samples=1 << 20),
    lambda: RecoverySettings(gap_replay_max=1.5),
    lambda: RecoverySettings(startup_faults=True),
    lambda: QualitySettings(good_ratio=3.0),
    lambda: QualitySettings(floor_ratio=-1.0),
    lambda: QualitySettings(determined={"alpha": 0.01}),
    lambda: DeterminedLimits(a1=0.0),
    lambda: OnlineSettings(quality=1.2),
    lambda: OnlineSettings().replace(qualty={"good_ratio": 1.5}),
    lambda: OnlineSettings().replace(quality={"good": 1.5}),
    lambda: OnlineEstimator(1e-3, settings={"quality": {}}),
    lambda: OnlineEstimator(1e-3, window_s=0.1, settings=OnlineSettings().replace(memory={"min_window_samples": 200})),
])
def test_a_bad_setting_is_a_one_line_data_error(build):
    with pytest.raises(DataError) as err:
        build()
    assert "\n" not in str(err.value)


def test_settings_are_a_parameter_like_the_others():
    cfg = OnlineSettings().replace(quality={"good_ratio": 1.5}, recovery=RecoverySettings(startup_faults=5))
    assert cfg.quality.good_ratio == 1.5 and cfg.recovery.startup_faults == 5 and cfg.startup == StartupSettings()
    est = OnlineEstimator(1e-3, settings=cfg)
    assert est.get_params()["settings"] is cfg
    assert "settings=" in repr(est) and "settings=" not in repr(OnlineEstimator(1e-3))
    twin = est.clone()
    assert twin.settings == cfg and twin.settings is not cfg
    assert est.clone({"settings": None}).settings is None
    est.set_params(settings=DEFAULT_SETTINGS)
    assert est._settings is DEFAULT_SETTINGS
    with pytest.raises(DataError):
        est.set_params(settings=3)
    assert est.settings is DEFAULT_SETTINGS
    assert pickle.loads(pickle.dumps(cfg)) == cfg and copy.deepcopy(cfg) == cfg
    with pytest.raises(AttributeError):
        cfg.quality = QualitySettings()                # frozen


def test_the_estimator_uses_its_settings():
    """The same stream under other thresholds: a stricter "good" (quality), a shorter replayed gap (recovery);
    the defaults give what ``settings=None`` gives."""
    u, y = _staircase()
    plain, same = OnlineEstimator(1e-3), OnlineEstimator(1e-3, settings=OnlineSettings())
    plain.update_block(u, y)
    same.update_block(u, y)
    assert plain.estimate == same.estimate and plain.estimate.quality == "good", plain.estimate.reason
    strict = OnlineEstimator(1e-3, settings=OnlineSettings().replace(
        quality={"determined": DeterminedLimits(alpha=1e-9)}))
    strict.update_block(u, y)
    e = strict.estimate
    assert e.quality == "provisional" and e.reason.startswith("alpha not yet determined"), e.reason
    assert e.alpha == plain.estimate.alpha                       # the rule reports; it changes no estimate
    short = OnlineEstimator(1e-3, settings=OnlineSettings().replace(recovery={"gap_replay_max": 10}))
    short.update_block(u, y)
    short.gap(11)                                                # longer than replayed: a restart
    assert short.estimate.phase == "buffering" and "restarting after 11 lost samples" in short.estimate.reason
    plain.gap(11)
    assert plain.estimate.phase == "tracking"


@pytest.mark.parametrize("refit", ["window", "recursive"])
def test_the_trackers_settings_reach_the_tracker_through_the_estimator(refit):
    """``OnlineSettings.trackers`` (a ``TrackerSettings``, or a dict of its fields to change) is what the tracker the
    estimator builds runs with; None gives the trackers' defaults; anything else is a one-line DataError."""
    u, y = _staircase(seconds=3.0)
    cfg = OnlineSettings().replace(trackers={"relinearize": 0.05})
    assert cfg.trackers == TrackerSettings(relinearize=0.05)
    est = OnlineEstimator(1e-3, refit=refit, settings=cfg)
    est.update_block(u, y)
    assert est._tracker.settings is cfg.trackers
    plain = OnlineEstimator(1e-3, refit=refit)
    plain.update_block(u, y)
    assert plain._tracker.settings == TrackerSettings()
    with pytest.raises(DataError, match="TrackerSettings has no setting 'nonsense'"):
        OnlineSettings().replace(trackers={"nonsense": 1})
    with pytest.raises(DataError, match="must be a TrackerSettings"):
        OnlineSettings(trackers={"relinearize": 0.05})


@pytest.mark.parametrize("refit, kind", [("window", WindowTracker), ("recursive", RecursiveTracker)])
def test_both_trackers_satisfy_the_declared_protocol(refit, kind):
    u, y = _staircase(seconds=3.0)
    est = OnlineEstimator(1e-3, refit=refit)
    est.update_block(u, y)
    tr = est._tracker
    assert isinstance(tr, kind) and isinstance(tr, Tracker)
    assert tr.state_finite() and tr.adapting and tr.noise_level > 0
    est.freeze()
    assert not tr.adapting
    est.unfreeze()
    assert tr.adapting
    assert est.predict_one(0.5) == tr.predict_next(0.5 - est._u_ref)
