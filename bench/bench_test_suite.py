"""The default test suite's wall time the way CI runs it: a fresh clone, ``.ci/run`` (the README's quick start).

Each run clones the committed tree (``git clone`` of this repository) into a temporary directory and
runs ``bash .ci/run`` there: a new virtual environment, the package installed with every extra, the
demo, then the README's test command (``pytest -q -n auto``) with numba's kernel cache empty, as a
newcomer's first run. Reported per run: the suite's wall time and the load average CI prints beside
it, the install-and-demo step's wall time, the CPU time of the whole run (user + sys of every child:
on a shared machine the steadier figure), the pass/fail counts and the 20 slowest tests (pytest's
junit XML, setup + call + teardown). Target: the suite <= 300 s on 2 cores.

Usage: python -m bench.bench_test_suite [--runs 2] [--keep DIR] [--out FILE]
       python -m bench.bench_test_suite --from-run LOG XML [--out FILE]   (a run made by hand, see below)
A run made by hand: ``PYTEST_ADDOPTS=--junitxml=XML bash .ci/run > LOG 2>&1`` in a fresh clone.
(prints one JSON document; --out writes it too, e.g. bench/results/test_suite.json)
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
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
        key = "suite" if "test suite" in m["title"] else "install_and_demo"
        load = [float(x) for x in m["load"].split()] if m["load"] != "n/a" else None
        steps[key] = {"wall_s": int(m["wall"]), "load_average_after": load}
    summary = re.findall(r"^=*\s*(\d+ passed.*?) in [\d.]+s", text, re.M)
    return {"steps": steps, "pytest_summary": summary[-1] if summary else None}


def parse_junit(path: str, top: int = 20) -> dict:
    """Counts and the ``top`` slowest tests of a pytest junit XML file (its times: setup + call + teardown)."""
    cases = []
    counts = {"passed": 0, "failed": 0, "error": 0, "skipped": 0}
    for case in ET.parse(path).getroot().iter("testcase"):
        nodeid = f"{case.get('classname', '').replace('.', '/')}.py::{case.get('name')}"
        cases.append((float(case.get("time", 0.0)), nodeid))
        kinds = {child.tag for child in case}
        kind = next((k for k in ("failure", "error", "skipped") if k in kinds), "passed")
        counts["failed" if kind == "failure" else kind] += 1
    cases.sort(reverse=True)
    return {"counts": counts, "tests": len(cases), "sum_of_test_times_s": round(sum(t for t, _ in cases), 1),
            "test_time_s": dist([t for t, _ in cases]),
            "slowest": [{"test": n, "s": round(t, 2)} for t, n in cases[:top]]}


def fresh_clone_run(workdir: str) -> dict:
    """Clone this repository's committed tree into ``workdir`` and run ``.ci/run`` there; its log, XML and CPU."""
    clone = os.path.join(workdir, "creep_online")
    subprocess.run(["git", "clone", "-q", str(ROOT), clone], check=True)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=clone, capture_output=True, text=True).stdout
    xml, log = os.path.join(workdir, "junit.xml"), os.path.join(workdir, "ci.log")
    env = dict(os.environ, PYTEST_ADDOPTS=f"--junitxml={xml}")
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
    if os.path.exists(xml):
        run.update(parse_junit(xml))
    return run


def summary(runs: list[dict]) -> dict:
    walls = [r["steps"]["suite"]["wall_s"] for r in runs if "suite" in r.get("steps", {})]
    return {"suite_wall_s": dist(walls), "target_s": TARGET_S,
            "within_target": bool(walls) and min(walls) <= TARGET_S,
            "cores": os.cpu_count(), "note": "wall times depend on the machine's load: see each run's load average"}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2, help="fresh-clone CI runs (default 2)")
    ap.add_argument("--keep", help="run in this directory and keep the clones (default: a temporary one)")
    ap.add_argument("--from-run", nargs=2, metavar=("LOG", "XML"), help="report a finished run instead")
    ap.add_argument("--out", help="write the JSON here too")
    args = ap.parse_args(argv)
    if args.from_run:
        log, xml = args.from_run
        with open(log) as f:
            runs = [{**parse_log(f.read()), **parse_junit(xml)}]
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
