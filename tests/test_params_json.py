"""One parameter grammar (creep_online/io/params.py) and one JSON normaliser (creep_online/io/jsonable.py)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from creep_online.cli import main
from creep_online.errors import ModelError
from creep_online.io.csvfile import load_csv
from creep_online.io.jsonable import json_text, jsonable
from creep_online.io.params import parse_params
from creep_online.model import CreepModel
from hil_sim import plant


def test_both_forms_give_the_same_model():
    by_resonance = parse_params("alpha=0.3,fn=400,zeta=0.1,b=2")
    by_coefficients = parse_params(f"alpha=0.3,a1={by_resonance.a1!r},a2={by_resonance.a2!r},b=2")
    assert by_resonance == CreepModel.from_resonance(0.3, 400.0, 0.1, 2.0) == by_coefficients
    assert parse_params("alpha=0.3,a1=0.01,a2=1e-4").b == 1.0


@pytest.mark.parametrize("text, words", [
    ("alpha=0.3,a1=0.01,a2=1e-4,fn=3", "not both"),
    ("alpha=0.3,fn=400", "missing zeta"),
    ("alpha=0.3,fn=-4,zeta=0.1", "fn and zeta must be > 0"),
    ("alpha=0.3,omega=2", "expected alpha=..,a1=..,a2=..,b=.. or alpha=..,fn=..,zeta=..,b=.."),
])
def test_bad_text_is_a_one_line_model_error(text, words):
    with pytest.raises(ModelError, match=None) as info:
        parse_params(text)
    assert words in str(info.value) and len(str(info.value).splitlines()) == 1


def test_simulate_accepts_fn_and_zeta(tmp_path, capsys):
    (tmp_path / "in.csv").write_text("t,u\n" + "".join(f"{k * 1e-3},1\n" for k in range(50)))
    outs = []
    for params in ("alpha=0.3,fn=40,zeta=0.2,b=2", "alpha=0.3,a1={a1!r},a2={a2!r},b=2"):
        m = CreepModel.from_resonance(0.3, 40.0, 0.2, 2.0)
        out = tmp_path / f"o{len(outs)}.csv"
        assert main(["simulate", "--params", params.format(a1=m.a1, a2=m.a2), "--input",
                     str(tmp_path / "in.csv"), "-o", str(out)]) == 0
        outs.append(load_csv(out).y)
    assert np.array_equal(outs[0], outs[1])


def test_hil_sim_overlays_creep_onlines_grammar_on_its_demo_plant():
    demo = plant.parse_params("")
    assert demo == CreepModel.from_resonance(**plant.DEFAULT_PARAMS)
    assert plant.parse_params("alpha=0.2") == CreepModel.from_resonance(0.2, 420.0, 0.08, 2.5)
    assert plant.parse_params("a1=1e-3,a2=1e-6") == CreepModel(0.12, 1e-3, 1e-6, 2.5)
    with pytest.raises(ValueError, match="missing a2"):       # was: a lone a1 silently ignored
        plant.parse_params("alpha=0.1,a1=3")
    with pytest.raises(ValueError, match="got 'noise=1'"):    # was: unknown names silently ignored
        plant.parse_params("alpha=0.1,noise=1")


def test_jsonable_makes_strict_json():
    doc = {"nan": math.nan, "inf": np.float64(np.inf), "arr": np.array([1.0, np.nan]), "n": np.int64(3),
           "ok": np.bool_(True), 4: (1.5, -math.inf)}
    assert jsonable(doc) == {"nan": None, "inf": None, "arr": [1.0, None], "n": 3, "ok": True, "4": [1.5, None]}
    strict = json.loads(json_text(doc), parse_constant=lambda c: pytest.fail(f"non-JSON token {c}"))
    assert strict["arr"] == [1.0, None]
