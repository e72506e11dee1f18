"""The documentation: the site builds strictly, every example runs, no history in the user docs.

Every fenced ``python``, ``bash``, ``sh`` or ``console`` block in README.md and docs/ carries a
marker on the line before it (blank lines between are allowed):

* ``<!-- run -->``: the block runs here. The runnable blocks of one page run in document order, in
  one fresh folder, in one child process: python blocks share one namespace (a later block uses
  what an earlier one made), bash blocks run with ``bash -euo pipefail`` and this interpreter's
  scripts (``creep-online``, ``python``) first on PATH. ``tests/data`` is linked into the folder,
  so the examples use the repository's real records by the paths a reader in a clone uses.
* ``*Not run by the ... tests: REASON*``: a visible line that tells the reader why the block is
  not run (hardware, or a command CI runs itself).

Running this file as a script (``python tests/test_docs.py BLOCKS.json``) is the child process.
"""
from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
#: Pages whose history and examples another piece of work owns (rewritten beside this one).
NOT_OURS: set[Path] = set()
RUN_MARK = "<!-- run -->"
NOT_RUN = re.compile(r"^\*Not run by the (documentation )?tests: (?P<reason>.+)\*$")
FENCE = re.compile(r"^(?P<indent> *)```(?P<lang>[\w-]*)[^\n]*$")
CHECKED = {"python", "bash", "sh", "console"}
#: Longest a page's examples may take before the test reports them as hung (s).
PAGE_TIMEOUT = 600


def pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(p for p in DOCS.rglob("*.md") if not p.is_relative_to(DOCS / "_hooks"))]


def blocks(path: Path) -> list[dict]:
    """The fenced blocks of a page: language, code, first line number and marker ("run", "not run" or None)."""
    lines = path.read_text().splitlines()
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        start, indent = i, len(m.group("indent"))
        j = i + 1
        while j < len(lines) and lines[j].strip() != "```":
            j += 1
        code = "\n".join(line[indent:] for line in lines[start + 1:j])
        k = start - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        before = lines[k].strip() if k >= 0 else ""
        marker = "run" if before == RUN_MARK else "not run" if NOT_RUN.match(before) else None
        out.append({"lang": m.group("lang"), "code": code, "line": start + 1, "marker": marker})
        i = j + 1
    return out


def runnable_pages() -> list[Path]:
    return [p for p in pages() if p not in NOT_OURS and any(b["marker"] == "run" for b in blocks(p))]


def test_every_example_is_marked():
    """A python or shell block either runs here or tells the reader why it does not."""
    unmarked = [f"{p.relative_to(ROOT)}:{b['line']}" for p in pages() if p not in NOT_OURS
                for b in blocks(p) if b["lang"] in CHECKED and b["marker"] is None]
    assert not unmarked, f"blocks with neither {RUN_MARK} nor a visible 'Not run by the tests: ...' line: {unmarked}"


#: Pages whose examples take over ~8 s (the tutorial's diagnoses of two real records ~60 s of CPU, the reliability,
#: fleet and diagnostics pages' runs 8-16 s; the PI, CAN, serial and capaNCDT how-tos wait 8-13 s on their real
#: transports): marked ``long``, run by CI after the default suite.
LONG_PAGES = ("tutorial.md", "reliability.md", "fleet.md", "diagnostics.md", "pi.md", "can.md", "serial.md",
              "capancdt.md")


@pytest.mark.parametrize("page", [pytest.param(p, marks=pytest.mark.long) if p.name in LONG_PAGES else p
                                  for p in runnable_pages()], ids=lambda p: str(p.relative_to(ROOT)))
def test_examples_run(page: Path, tmp_path: Path):
    """The page's runnable blocks, in order, in an empty folder, in a child process."""
    runnable = [b for b in blocks(page) if b["marker"] == "run"]
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "data").symlink_to(ROOT / "tests" / "data")
    spec = tmp_path / "blocks.json"
    spec.write_text(json.dumps({"page": str(page.relative_to(ROOT)), "blocks": runnable}))
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run([sys.executable, __file__, str(spec)], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=PAGE_TIMEOUT)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert proc.returncode == 0, f"{page.relative_to(ROOT)}: {proc.stderr[-4000:]}"
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    print(f"{page.relative_to(ROOT)}: {len(runnable)} blocks, {cpu:.1f} s CPU")


def test_site_builds_strictly(tmp_path: Path):
    """mkdocs build --strict: a broken link, a missing page or an API object that does not resolve fails."""
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"}, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert (tmp_path / "site" / "reference" / "api" / "index.html").read_text().count("OnlineEstimator") > 5
    cli = (tmp_path / "site" / "reference" / "cli" / "index.html").read_text()
    assert "creep-online identify" in cli and "--u-column" in cli, "the CLI reference is the parsers' help"
    print(f"strict build {time.perf_counter() - start:.1f} s")


#: What a commit hash looks like in text (7-12 hex digits, at least one letter, not part of a word or path).
HASH = re.compile(r"(?:^|[^0-9A-Za-z_/.-])([0-9a-f]{7,12})(?:[^0-9A-Za-z_]|$)", re.MULTILINE)
#: Development history does not belong in the user docs (it goes to CHANGELOG.md and commit messages).
HISTORY = re.compile(r"\b(round \d|this round|previous round|issue \d+|latest \(|before this (round|work)|"
                     r"branch `|was \d[^ ]* now)\b", re.IGNORECASE)


#: The two quick-start commands: the README shows them exactly, and .ci/run runs exactly these.
QUICK_START = ('python3 -m venv .venv && .venv/bin/pip install -q -e ".[all]" && .venv/bin/creep-online demo',
               ".venv/bin/python -m pytest -q -n auto")


def test_readme_is_a_front_page():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 300
    for command in QUICK_START:
        assert command in text and command in (ROOT / ".ci" / "run").read_text(), command


def test_no_history_in_user_docs():
    found = []
    for p in pages():
        if p in NOT_OURS:
            continue
        text = p.read_text()
        found += [f"{p.relative_to(ROOT)}: hash {h}" for h in HASH.findall(text) if re.search("[a-f]", h)]
        found += [f"{p.relative_to(ROOT)}: {m.group(0)!r}" for m in HISTORY.finditer(text)]
    assert not found, found


# ---------------------------------------------------------------------------------------------------- the child
def _run_blocks(spec_path: str) -> int:
    spec = json.loads(Path(spec_path).read_text())
    namespace: dict = {"__name__": "__doc_example__"}
    for block in spec["blocks"]:
        where = f"{spec['page']}, block at line {block['line']} ({block['lang']})"
        started = time.perf_counter()
        if block["lang"] == "python":
            try:
                exec(compile(block["code"], where, "exec"), namespace)
            except BaseException:
                import traceback
                print(f"FAILED: {where}\n{block['code']}", file=sys.stderr)
                traceback.print_exc()
                return 1
        else:
            code, out, err = _bash(block["code"])
            sys.stdout.write(out)
            if code != 0:
                print(f"FAILED (exit {code}): {where}\n{block['code']}\n--- stdout\n{out[-3000:]}"
                      f"\n--- stderr\n{err[-3000:]}", file=sys.stderr)
                return 1
        print(f"[{time.perf_counter() - started:.1f} s] {where}", file=sys.stderr)
    return 0


def _bash(code: str) -> tuple[int, str, str]:
    """Run a shell block in its own process group; whatever it left running in the background is ended after it."""
    import signal
    import tempfile
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(["bash", "-euo", "pipefail", "-c", code], stdout=out, stderr=err, text=True,
                                start_new_session=True)
        try:
            status = proc.wait(timeout=PAGE_TIMEOUT)
        finally:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        out.seek(0)
        err.seek(0)
        return status, out.read(), err.read()


if __name__ == "__main__":
    sys.exit(_run_blocks(sys.argv[1]))
