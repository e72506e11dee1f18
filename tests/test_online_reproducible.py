"""An online estimate is a function of the data alone, not of what numba's cache held when the kernels compiled.

A kernel compiled with fast-math flags is optimised together with the kernels it calls when they are compiled in
the same process and apart from them when they are loaded from the cache, so its last bits (and the decisions that
hang on them) would follow the cache's history: a user who ran the recursive tracker once would get other window
estimates afterwards. Each run below compiles into a cache of its own that starts empty (about 20-40 s of
compilation each: a long test).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.long

#: Two scenario records (one from rest, one taken in operation), fed in 0.1 s blocks; the estimate after each block.
RUN = """
import json, sys
from creep_online.online import OnlineEstimator
from hil_sim import scenarios
out = []
for refit in sys.argv[1].split(","):
    for family in ("payload", "mid_operation"):
        s = scenarios.make(family, 0)
        est = OnlineEstimator(s.h, refit=refit)
        step = int(round(0.1 / s.h))
        for k in range(0, min(s.u.size, 30000), step):
            est.update_block(s.u[k:k + step], s.y[k:k + step])
            e = est.estimate
            out.append([refit, family, k, e.quality, e.alpha, e.a1, e.a2, e.b])
print(json.dumps(out))
"""


def _estimates(cache: Path, trackers: str) -> str:
    """The trajectories of ``trackers`` (comma-separated ``refit`` values) run with ``cache`` as numba's cache."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    done = subprocess.run([sys.executable, "-c", RUN, trackers], env=env, capture_output=True, text=True,
                          timeout=900, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_window_estimates_do_not_depend_on_what_the_cache_held(tmp_path):
    alone = _estimates(tmp_path / "fresh", "window")
    _estimates(tmp_path / "grown", "recursive")           # the other tracker's kernels compiled and cached first
    after = _estimates(tmp_path / "grown", "window")
    first = next((pair for pair in zip(json.loads(alone), json.loads(after)) if repr(pair[0]) != repr(pair[1])), None)
    assert first is None, f"first estimate that differs (fresh cache, then grown cache): {first}"
    assert after == alone
