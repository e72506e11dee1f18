"""The default test suite's wall time the way CI runs it: a fresh clone, ``.ci/run`` (the README's quick start).

Each run clones the committed tree (``git clone`` of this repository) into a temporary directory and
runs ``bash .ci/run`` there: a new virtual environment, the package installed with every extra, the
demo, the README's test command (``pytest -q -n auto``) with numba's kernel cache empty, as a
newcomer's first run, then the tests marked ``slow``. Reported per run: each step's wall time and the
load average CI prints beside it, the CPU time of the whole run (user + sys of every child: on a
shared machine the steadier figure), and per test step the pass/fail counts, the sum of the test
times and the 20 slowest tests (pytest's junit XML, setup + call + teardown, which ``.ci/run`` writes
with ``CI_REPORTS``). Target: the default suite <= 300 s on 2 cores.

``--here`` times the README's test command alone in this checkout instead (numba's kernel cache as it
is), with the load average before and after, the run's CPU time and each test's CPU time
(``bench/suite_cpu.py``): their sum, per file and the most expensive tests. On a shared machine the
CPU sums are the figures to compare; wall times grow with the load.

Usage: python -m bench.bench_test_suite [--runs 2] [--keep DIR] [--out FILE]
       python -m bench.bench_test_suite --here [--out FILE]
       python -m bench.bench_test_suite --from-run LOG XML [--out FILE]   (a run made by hand, see below)
       python -m bench.bench_test_suite --durations SUITE_XML LONG_XML   (writes tests/durations.json)
A run made by hand: ``CI_REPORTS=DIR bash .ci/run > LOG 2>&1`` in a fresh clone (XML: DIR/suite.xml).
(prints one JSON document; --out writes it too, e.g. bench/results/test_suite.json)
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

from bench.harness import ROOT, dist, write_report

TARGET_S = 300.0
STEP = re.compile(r"^== (?P<title>.+): (?P<wall>\d+) s wall \(load average (?P<load>[^)]*)\)$", re.M)


def parse_log(text: str) -> dict:
    """The wall time and load average of each ``.ci/run`` step (the lines it prints after each)."""
    steps = {}
    for m in STEP.finditer(text):
        key = "suite" if "test suite" in m["title"] else "install_and_demo" if "quick start" in m["title"] else "slow"
        load = [float(x) for x in m["load"].split()] if m["load"] != "n/a" else None
        steps[key] = {"wall_s": int(m["wall"]), "load_average_after": load}
    summaries = re.findall(r"^=*\s*(\d+ passed.*?) in [\d.]+s", text, re.M)
    return {"steps": steps, "pytest_summary": summaries[0] if summaries else None,
            "pytest_summary_slow": summaries[1] if len(summaries) > 1 else None}


def parse_junit(path: str, top: int = 20) -> dict:
    """Counts and the ``top`` slowest tests of a pytest junit XML file (its times: setup + call + teardown)."""
    cases = []
    counts = {"passed": 0, "failed": 0, "error": 0, "skipped": 0}
    for case in ET.parse(path).getroot().iter("testcase"):
        nodeid = _nodeid(case.get("classname", ""), case.get("name", ""))
        cases.append((float(case.get("time", 0.0)), nodeid))
        kinds = {child.tag for child in case}
        kind = next((k for k in ("failure", "error", "skipped") if k in kinds), "passed")
        counts["failed" if kind == "failure" else kind] += 1
    cases.sort(reverse=True)
    return {"counts": counts, "tests": len(cases), "sum_of_test_times_s": round(sum(t for t, _ in cases), 1),
            "test_time_s": dist([t for t, _ in cases]),
            "slowest": [{"test": n, "s": round(t, 2)} for t, n in cases[:top]]}


def junit_times(paths: list[str]) -> dict[str, float]:
    """Each test's time (setup + call + teardown) by pytest node id, from junit XML files: the least of its times
    in them (a fresh clone's first tests also compile numba kernels; a loaded machine slows any test)."""
    times: dict[str, float] = {}
    for path in paths:
        for case in ET.parse(path).getroot().iter("testcase"):
            key = _nodeid(case.get("classname", ""), case.get("name", ""))
            times[key] = min(times.get(key, float("inf")), round(float(case.get("time", 0.0)), 2))
    return times


def _nodeid(classname: str, name: str) -> str:
    """pytest's node id of a junit test case: its class name is the module's dotted path, then any classes (the
    longest prefix that is a file here is the module; all of it if none is)."""
    parts = classname.split(".")
    k = next((k for k in range(len(parts), 0, -1) if (ROOT / ("/".join(parts[:k]) + ".py")).is_file()), len(parts))
    return "::".join(["/".join(parts[:k]) + ".py", *parts[k:], name])


def write_durations(paths: list[str], out: str) -> dict:
    """The durations file the suite is split by (tests/conftest.py: ``LONG_S``): every test's time in the runs
    ``paths`` (junit XML of ``.ci/run``'s two test steps), with where it was measured."""
    doc = {"measured": {"from": [os.path.basename(p) for p in paths], "cores": os.cpu_count(),
                        "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())},
           "seconds": dict(sorted(junit_times(paths).items()))}
    with open(out, "w") as f:
        json.dump(doc, f, indent=0)
        f.write("\n")
    return {"tests": len(doc["seconds"]), "written": out}


def fresh_clone_run(workdir: str) -> dict:
    """Clone this repository's committed tree into ``workdir`` and run ``.ci/run`` there; its log, XML and CPU."""
    clone = os.path.join(workdir, "creep_online")
    subprocess.run(["git", "clone", "-q", str(ROOT), clone], check=True)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=clone, capture_output=True, text=True).stdout
    log = os.path.join(workdir, "ci.log")
    env = dict(os.environ, CI_REPORTS=workdir)
    env.pop("NUMBA_CACHE_DIR", None)
    before, load_before, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), list(os.getloadavg()), time.time()
    with open(log, "w") as out:
        rc = subprocess.run(["bash", ".ci/run"], cwd=clone, stdout=out, stderr=subprocess.STDOUT, env=env).returncode
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    run = {"clone_of": head.strip(), "exit_code": rc, "ci_wall_s": round(time.time() - t0, 1),
           "ci_cpu_s": round(cpu, 1), "load_average_before": load_before}
    with open(log) as f:
        run.update(parse_log(f.read()))
    suite_xml, slow_xml = os.path.join(workdir, "suite.xml"), os.path.join(workdir, "slow.xml")
    if os.path.exists(suite_xml):
        run.update(parse_junit(suite_xml))
    if os.path.exists(slow_xml):
        run["slow_tests"] = parse_junit(slow_xml)
    return run


def cpu_profile(paths: list[str], top: int = 20) -> dict:
    """Per-test CPU rows (``bench/suite_cpu.py``'s JSON lines) summed: in all, per file, the ``top`` tests."""
    rows = [json.loads(line) for path in paths for line in open(path) if line.strip()]
    files: dict[str, dict] = {}
    for r in rows:
        f = files.setdefault(r["id"].split("::")[0], {"tests": 0, "cpu_s": 0.0, "wall_s": 0.0})
        f["tests"] += 1
        f["cpu_s"] += r["self"] + max(r["children"], 0.0)
        f["wall_s"] += r["wall"]
    ranked = sorted(rows, key=lambda r: -(r["self"] + max(r["children"], 0.0)))
    return {"tests": len(rows), "sum_own_cpu_s": round(sum(r["self"] for r in rows), 1),
            "sum_children_cpu_s": round(sum(max(r["children"], 0.0) for r in rows), 1),
            "sum_wall_s": round(sum(r["wall"] for r in rows), 1),
            "files": {k: {"tests": v["tests"], "cpu_s": round(v["cpu_s"], 1), "wall_s": round(v["wall_s"], 1)}
                      for k, v in sorted(files.items(), key=lambda kv: -kv[1]["cpu_s"])[:top]},
            "costliest": [{"test": r["id"], "cpu_s": round(r["self"] + max(r["children"], 0.0), 1),
                           "wall_s": round(r["wall"], 1)} for r in ranked[:top]]}


def here_run(keep: str | None = None) -> dict:
    """The README's test command in this checkout (numba's cache as it is): wall, loads, CPU, junit summary
    (its junit XML kept in ``keep``, if given: a ``--durations`` source)."""
    with tempfile.TemporaryDirectory(prefix="creep_suite_") as workdir:
        xml = os.path.join(keep or workdir, "suite.xml")
        env = dict(os.environ, SUITE_CPU_DIR=workdir, PYTHONPATH=os.pathsep.join(
            p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p))
        before, load_before, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), list(os.getloadavg()), time.time()
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "auto", "-p", "bench.suite_cpu",
                               f"--junitxml={xml}"], cwd=ROOT, capture_output=True, text=True, env=env)
        wall, load_after = time.time() - t0, list(os.getloadavg())
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        summaries = re.findall(r"^=*\s*(\d+ passed.*?) in [\d.]+s", proc.stdout, re.M)
        run = {"where": "this checkout", "exit_code": proc.returncode,
               "steps": {"suite": {"wall_s": round(wall), "load_average_before": load_before,
                                   "load_average_after": load_after}},
               "ci_cpu_s": round((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), 1),
               "pytest_summary": summaries[-1] if summaries else None}
        if os.path.exists(xml):
            run.update(parse_junit(xml))
        run["cpu_profile"] = cpu_profile(glob.glob(os.path.join(workdir, "*.jsonl")))
    return run


def summary(runs: list[dict]) -> dict:
    walls = [r["steps"]["suite"]["wall_s"] for r in runs if "suite" in r.get("steps", {})]
    return {"suite_wall_s": dist(walls), "target_s": TARGET_S,
            "within_target": bool(walls) and min(walls) <= TARGET_S,
            "cores": os.cpu_count(), "note": "wall times depend on the machine's load: see each run's load average"}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2, help="fresh-clone CI runs (default 2)")
    ap.add_argument("--keep", help="run in this directory and keep the clones (default: a temporary one); with "
                    "--here: keep the junit XML there")
    ap.add_argument("--here", action="store_true", help="time the README's test command in this checkout instead")
    ap.add_argument("--from-run", nargs=2, metavar=("LOG", "XML"), help="report a finished run instead")
    ap.add_argument("--durations", nargs="+", metavar="XML",
                    help="write tests/durations.json (the suite's split) from these junit XML files, and stop")
    ap.add_argument("--out", help="write the JSON here too")
    args = ap.parse_args(argv)
    if args.durations:
        print(json.dumps(write_durations(args.durations, str(ROOT / "tests" / "durations.json"))))
        return
    if args.from_run:
        log, xml = args.from_run
        with open(log) as f:
            runs = [{**parse_log(f.read()), **parse_junit(xml)}]
    elif args.here:
        runs = [here_run(args.keep)]
    else:
        runs = []
        for k in range(args.runs):
            workdir = os.path.join(args.keep, f"run{k}") if args.keep else tempfile.mkdtemp(prefix="creep_suite_")
            os.makedirs(workdir, exist_ok=True)
            try:
                runs.append(fresh_clone_run(workdir))
            finally:
                if not args.keep:
                    shutil.rmtree(workdir, ignore_errors=True)
    write_report({"bench": "test_suite", "summary": summary(runs), "runs": runs}, args.out, argv=argv)


if __name__ == "__main__":
    main()
