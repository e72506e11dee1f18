"""``bench_diagnose_bands.py --merge``: runs and earlier merges over consecutive seeds make one table."""
from __future__ import annotations

import json
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[1]


def _bench():
    from bench import bench_diagnose_bands
    return bench_diagnose_bands


def _run(first: int, n: int, elapsed: float, miss: int | None = None) -> dict:
    """A run document as ``run()`` writes it (rows only as ``cell()`` reads them)."""
    def row(s: int, effect: str | None) -> dict:
        ok = s != miss
        return {"seed": s, "verdict": (effect or "none") if ok else "delay", "named_first": ok,
                "own_fit_over_noise": None if effect is None else (1.0 if ok else 2.0), "seconds": 1.0}
    rows = {"none|clean": [row(s, None) for s in range(first, first + n)],
            "drift|1.3-3x": [row(s, "drift") for s in range(first, first + n)]}
    return {"bench": "diagnose_bands", "records_per_cell": n, "first_seed": first, "load_average": [1.0, 1.0, 1.0],
            "elapsed_s": elapsed, "rows": rows}


def _write(tmp_path: Path, name: str, doc: dict) -> str:
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return str(p)


def test_a_merge_merged_again_with_new_runs_holds_every_run_and_seed(tmp_path):
    bench = _bench()
    earlier = bench.merge([_write(tmp_path, "a.json", _run(0, 3, 30.0)),
                           _write(tmp_path, "b.json", _run(3, 2, 20.0, miss=4))])
    doc = bench.merge([_write(tmp_path, "c.json", _run(7, 2, 25.0)), _write(tmp_path, "ab.json", earlier),
                       _write(tmp_path, "d.json", _run(5, 2, 10.0))])
    assert doc["first_seed"] == 0 and doc["records_per_cell"] == 9
    assert [r["first_seed"] for r in doc["merged_runs"]] == [0, 3, 5, 7]
    assert [r["records_per_cell"] for r in doc["merged_runs"]] == [3, 2, 2, 2]
    assert doc["elapsed_s_sum"] == 85.0 and doc["elapsed_s"] == 30.0 and len(doc["load_average"]) == 4
    assert [r["seed"] for r in doc["rows"]["drift|1.3-3x"]] == list(range(9))
    cell = doc["table"]["drift"]["1.3-3x"]
    assert cell["records"] == 9 and cell["named_first"] == pytest.approx(8 / 9)
    assert cell["at_floor"] == pytest.approx(8 / 9) and cell["verdicts"] == {"drift": 8, "delay": 1}
    assert doc["table"]["none"]["verdicts"] == {"none": 8, "delay": 1}


@pytest.mark.parametrize("firsts", [(0, 4), (0, 2)])     # a gap, an overlap
def test_a_merge_refuses_seeds_that_do_not_follow_on(tmp_path, firsts):
    bench = _bench()
    paths = [_write(tmp_path, f"{i}.json", _run(f, 3, 1.0)) for i, f in enumerate(firsts)]
    with pytest.raises(SystemExit, match="seeds"):
        bench.merge(paths)
