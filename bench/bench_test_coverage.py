"""Which lines of the package the default test suite runs, and what a change to the suite lost.

The default suite (the README's test command) is kept short by running the costliest variants of a path
(``long`` and ``slow`` tests) after it, in CI. That must not leave a line of the package to those tests
alone: this bench measures it. It runs the suite under coverage.py (pytest-cov; the CLI tests' child
processes too, through coverage's ``patch = subprocess``; ``[tool.coverage]`` in pyproject.toml), and
reports the lines covered per file and in all, and, with ``--against`` a report of an earlier run (the
suite before a change: ``--save`` writes one), every line that run covered and this one does not.

``--by-test FILE`` also writes which lines each test ran (pytest-cov's contexts for the test's own process,
``bench/suite_coverage.py`` for its children; a child started with an environment of its own is counted
for no test), and ``--cover REPORT`` (a report of the default suite run ``--against`` the suite before a
change) the cheapest set of this run's tests (by ``tests/durations.json``) that runs every line that
report lost: the tests to keep in the default suite (``tests/conftest.py``: ``ALWAYS_DEFAULT``), e.g.
``-m "long and not slow" --by-test F --cover AFTER.json``.

Usage: python -m bench.bench_test_coverage [-m MARKERS] [--save FILE] [--against FILE] [--by-test FILE]
       [--cover REPORT] [--out FILE]   (MARKERS: pytest's -m; by default the suite's own, ``not slow and not long``)
Needs coverage>=7.10 and pytest-cov (``pip install "coverage>=7.10" pytest-cov``).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import suite_coverage
from bench.harness import ROOT, write_report

PACKAGES = ("creep_online", "hil_sim")


def run_suite(markers: str | None, folder: Path, extra: list[str], by_test: bool = False) -> tuple[int, float]:
    """The suite under coverage, its data in ``folder`` (each test's children's in ``folder/tests`` with
    ``by_test``); (pytest's exit code, wall seconds)."""
    cmd = [sys.executable, "-m", "pytest", "-q", "-n", "auto", "-p", "no:cacheprovider",
           *[f"--cov={p}" for p in PACKAGES], "--cov-report=", *extra]
    if markers is not None:
        cmd += ["-m", markers]
    env = dict(os.environ, COVERAGE_FILE=str(folder / ".coverage"))
    if by_test:
        (folder / "tests").mkdir()
        cmd += ["--cov-context=test", "-p", "bench.suite_coverage"]
        env[suite_coverage.DIR_ENV] = str(folder / "tests")
    t0 = time.time()
    code = subprocess.run(cmd, cwd=ROOT, env=env).returncode
    return code, time.time() - t0


def covered_lines(data_file: Path) -> dict[str, dict[str, list[int]]]:
    """Per source file (relative to the repository): the executable lines and those run."""
    import coverage

    cov = coverage.Coverage(data_file=str(data_file))
    cov.load()
    data = cov.get_data()
    out = {}
    for path in sorted(data.measured_files()):
        rel = os.path.relpath(path, ROOT)
        if rel.startswith("..") or not rel.endswith(".py"):
            continue
        _, statements, _, missing, _ = cov.analysis2(path)
        run = sorted(set(statements) - set(missing))
        out[rel] = {"statements": sorted(statements), "run": run}
    return out


def lines_by_test(folder: Path) -> dict[str, dict[str, set[int]]]:
    """Per test node id: the lines (per file, relative to the repository) it ran, in its own process
    (pytest-cov's contexts in ``folder/.coverage``) and in its children (``folder/tests``)."""
    from coverage import CoverageData

    out: dict[str, dict[str, set[int]]] = {}

    def add(test: str, data: CoverageData, path: str, contexts: set[str] | None = None) -> None:
        rel = os.path.relpath(path, ROOT)
        if rel.startswith("..") or not rel.endswith(".py"):
            return
        if contexts is None:
            lines = data.lines(path) or []
            out.setdefault(test, {}).setdefault(rel, set()).update(lines)
            return
        for line, names in data.contexts_by_lineno(path).items():
            for name in names:
                if name:
                    out.setdefault(name.rsplit("|", 1)[0], {}).setdefault(rel, set()).add(line)

    main = CoverageData(str(folder / ".coverage"))
    main.read()
    for path in main.measured_files():
        add("", main, path, contexts=set())
    numbers = {}
    for log in (folder / "tests").glob("tests.*.jsonl"):
        numbers.update({r["number"]: r["id"] for r in map(json.loads, log.read_text().splitlines())})
    for child in (folder / "tests").glob("child.*"):
        number = child.name.split(".")[1]
        if number not in numbers:
            continue
        data = CoverageData(str(child))
        data.read()
        for path in data.measured_files():
            add(numbers[number], data, path)
    return out


def join_children(folder: Path) -> None:
    """Add the tests' children's data (``folder/tests``) to the run's (``folder/.coverage``)."""
    from coverage import CoverageData

    whole = CoverageData(str(folder / ".coverage"))
    whole.read()
    for child in (folder / "tests").glob("child.*"):
        data = CoverageData(str(child))
        data.read()
        whole.update(data)
    whole.write()


def cheapest_cover(lost: dict[str, list[int]], by_test: dict[str, dict[str, set[int]]],
                   seconds: dict[str, float]) -> tuple[list[dict], int]:
    """Tests that together run every line in ``lost`` (those any test runs), greedily the most lines per second
    first; and the number of lost lines no test of ``by_test`` ran."""
    need = {(f, n) for f, lines in lost.items() for n in lines}
    runs = {t: {(f, n) for f, lines in v.items() for n in lines} & need for t, v in by_test.items()}
    reachable = set().union(*runs.values()) if runs else set()
    left, chosen = need & reachable, []
    while left:
        best = max(runs, key=lambda t: len(runs[t] & left) / max(seconds.get(t, 1.0), 0.05))
        gain = runs[best] & left
        if not gain:
            break
        chosen.append({"test": best, "s": seconds.get(best), "lines": len(gain)})
        left -= gain
    return chosen, len(need - reachable)


def summary(lines: dict) -> dict:
    """Lines covered in all and per file (percent of the executable lines)."""
    total = sum(len(v["statements"]) for v in lines.values())
    run = sum(len(v["run"]) for v in lines.values())
    return {"files": len(lines), "statements": total, "covered": run,
            "percent": round(100.0 * run / total, 2) if total else None}


def lost(before: dict, after: dict) -> dict[str, list[int]]:
    """Lines ``before`` ran that ``after`` does not (per file; a file ``after`` never imported counts whole)."""
    out = {}
    for rel, v in before.items():
        now = set(after.get(rel, {}).get("run", []))
        gone = sorted(set(v["run"]) - now)
        if gone:
            out[rel] = gone
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-m", dest="markers", default=None, help="pytest -m (default: the suite's own)")
    ap.add_argument("--save", help="write the covered lines here (an --against file for a later run)")
    ap.add_argument("--against", help="the covered lines of an earlier run (--save): report what this run lost")
    ap.add_argument("--by-test", help="write each test's lines here")
    ap.add_argument("--cover", help="a report of the default suite run --against the suite before a change: the "
                                    "cheapest tests of this run (needs --by-test) that run every line it lost")
    ap.add_argument("--out", help="write the JSON report here too")
    ap.add_argument("pytest_args", nargs="*", help="more arguments for pytest (after --)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        code, wall = run_suite(args.markers, Path(tmp), args.pytest_args, by_test=bool(args.by_test))
        per_test = lines_by_test(Path(tmp)) if args.by_test else None
        if args.by_test:
            join_children(Path(tmp))
        lines = covered_lines(Path(tmp) / ".coverage")
    if args.save:
        Path(args.save).write_text(json.dumps(lines))
    doc = {"bench": "test_coverage", "markers": args.markers or "the suite's default (not slow and not long)",
           "pytest_exit_code": code, "wall_s": round(wall, 1), "coverage": summary(lines),
           "per_file_percent": {k: round(100.0 * len(v["run"]) / max(len(v["statements"]), 1), 1)
                                for k, v in lines.items()}}
    if args.against:
        before = json.loads(Path(args.against).read_text())
        gone = lost(before, lines)
        doc["against"] = {"file": args.against, "coverage": summary(before),
                          "lines_lost": sum(len(v) for v in gone.values()), "lost": gone}
    if args.cover:
        target = json.loads(Path(args.cover).read_text())["against"]["lost"]
        durations = json.loads((ROOT / "tests" / "durations.json").read_text())["seconds"]
        chosen, unreached = cheapest_cover(target, per_test or {}, durations)
        doc["keep_in_default"] = {"lost_in": args.cover, "tests": chosen,
                                  "seconds": round(sum(c["s"] or 0 for c in chosen), 1),
                                  "lines_no_test_here_ran": unreached}
    if per_test is not None:
        Path(args.by_test).write_text(json.dumps({t: {f: sorted(v) for f, v in d.items()}
                                                  for t, d in per_test.items()}))
    write_report(doc, args.out)
    return 0 if code == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
