"""The reliability sweep: hostile but realistic attempts on the CLI, the API, hil_sim, signals, pipes, outputs.

Every attempt is run for real (the CLI in a forked child of this process, or a
subprocess where signals, pipes, FIFOs, Dask or hil_sim are involved; the API
in a forked child) under a timeout, and its outcome is classified:

  clean             exit 0 with a right result, or exit 2 with one error line (API: a CreepOnlineError)
  traceback         a Python traceback reached the user
  outside_contract  the API raised something that is not a CreepOnlineError
  internal_error    exit 3 ("internal error ... please report it")
  hang              no answer within the attempt's timeout
  file_lost         a file of the user's (an input, a folder's content) changed or vanished
  silently_wrong    exit 0 (API: a return) where the input must be refused, or a wrong result
  valid_refused     a valid input refused
  injection         a control character reached the terminal raw, or a CSV cell a spreadsheet runs
  messy_error       exit 2 but not one line (or another exit status than documented)
  no_estimate       a stream ended by a signal without printing its estimate
  temp_left         a temporary file left behind
  python_startup    a Ctrl-C in the interpreter's own start-up, before the package's first line runs: Python's
                    KeyboardInterrupt (no frame of creep_online in it), which no code of the package can catch

Categories: flags (every flag of every command with hostile values), specs
(every source option), files (malformed inputs), outputs (user files and
folders), signals, pipes, api, pickle, canlog, security, scheduler, hil_sim,
bounded. ``python -m bench.bench_reliability`` prints JSON counts per category
and outcome (and writes bench/results/reliability.json); ``--only CAT,...``
runs some categories, ``--sample N`` every N-th attempt, ``--baseline REF``
runs the same sweep on an earlier commit (``git archive``), ``--list`` prints
the failures.
"""


import argparse
import copy
import gzip
import hashlib
import json
import math
import os
import pickle
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def code_root() -> Path:
    """The tree whose creep_online and hil_sim run (this one, or a baseline's with ``--baseline``)."""
    import creep_online
    return Path(creep_online.__file__).resolve().parents[1]
OUTCOMES = ("clean", "traceback", "outside_contract", "internal_error", "hang", "file_lost", "silently_wrong",
            "valid_refused", "injection", "messy_error", "no_estimate", "temp_left", "python_startup")
CATEGORIES = ("flags", "specs", "files", "outputs", "signals", "pipes", "api", "pickle", "canlog", "security",
              "scheduler", "hil_sim", "bounded")
#: Values every flag and option is tried with.
HOSTILE = ("nan", "inf", "-inf", "0", "-1", "1e300", "1e-300", "", "x" * 5000, "abc", "-0", "1e-320")
TRUE = {"alpha": 0.3, "a1": 0.01, "a2": 1e-4, "b": 2.0}
RAW_CONTROL = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\x7f\x9b]")


@dataclass
class Outcome:
    code: int | None = None
    out: str = ""
    err: str = ""
    hung: bool = False
    seconds: float = 0.0
    api: dict | None = None          # the API child's report


@dataclass
class Case:
    category: str
    name: str
    run: Callable[["Case"], Outcome]
    expect: str = "either"           # ok | refuse | either | custom
    check: Callable[[Outcome], str | None] | None = None
    protect: tuple = ()               # paths whose bytes must not change
    timeout: float = 60.0
    data: dict = field(default_factory=dict)


# ------------------------------------------------------------------ running
def _fork(target: Callable[[], int], timeout: float, stdin: str | None = None, cwd: str | None = None,
          env: dict | None = None) -> Outcome:
    """Run ``target`` in a forked child (stdout/stderr captured); kill it after ``timeout`` s."""
    out_f, err_f = tempfile.TemporaryFile(), tempfile.TemporaryFile()
    start = time.monotonic()
    pid = os.fork()
    if pid == 0:                                       # the child
        code = 97
        try:
            os.setpgid(0, 0)
            fd = os.open(stdin or os.devnull, os.O_RDONLY)
            os.dup2(fd, 0)
            os.dup2(out_f.fileno(), 1)
            os.dup2(err_f.fileno(), 2)
            if cwd:
                os.chdir(cwd)
            if env:
                os.environ.update(env)
            code = target()
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
        except BaseException:  # noqa: BLE001 - the sweep reports it
            traceback.print_exc()
            code = 98
        finally:
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except Exception:  # noqa: BLE001
                    pass
            os._exit(int(code or 0) & 0xFF)
    hung, status = False, None
    deadline = start + timeout
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            hung = True
            _kill_group(pid)
            os.waitpid(pid, 0)
            break
        time.sleep(0.01)
    _kill_group(pid)        # anything it left behind (hil_sim, Dask workers)
    res = Outcome(hung=hung, seconds=time.monotonic() - start)
    if not hung:
        res.code = os.waitstatus_to_exitcode(status)
    for f, attr in ((out_f, "out"), (err_f, "err")):
        f.seek(0)
        setattr(res, attr, f.read().decode("utf-8", errors="replace"))
        f.close()
    return res


def _kill_group(pid: int) -> None:
    try:
        os.killpg(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def cli(argv: list[str], *, stdin: str | None = None, env: dict | None = None, cwd: str | None = None,
        timeout: float = 60.0) -> Callable[[Case], Outcome]:
    """An attempt: ``creep-online ARGV`` in a forked child of this (warmed) process."""
    def run(case: Case) -> Outcome:
        def target() -> int:
            from creep_online.cli import main
            return main([str(a) for a in argv])
        return _fork(target, case.timeout, stdin=stdin, cwd=cwd, env=env)
    return run


def proc(cmd: list[str] | str, *, stdin_data: bytes | None = None, env: dict | None = None, cwd: str | None = None,
         shell: bool = False) -> Callable[[Case], Outcome]:
    """An attempt: a subprocess (pipes, FIFOs, shells)."""
    def run(case: Case) -> Outcome:
        start = time.monotonic()
        p = subprocess.Popen(cmd, stdin=subprocess.PIPE if stdin_data is not None else subprocess.DEVNULL,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ, **(env or {})},
                             cwd=cwd, shell=shell, start_new_session=True,
                             executable="/bin/bash" if shell else None)
        try:
            out, err = p.communicate(stdin_data, timeout=case.timeout)
            hung = False
        except subprocess.TimeoutExpired:
            _kill_group(p.pid)
            out, err = p.communicate()
            hung = True
        _kill_group(p.pid)
        return Outcome(code=None if hung else p.returncode, out=out.decode(errors="replace"),
                       err=err.decode(errors="replace"), hung=hung, seconds=time.monotonic() - start)
    return run


def api(fn: Callable[[], Any], check: Callable[[Any], str | None] | None = None) -> Callable[[Case], Outcome]:
    """An attempt on the Python API in a forked child: its return or exception, and ``check`` of the value."""
    def run(case: Case) -> Outcome:
        report_f = tempfile.NamedTemporaryFile(suffix=".json", delete=False)
        report_f.close()

        def target() -> int:
            from creep_online.errors import CreepOnlineError
            try:
                value = fn()
            except BaseException as exc:  # noqa: BLE001 - classified by the parent
                rep = {"raised": type(exc).__name__, "contract": isinstance(exc, CreepOnlineError),
                       "message": str(exc)[:300], "lines": len(str(exc).strip().splitlines())}
            else:
                rep = {"raised": None, "problem": check(value) if check else None, "value": repr(value)[:200]}
            Path(report_f.name).write_text(json.dumps(rep))
            return 0
        res = _fork(target, case.timeout)
        try:
            res.api = json.loads(Path(report_f.name).read_text() or "null")
        except ValueError:
            res.api = None
        os.unlink(report_f.name)
        return res
    return run


def classify(case: Case, res: Outcome) -> str:
    """The outcome label of one attempt (module docstring)."""
    if res.hung:
        return "hang"
    for path, digest in case.data.get("digests", {}).items():
        if _digest(path) != digest:
            return "file_lost"
    text = res.out + res.err
    if "Traceback (most recent call last)" in text:
        return "python_startup" if case.data.get("startup") and _before_the_package(res.err) else "traceback"
    if res.api is not None:
        return _classify_api(case, res.api)
    if res.code == 3 or "internal error" in res.err:
        return "internal_error"
    if RAW_CONTROL.search(text.replace("\r", "")):
        return "injection"
    if case.check is not None:
        label = case.check(res)
        if label:
            return label
    if case.expect == "custom":
        return "clean"
    if res.code == 0:
        return "silently_wrong" if case.expect == "refuse" else "clean"
    if res.code == 2:
        if case.expect == "ok":
            return "valid_refused"
        return "clean" if one_error_line(res.err) else "messy_error"
    return "messy_error"


def _classify_api(case: Case, rep: dict) -> str:
    if rep.get("raised"):
        if rep["raised"] in ("KeyboardInterrupt",):
            return "messy_error"
        if not rep["contract"]:
            return "outside_contract"
        if rep["lines"] > 1:
            return "messy_error"
        return "valid_refused" if case.expect == "ok" else "clean"
    if rep.get("problem"):
        return rep["problem"]
    return "silently_wrong" if case.expect == "refuse" else "clean"


def _before_the_package(err: str) -> bool:
    """A KeyboardInterrupt traceback with no frame of the package: it came before the package's first line."""
    frames = re.findall(r'^  File "([^"]*)"', err, re.MULTILINE)
    return err.rstrip().endswith("KeyboardInterrupt") and not any(
        "creep_online" in f or "hil_sim" in f for f in frames)


def one_error_line(err: str) -> bool:
    """Exactly one line on stderr that is not a warning or progress, and it is an error line."""
    lines = [ln for ln in err.replace("\r", "\n").splitlines()
             if ln.strip() and ": warning: " not in ln and not ln.lstrip().startswith("[")
             and not ln.startswith("creep-online: ")]        # (a stream's events, not its error)
    return len(lines) == 1 and ("error" in lines[0] or lines[0].startswith("hil_sim:"))


def _digest(path: str | Path) -> str:
    p = Path(path)
    if p.is_dir():
        return ";".join(f"{q.name}:{_digest(q)}" for q in sorted(p.iterdir()))
    try:
        return hashlib.sha256(p.read_bytes()).hexdigest()
    except OSError:
        return "missing"


def _json(res: Outcome) -> dict | None:
    try:
        return json.loads(res.out)
    except ValueError:
        return None


# ------------------------------------------------------------------ fixtures
class Fixtures:
    """The files every category uses, written once into ``root``."""

    def __init__(self, root: Path) -> None:
        from creep_online import CreepModel, simulate
        self.root = root
        rng = np.random.default_rng(1)
        h, n = 1e-3, 3000
        t = np.arange(n) * h
        u = np.where(t > 0.05, 1.0, 0.0)
        y = simulate(CreepModel(**TRUE), t, u) + 1e-4 * rng.standard_normal(n)
        self.rec = self.csv("rec.csv", t, u, y)
        self.n = n
        self._big: Path | None = None
        (root / "tu.csv").write_text("t,u\n" + "".join(f"{a!r},{b!r}\n" for a, b in zip(t.tolist(), u.tolist())))
        self.tu = root / "tu.csv"
        self.gz = root / "rec.csv.gz"
        self.gz.write_bytes(gzip.compress(self.rec.read_bytes()))
        (root / "command.csv").write_text("t,u\n0,0\n0.05,1\n")
        self.command = root / "command.csv"
        self.gcs = root / "rec.gcs"
        self.gcs.write_text(gcs_text(u, y, h))
        self.dbc = str(ROOT / "creep_online" / "data" / "amplifier.dbc")
        self.canlogs = write_canlogs(root)

    @property
    def big(self) -> Path:
        """A 60 s record (written on first use: the signal cases' long streams)."""
        if self._big is None:
            from creep_online import CreepModel, simulate
            tb = np.arange(60000) * 1e-3
            ub = np.where((tb % 4.0) > 2.0, 1.0, 0.0)
            yb = simulate(CreepModel(**TRUE), tb, ub) + 1e-4 * np.random.default_rng(2).standard_normal(tb.size)
            self._big = self.csv("big.csv", tb, ub, yb)
        return self._big

    def csv(self, name: str, t, u, y) -> Path:
        path = self.root / name
        with open(path, "w") as fh:
            fh.write("t,u,y\n")
            for a, b, c in zip(t.tolist(), u.tolist(), y.tolist()):
                fh.write(f"{a!r},{b!r},{c!r}\n")
        return path

    def model(self) -> Path:
        """A model file identified from ``rec`` (written on first use)."""
        path = self.root / "model.json"
        if not path.exists():
            from creep_online import identify, save_model
            from creep_online.io.csvfile import load_record
            rec = load_record(self.rec)
            save_model(identify(rec.t, rec.u, rec.y), path)
        return path

    def workdir(self, name: str) -> Path:
        d = self.root / "work" / name
        d.mkdir(parents=True, exist_ok=True)
        return d


def gcs_text(u, y, h, header: dict | None = None) -> str:
    """A PI GCS data-recorder file as pipython writes it (``header`` overrides keys)."""
    head = {"VERSION": "1", "TYPE": "1", "SEPARATOR": "32", "DIM": "2", "SAMPLE_TIME": repr(h),
            "NDATA": str(len(u)), "NAME0": "Piezo Voltage of axis 1", "NAME1": "Actual Position of axis 1"}
    head.update(header or {})
    lines = [f"# {k} = {v}" for k, v in head.items()] + ["# END_HEADER"]
    lines += [f"{a:.9f} {b:.9f}" for a, b in zip(u, y)]
    return "\n".join(lines) + "\n"


CAN_RATE = 10_000.0
#: alpha of the simulated plant the CAN logs are recorded from (hil_sim's default plant).
PLANT_ALPHA = 0.12


def write_canlogs(root: Path) -> dict[str, Path]:
    """The plant's CAN session as .asc, .log, .csv and .blf logs (2 s, pair frames)."""
    try:
        import can
    except ImportError:
        return {}
    from creep_online.io import can_frames as cf
    from hil_sim import PlantConfig, generate, parse_params
    rec = generate(PlantConfig(parse_params(""), rate=CAN_RATE, duration=2.0, t_start=0.05, seed=1))
    n = rec.t.size - rec.t.size % 2
    gen = (np.concatenate([[0], np.cumsum(np.diff(rec.u) != 0)]) % 16).astype(int)
    out = {}
    for suffix in (".asc", ".log", ".csv", ".blf"):
        path = root / f"session{suffix}"
        with can.Logger(str(path)) as log:
            ts = 1000.0
            for k in range(0, n, 2):
                msgs = []
                if k % 100 == 0 or gen[k] != gen[k - 1] or gen[k + 1] != gen[k]:
                    msgs += [cf.encode_input(int(gen[k]), rec.u[k]), cf.encode_input(int(gen[k + 1]), rec.u[k + 1])]
                msgs.append(cf.encode_pair(k, int(gen[k]), int(gen[k + 1]), rec.y[k], rec.y[k + 1]))
                for fid, data, _ in msgs:
                    log(can.Message(timestamp=ts, arbitration_id=fid, data=data, is_extended_id=False))
                    ts += 1e-4
        out[suffix] = path
    return out


# ------------------------------------------------------------------ checks of an exit 0
def estimate_ok(res: Outcome, samples: int | None = None, alpha: float = TRUE["alpha"]) -> str | None:
    """A stream's JSON: the samples asked for, and a right estimate (``alpha``) or an honest "none"."""
    d = _json(res)
    if d is None:
        return "silently_wrong"
    if samples is not None and d.get("samples") != samples:
        return "silently_wrong"
    if d.get("quality") in ("none", "degraded") and d.get("reason"):
        return None                                  # an honest "no estimate" (the reason says why)
    if d.get("phase") == "tracking" and abs(d.get("alpha", 0) - alpha) < 0.05:
        return None
    if d.get("quality") == "provisional" and d.get("reason") and abs(d.get("alpha", 0) - alpha) < 0.05:
        return None                                  # restarting after an outage: the estimate before it, said so
    return "silently_wrong"


def identified_ok(res: Outcome) -> str | None:
    d = _json(res)
    if d is None or res.code != 0:
        return None if res.code != 0 else "silently_wrong"
    return None if abs(d.get("alpha", 0) - TRUE["alpha"]) < 0.05 and d.get("fit_percent", 0) > 90 \
        else "silently_wrong"


def on_exit0(check: Callable[[Outcome], str | None]) -> Callable[[Outcome], str | None]:
    return lambda res: check(res) if res.code == 0 else None


# ------------------------------------------------------------------ categories
def flag_cases(fx: Fixtures) -> list[Case]:
    """Every flag of every command with every hostile value: exit 0 with a right result, or exit 2, one line."""
    rec, tu = str(fx.rec), str(fx.tu)
    templates = {
        "identify": (["identify", rec, "--json"], ["--t-c", "--alpha0", "--layer1-step", "-o", "--t-column"],
                     on_exit0(identified_ok)),
        "stream": (["stream", "--source", f"csv:{rec}", "--json"],
                   ["--t-c", "--alpha0", "--window", "--dt", "--max-samples", "--duration"], None),
        "simulate": (["simulate", "--input", tu, "--params", "alpha=0.3,a1=0.01,a2=1e-4,b=2", "-o", "OUT"],
                     ["--memory", "--method"], None),
        "diagnose": (["diagnose", rec, "--json", "--effects", "delay", "--workers", "1"],
                     ["--effects", "--workers", "--report", "--u-column"], None),
        "fit": (["fit", rec, "--json", "--effects", "delay"], ["--window", "--effects", "-o"], None),
        "compare": (["compare", str(fx.model()), rec, "--json"], ["--initial", "--report", "--t-column"], None),
        "demo": (["demo", "--duration", "0.5", "--rate", "2000", "--json", "--quiet", "--report", "REPORT"],
                 ["--duration", "--rate", "--bandwidth", "--period", "--amplitude", "--u-min", "--seed",
                  "--report"], None),
        "batch": (["batch", rec, "--json", "--workers", "1"], ["--workers", "--scheduler", "--out", "--html"], None),
    }
    cases = []
    for command, (base, flags, check) in templates.items():
        for flag in flags:
            for k, value in enumerate(HOSTILE):
                work = fx.workdir(f"flags-{command}-{flag.strip('-')}-{k}")
                argv = [str(work / "out.csv") if a == "OUT" else str(work / "report") if a == "REPORT" else a
                        for a in base]
                if flag in argv:                      # the flag under test replaces the template's value
                    i = argv.index(flag)
                    argv[i + 1] = value
                else:
                    argv += [flag, value]
                if command == "stream" and flag == "--max-samples":
                    chk = on_exit0(lambda res, v=value: estimate_ok(res, int(float(v))
                                                                    if _is_number(v) else None))
                elif command == "stream":
                    chk = on_exit0(estimate_ok)
                elif command == "simulate":
                    chk = on_exit0(lambda res, w=work: None if (w / "out.csv").is_file() else "silently_wrong")
                else:
                    chk = check
                if command == "demo" and flag == "--compensate":
                    continue
                cases.append(Case("flags", f"{command} {flag} {value[:12]!r}", cli(argv, cwd=str(work)),
                                  check=chk, protect=(fx.rec,),
                                  timeout=150.0 if command in ("demo", "batch") else 90.0))
        if command == "simulate":                     # the model's numbers
            for key in ("alpha", "a1", "a2", "b", "fn", "zeta"):
                for k, value in enumerate(HOSTILE):
                    work = fx.workdir(f"flags-params-{key}-{k}")
                    base_p = {"alpha": "0.3", "a1": "0.01", "a2": "1e-4", "b": "2"} if key in ("a1", "a2") else \
                        {"alpha": "0.3", "fn": "15.9", "zeta": "0.5", "b": "2"}
                    base_p[key] = value
                    params = ",".join(f"{a}={b}" for a, b in base_p.items())
                    argv = ["simulate", "--input", tu, "--params", params, "-o", str(work / "out.csv")]
                    cases.append(Case("flags", f"simulate --params {key}={value[:12]!r}", cli(argv, cwd=str(work)),
                                      check=on_exit0(lambda res, w=work: _finite_csv(w / "out.csv")),
                                      protect=(fx.tu,)))
    return cases


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def _finite_csv(path: Path) -> str | None:
    try:
        data = np.loadtxt(path, delimiter=",", skiprows=1)
    except (OSError, ValueError):
        return "silently_wrong"
    return None if data.size and np.all(np.isfinite(data)) else "silently_wrong"


def spec_cases(fx: Fixtures) -> list[Case]:
    """Every option of every source kind with every hostile value (and the kinds' spellings)."""
    rec = str(fx.rec)
    kinds = {
        "csv": (f"csv:{rec}?realtime=0", ["window", "stall", "realtime", "u_column", "y_column"]),
        "canlog": (f"canlog:{fx.canlogs.get('.asc', 'none.asc')}?rate={CAN_RATE:g}",
                   ["rate", "window", "dbc", "realtime"]),
        "capancdt": (f"capancdt:127.0.0.1:9?command={fx.command}",
                     ["rate", "range", "channel", "timeout", "counter0", "command", "window", "stall",
                      "reconnect_timeout", "idle_timeout"]),
        "serial": ("serial:/dev/creep-online-no-such-port?rate=1000",
                   ["rate", "baud", "scale_u", "scale_y", "format", "checksum", "window", "stall",
                    "reconnect_timeout"]),
    }
    cases = []
    for kind, (base, options) in kinds.items():
        for option in options:
            for value in HOSTILE:
                target, _, query = base.partition("?")
                pairs = [p for p in query.split("&") if p and not p.startswith(option + "=")]
                spec = target + "?" + "&".join(pairs + [f"{option}={value}"])
                truth = PLANT_ALPHA if kind == "canlog" else TRUE["alpha"]
                cases.append(Case("specs", f"{kind}?{option}={value[:12]!r}",
                                  cli(["stream", "--source", spec, "--json"]),
                                  check=on_exit0(lambda res, a=truth: estimate_ok(res, alpha=a)), protect=(fx.rec,),
                                  timeout=90.0))
    for spec in ("CSV:" + rec, "Csv:" + rec, " csv:" + rec, "csv :" + rec, "csv:", "csv", ":" + rec,
                 "nosuchkind:" + rec, "csv:" + rec + "?realtime=0&realtime=1", "csv:" + rec + "?bogus=1"):
        cases.append(Case("specs", f"spec {spec[:24]!r}", cli(["stream", "--source", spec, "--json"]),
                          expect="refuse" if not spec.endswith("realtime=1") else "either",
                          check=on_exit0(estimate_ok)))
    return cases


def file_cases(fx: Fixtures) -> list[Case]:
    """Malformed inputs (CSV and GCS) for identify, diagnose and stream."""
    d = fx.workdir("files")
    good = fx.rec.read_text()
    lines = good.splitlines(keepends=True)
    n = fx.n
    u = np.where(np.arange(n) * 1e-3 > 0.05, 1.0, 0.0)
    y = np.loadtxt(fx.rec, delimiter=",", skiprows=1)[:, 2]
    bad: dict[str, bytes] = {
        "empty": b"", "header_only": b"t,u,y\n", "bom_crlf": ("\ufeff" + good.replace("\n", "\r\n")).encode(),
        "nul_bytes": good.encode()[:500] + b"\x00" * 100 + good.encode()[500:],
        "binary": bytes(range(256)) * 40, "latin1": ("t,u,y\n" + "1,2,\xe9\n").encode("latin-1"),
        "dup_columns": ("t,u,y,y\n" + "".join(ln.rstrip("\n") + ",1\n" for ln in lines[1:])).encode(),
        "nan_cell": ("".join(lines[:100]) + "0.1,1,nan\n" + "".join(lines[101:])).encode(),
        "one_row": "".join(lines[:2]).encode(), "t_backwards": ("t,u,y\n" + "".join(lines[1:][::-1])).encode(),
        "t_constant": ("t,u,y\n" + "".join("0," + ln.split(",", 1)[1] for ln in lines[1:])).encode(),
        "huge_numbers": ("t,u,y\n" + "".join(f"{k * 1e-3},{1e308 if k > 50 else 0},{1e308}\n"
                                             for k in range(500))).encode(),
        "long_line": b"t,u,y\n" + b"1" * 200_000 + b"\n", "cut_last": good.encode()[:-7],
        "semicolons": good.replace(",", ";").encode(), "no_header": "".join(lines[1:]).encode(),
        "gcs_sep_inf": gcs_text(u, y, 1e-3, {"SEPARATOR": "inf"}).encode(),
        "gcs_sep_huge": gcs_text(u, y, 1e-3, {"SEPARATOR": "1e300"}).encode(),
        "gcs_sep_zero": gcs_text(u, y, 1e-3, {"SEPARATOR": "0"}).encode(),
        "gcs_sep_big": gcs_text(u, y, 1e-3, {"SEPARATOR": "2000000"}).encode(),
        "gcs_dim_inf": gcs_text(u, y, 1e-3, {"DIM": "inf"}).encode(),
        "gcs_dim_huge": gcs_text(u, y, 1e-3, {"DIM": "1e300"}).encode(),
        "gcs_dim_frac": gcs_text(u, y, 1e-3, {"DIM": "1.5"}).encode(),
        "gcs_dt_nan": gcs_text(u, y, 1e-3, {"SAMPLE_TIME": "nan"}).encode(),
        "gcs_no_end": gcs_text(u, y, 1e-3).replace("# END_HEADER\n", "").encode(),
    }
    cases = []
    for name, content in bad.items():
        path = d / f"{name}.csv"
        path.write_bytes(content)
        for argv in (["identify", path, "--json"], ["diagnose", path, "--json", "--effects", "delay",
                                                      "--workers", "1"],
                     ["stream", "--source", f"csv:{path}", "--json"]):
            chk = on_exit0(estimate_ok) if argv[0] == "stream" else None
            cases.append(Case("files", f"{argv[0]} {name}", cli(argv), check=chk, protect=(path,), timeout=120.0))
    return cases


def output_cases(fx: Fixtures) -> list[Case]:
    """Outputs that would destroy an input, a folder of the user's files or a file the tool did not write."""
    cases = []
    d = fx.workdir("outputs")

    def fresh(name: str, source: Path) -> Path:
        p = d / name
        shutil.copy(source, p)
        return p

    m = fresh("m.csv", fx.rec)
    os.symlink(m, d / "m_link.csv")
    os.link(m, d / "m_hard.csv")
    for spelling in (str(m), f"{d}/./m.csv", f"{d}/../outputs/m.csv", str(d / "m_link.csv"), str(d / "m_hard.csv")):
        for spec in (f"csv:{m}", f"csv:{m}?realtime=0", f"csv:{d}/./m.csv?window=16"):
            cases.append(Case("outputs", f"stream {spec[-24:]} --trace {spelling[-20:]}",
                              cli(["stream", "--source", spec, "--trace", spelling]), expect="refuse", protect=(m,)))
    if ".asc" in fx.canlogs:
        s = fresh("s.asc", fx.canlogs[".asc"])
        dbc = fresh("amp.dbc", Path(fx.dbc))
        for spec, trace in ((f"canlog:{s}?rate=2000", s), (f"canlog:{s}?rate=2000&dbc={dbc}", dbc),
                            (f"canlog:{d}/./s.asc?rate=2000", s)):
            cases.append(Case("outputs", f"stream {spec[-30:]} --trace {trace.name}",
                              cli(["stream", "--source", spec, "--trace", trace]), expect="refuse", protect=(s, dbc)))
    c = fresh("command.csv", fx.command)
    cases.append(Case("outputs", "stream capancdt --trace command",
                      cli(["stream", "--source", f"capancdt:127.0.0.1:9?command={c}", "--trace", c]),
                      expect="refuse", protect=(c,)))
    for spelling in (str(m), f"{d}/./m.csv", str(d / "m_link.csv"), str(d / "m_hard.csv")):
        cases.append(Case("outputs", f"simulate -o {spelling[-20:]} (the input)",
                          cli(["simulate", "--input", m, "--params", "alpha=0.3,a1=0.01,a2=1e-4", "-o", spelling]),
                          expect="refuse", protect=(m,)))
    # folders that hold the user's files
    for name, files in (("rep_user", {"calibration.json": "{}", "holiday.png": "png"}),
                        ("rep_mixed", {"index.html": "<p>x</p>", "notes.txt": "mine"}),
                        ("rep_only_html", {"index.html": "<p>mine</p>"})):
        folder = d / name
        folder.mkdir()
        for f, text in files.items():
            (folder / f).write_text(text)
        cases.append(Case("outputs", f"diagnose --report {name}",
                          cli(["diagnose", fx.rec, "--effects", "delay", "--workers", "1", "--report", folder]),
                          expect="refuse", protect=(folder,), timeout=120))
        cases.append(Case("outputs", f"demo --report {name}",
                          cli(["demo", "--duration", "0.5", "--rate", "2000", "--quiet", "--report", folder]),
                          expect="refuse", protect=(folder,), timeout=120))
    holder = d / "holder"
    holder.mkdir()
    data = fresh("holder/data.csv", fx.rec)
    cases.append(Case("outputs", "diagnose --report (the data's folder)",
                      cli(["diagnose", data, "--effects", "delay", "--report", holder]), expect="refuse",
                      protect=(holder,), timeout=120))
    cases.append(Case("outputs", "diagnose --report . (the current folder)",
                      cli(["diagnose", data, "--effects", "delay", "--report", "."], cwd=str(holder)),
                      expect="refuse", protect=(holder,), timeout=120))
    cases.append(Case("outputs", "diagnose --report ''", cli(["diagnose", fx.rec, "--report", ""]), expect="refuse"))
    cases.append(Case("outputs", "diagnose --report FILE", cli(["diagnose", fx.rec, "--report", m]), expect="refuse",
                      protect=(m,)))
    # batch: the page's default name over a file of the user's, the table over a record
    fleet = d / "fleet"
    fleet.mkdir()
    r1 = fresh("fleet/r1.csv", fx.rec)
    page = d / "x.html"
    page.write_text("<p>the user's own page</p>")
    cases.append(Case("outputs", "batch --out x.csv over a user's x.html",
                      cli(["batch", fleet, "--workers", "1", "--out", d / "x.csv"]), expect="refuse",
                      protect=(page, r1), timeout=150))
    cases.append(Case("outputs", "batch --out over a record", cli(["batch", fleet, "--workers", "1", "--out", r1]),
                      expect="refuse", protect=(r1,), timeout=150))
    cases.append(Case("outputs", "batch --html over a record",
                      cli(["batch", fleet, "--workers", "1", "--html", r1]), expect="refuse", protect=(r1,),
                      timeout=150))
    cases += model_output_cases(fx, d, fresh)
    return cases


def model_output_cases(fx: Fixtures, d: Path, fresh: Callable[[str, Path], Path]) -> list[Case]:
    """The model file (identify/fit -o), simulate's formats and compare's report: never over what the run reads."""
    cases = []
    model = fresh("model.json", fx.model())
    as_json = fresh("rec_as.json", fx.rec)                  # a record whose name ends like a model file's
    os.symlink(as_json, d / "rec_link.json")
    for spelling in (str(as_json), f"{d}/./rec_as.json", str(d / "rec_link.json")):
        cases.append(Case("outputs", f"identify -o {spelling[-22:]} (the data)",
                          cli(["identify", as_json, "-o", spelling]), expect="refuse", protect=(as_json,)))
        cases.append(Case("outputs", f"fit -o {spelling[-22:]} (the data)",
                          cli(["fit", as_json, "--effects", "delay", "-o", spelling]), expect="refuse",
                          protect=(as_json,), timeout=120))
    m = d / "m.csv"
    cases.append(Case("outputs", "identify -o m.csv (the data, not .json)", cli(["identify", m, "-o", m]),
                      expect="refuse", protect=(m,)))
    cases.append(Case("outputs", "identify -o ''", cli(["identify", m, "-o", ""]), expect="refuse", protect=(m,)))
    cases.append(Case("outputs", "identify -o a folder.json", cli(["identify", m, "-o", d / "rep_user"]),
                      expect="refuse", protect=(m,)))
    for flag in ("--model", "--params"):
        for spelling in (str(model), f"{d}/./model.json"):
            cases.append(Case("outputs", f"simulate {flag} model.json -o {spelling[-18:]}",
                              cli(["simulate", "--input", fx.tu, flag, model, "-o", spelling]), expect="refuse",
                              protect=(model,)))
    cases.append(Case("outputs", "simulate -o x.xlsx (unknown format)",
                      cli(["simulate", "--input", fx.tu, "--model", model, "-o", d / "x.xlsx"]), expect="refuse"))
    cases.append(Case("outputs", "simulate -o sim.parquet", cli(["simulate", "--input", fx.tu, "--model", model,
                                                                  "-o", d / "sim.parquet"]),
                      expect="ok", protect=(model, fx.tu)))
    for name in ("rep_user", "rep_mixed", "holder"):
        folder = d / name
        cases.append(Case("outputs", f"compare --report {name}",
                          cli(["compare", model, fx.rec, "--report", folder]), expect="refuse",
                          protect=(folder, model), timeout=120))
    cases.append(Case("outputs", "compare --report over the model file",
                      cli(["compare", model, fx.rec, "--report", model]), expect="refuse", protect=(model,)))
    cases.append(Case("outputs", "compare --report ''", cli(["compare", model, fx.rec, "--report", ""]),
                      expect="refuse", protect=(model,)))
    rep = d / "cmp_rep"
    cases.append(Case("outputs", "compare --report NEW (marker written)",
                      cli(["compare", model, fx.rec, "--report", rep]), expect="ok", protect=(model,),
                      check=lambda res, rep=rep: None if res.code != 0 or (rep / ".creep-online-report").is_file()
                      else "silently_wrong", timeout=120))
    cases.append(Case("outputs", "compare --report NEW again (its own earlier report)",
                      cli(["compare", model, fx.rec, "--report", rep]), expect="ok", protect=(model,), timeout=120))
    return cases


def signal_cases(fx: Fixtures, plant: "PlantServers") -> list[Case]:
    """Streams, batches, simulate and start-up ended by Ctrl-C, SIGTERM and SIGHUP, as a service manager sends them."""
    cases = []
    sigs = {"SIGINT": signal.SIGINT, "SIGTERM": signal.SIGTERM, "SIGHUP": signal.SIGHUP}
    for sname, signum in sigs.items():
        for label, spec, after in (("csv realtime", f"csv:{fx.big}?realtime=1", 4.0),
                                   ("csv replay", f"csv:{fx.big}", 4.5),
                                   ("canlog realtime", f"canlog:{fx.canlogs.get('.asc')}?rate={CAN_RATE:g}&realtime=1",
                                    4.0)):
            work = fx.workdir(f"sig-{label.replace(' ', '_')}-{sname}")
            cases.append(Case("signals", f"stream {label} {sname}",
                              signalled([*_creep(), "stream", "--source", spec, "--trace", str(work / "trace.csv")],
                                        signum, after),
                              expect="custom", check=_stream_signalled(signum, work), timeout=90))
        for transport in ("serial-binary", "capancdt"):
            work = fx.workdir(f"sig-{transport}-{sname}")
            cases.append(Case("signals", f"stream {transport} {sname}",
                              plant.signalled_stream(transport, signum, work), expect="custom",
                              check=_stream_signalled(signum, work), timeout=120))
        work = fx.workdir(f"sig-simulate-{sname}")
        big_tu = work / "big_tu.csv"
        big_tu.write_text("t,u\n" + "".join(f"{k * 1e-4!r},{float(k > 10)!r}\n" for k in range(400_000)))
        old = work / "out.csv"
        old.write_text("old output\n")
        cases.append(Case("signals", f"simulate -o {sname}",
                          signalled([*_creep(), "simulate", "--input", str(big_tu), "--params",
                                     "alpha=0.3,a1=0.01,a2=1e-4", "--method", "paper", "-o", str(old)], signum, 4.0),
                          expect="custom", check=_simulate_signalled(signum, work, old), timeout=120))
        work = fx.workdir(f"sig-diagnose-{sname}")
        cases.append(Case("signals", f"diagnose --report {sname}",
                          signalled([*_creep(), "diagnose", str(fx.rec), "--workers", "1", "--report",
                                     str(work / "rep")], signum, 5.0),
                          expect="custom", check=_plain_signalled(signum, work), timeout=120))
        work = fx.workdir(f"sig-compare-{sname}")
        cases.append(Case("signals", f"compare --report {sname}",
                          signalled([*_creep(), "compare", str(fx.model()), str(fx.big), "--report",
                                     str(work / "rep")], signum, 4.0),
                          expect="custom", check=_plain_signalled(signum, work), timeout=120))
        if signum == signal.SIGTERM:
            work = fx.workdir(f"sig-parquet-{sname}")
            cases.append(Case("signals", f"simulate -o .parquet {sname}",
                              signalled([*_creep(), "simulate", "--input", str(big_tu), "--params",
                                         "alpha=0.3,a1=0.01,a2=1e-4", "--method", "paper", "-o",
                                         str(work / "out.parquet")], signum, 4.0),
                              expect="custom", check=_plain_signalled(signum, work), timeout=120))
    for after in (0.05, 0.15, 0.3, 0.6, 1.0, 1.6):
        work = fx.workdir(f"sig-startup-{after}")
        cases.append(Case("signals", f"identify Ctrl-C at start-up +{after} s",
                          signalled([*_creep(), "identify", str(fx.rec)], signal.SIGINT, after),
                          expect="custom", check=_plain_signalled(signal.SIGINT, work, finished_ok=True), timeout=90,
                          data={"startup": True}))
    for sname, signum in sigs.items():
        work = fx.workdir(f"sig-batch-{sname}")
        many = work / "many"
        many.mkdir()
        for k in range(30):
            os.symlink(fx.rec, many / f"r{k:02d}.csv")
        cases.append(Case("signals", f"batch {sname}",
                          signalled([*_creep(), "batch", str(many), "--workers", "1", "--out", str(work / "t.csv")],
                                    signum, 25.0),
                          expect="custom", check=_batch_signalled(signum, work), timeout=180))
    return cases


def _creep() -> list[str]:
    return [sys.executable, "-m", "creep_online"]


def signalled(cmd: list[str], signum: int, after: float) -> Callable[[Case], Outcome]:
    """A subprocess sent ``signum`` ``after`` seconds after it started (its own signal dispositions default)."""
    def run(case: Case) -> Outcome:
        start = time.monotonic()
        p = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             start_new_session=True,
                             preexec_fn=lambda: [signal.signal(s, signal.SIG_DFL)
                                                 for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)])
        time.sleep(after)
        try:
            p.send_signal(signum)
        except ProcessLookupError:
            pass
        try:
            out, err = p.communicate(timeout=case.timeout)
            hung = False
        except subprocess.TimeoutExpired:
            _kill_group(p.pid)
            out, err = p.communicate()
            hung = True
        _kill_group(p.pid)
        return Outcome(code=None if hung else p.returncode, out=out.decode(errors="replace"),
                       err=err.decode(errors="replace"), hung=hung, seconds=time.monotonic() - start)
    return run


def _temp_left(work: Path) -> bool:
    return any(p.name.endswith(".tmp") or ".tmp" in p.name for p in work.rglob(".*"))


def _stream_signalled(signum: int, work: Path) -> Callable[[Outcome], str | None]:
    def check(res: Outcome) -> str | None:
        if res.code == 0 and "alpha" in res.out:
            return None                              # the stream had ended before the signal
        if res.code == 128 + signum and one_line_stop(res.err) and ("before the first sample arrived" in res.err
                                                                      or "while starting" in res.err):
            return None                              # stopped while starting (a busy machine): said so, on one line
        if res.code not in (128 + signum, -signum) or "alpha" not in res.out:
            return "no_estimate" if res.code in (128 + signum, -signum) or "alpha" not in res.out else "messy_error"
        if _temp_left(work):
            return "temp_left"
        trace = work / "trace.csv"
        if trace.exists() and trace.read_text().count("\n") < 2:
            return "no_estimate"
        return None
    return check


def _simulate_signalled(signum: int, work: Path, old: Path) -> Callable[[Outcome], str | None]:
    def check(res: Outcome) -> str | None:
        if _temp_left(work):
            return "temp_left"
        if res.code == 0:
            return None
        if old.read_text() != "old output\n":
            return "file_lost"
        return None if res.code == 128 + signum and one_line_stop(res.err) else "messy_error"
    return check


def _plain_signalled(signum: int, work: Path, finished_ok: bool = False) -> Callable[[Outcome], str | None]:
    def check(res: Outcome) -> str | None:
        if _temp_left(work) or any(p.name.startswith(".rep.") for p in work.iterdir()):
            return "temp_left"
        if res.code == 0:
            return None
        if finished_ok and res.code == -signum and res.out:
            return None                  # the command had ended (its output whole): the interpreter's last moments
        return None if res.code == 128 + signum and one_line_stop(res.err) else "messy_error"
    return check


def one_line_stop(err: str) -> bool:
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip() and ": warning: " not in ln
             and not ln.lstrip().startswith("[")]
    return len(lines) <= 2 and all("creep-online" in ln for ln in lines)


def _batch_signalled(signum: int, work: Path) -> Callable[[Outcome], str | None]:
    def check(res: Outcome) -> str | None:
        if "leaked semaphore" in res.err:
            return "temp_left"
        if res.code in (0, 1):
            return None
        if res.code != 128 + signum:
            return "messy_error"
        table = work / "t.csv"
        m = re.search(r"after (\d+) of", res.err)
        done = int(m.group(1)) if m else -1
        rows = table.read_text().count("\n") - 1 if table.exists() else 0
        return None if done >= 0 and rows == done else "file_lost"
    return check


def pipe_cases(fx: Fixtures) -> list[Case]:
    """Pipes, FIFOs, '-' and devices as inputs: read as streams, bounded, never waited on forever."""
    rec, gz = str(fx.rec), str(fx.gz)
    exe = " ".join(_creep())
    d = fx.workdir("pipes")
    fifo, lonely = d / "fifo", d / "lonely"
    os.mkfifo(fifo)
    os.mkfifo(lonely)
    ok = on_exit0(identified_ok)
    cases = [
        Case("pipes", "identify - < file", proc(f"{exe} identify - --json < {rec}", shell=True), expect="ok", check=ok),
        Case("pipes", "identify /dev/stdin < file", proc(f"{exe} identify /dev/stdin --json < {rec}", shell=True),
             expect="ok", check=ok),
        Case("pipes", "cat | identify -", proc(f"cat {rec} | {exe} identify - --json", shell=True), expect="ok",
             check=ok),
        Case("pipes", "identify <(cat file)", proc(f"{exe} identify <(cat {rec}) --json", shell=True), expect="ok",
             check=ok),
        Case("pipes", "identify <(zcat file.gz)", proc(f"{exe} identify <(zcat {gz}) --json", shell=True),
             expect="ok", check=ok),
        Case("pipes", "identify GCS <(cat)", proc(f"{exe} identify <(cat {fx.gcs}) --json", shell=True),
             expect="either", check=ok),
        Case("pipes", "stream csv:<(cat file)", proc(f"{exe} stream --source csv:<(cat {rec}) --json", shell=True),
             expect="ok", check=on_exit0(estimate_ok)),
        Case("pipes", "stream csv:- < file", proc(f"{exe} stream --source csv:- --json < {rec}", shell=True),
             expect="ok", check=on_exit0(estimate_ok)),
        Case("pipes", "diagnose <(cat file)",
             proc(f"{exe} diagnose <(cat {rec}) --effects delay --workers 1 --json", shell=True), expect="ok",
             timeout=150),
        Case("pipes", "fit <(cat file)", proc(f"{exe} fit <(cat {rec}) --effects delay --json", shell=True),
             expect="ok", timeout=150),
        Case("pipes", "simulate --input <(cat tu.csv)",
             proc(f"{exe} simulate --input <(cat {fx.tu}) --params alpha=0.3,a1=0.01,a2=1e-4 -o {d}/sim.csv",
                  shell=True), expect="ok"),
        Case("pipes", "identify FIFO with a writer",
             proc(f"(sleep 2; cat {rec} > {fifo}) & {exe} identify {fifo} --json; wait", shell=True), expect="ok",
             check=ok),
        Case("pipes", "identify FIFO with no writer",
             proc(f"{exe} identify {lonely}", shell=True, env={"CREEP_ONLINE_READ_TIMEOUT": "3"}), expect="refuse",
             timeout=40),
        Case("pipes", "diagnose FIFO with no writer",
             proc(f"{exe} diagnose {lonely}", shell=True, env={"CREEP_ONLINE_READ_TIMEOUT": "3"}), expect="refuse",
             timeout=40),
        Case("pipes", "identify a writer that stalls",
             proc(f"(head -c 1000 {rec}; sleep 30) | {exe} identify -", shell=True,
                  env={"CREEP_ONLINE_READ_TIMEOUT": "3"}), expect="refuse", timeout=40),
        Case("pipes", "identify empty pipe", proc(f"{exe} identify - < /dev/null", shell=True), expect="refuse"),
        Case("pipes", "identify /dev/zero", proc(f"{exe} identify /dev/zero", shell=True), expect="refuse"),
        Case("pipes", "identify endless line pipe", proc(f"head -c 100000000 /dev/zero | {exe} identify -",
                                                         shell=True), expect="refuse"),
        Case("pipes", "stream capancdt command=/dev/zero",
             cli(["stream", "--source", "capancdt:127.0.0.1:9?command=/dev/zero"]), expect="refuse"),
        Case("pipes", "stream canlog dbc=/dev/zero",
             cli(["stream", "--source", f"canlog:{fx.canlogs.get('.asc')}?rate=2000&dbc=/dev/zero"]),
             expect="refuse"),
        Case("pipes", "stream capancdt command=<FIFO no writer>",
             cli(["stream", "--source", f"capancdt:127.0.0.1:9?command={lonely}"],
                 env={"CREEP_ONLINE_READ_TIMEOUT": "3"}), expect="refuse", timeout=40),
        Case("pipes", "batch <(cat file)", proc(f"{exe} batch <(cat {rec}) --workers 1 --json", shell=True),
             expect="ok", timeout=150),
    ]
    return cases


# ------------------------------------------------------------------ API
def api_cases(fx: Fixtures) -> list[Case]:
    """Every public function and method with numbers of every kind and non-numbers: DataError, one line."""
    numbers_ok = {"np.float32": np.float32(0.5), "np.float16": np.float16(0.5), "np.int8": np.int8(1),
                  "np.uint64": np.uint64(1), "int": 1, "Fraction": Fraction(1, 3), "np.float64": np.float64(0.5)}
    not_numbers = {"str '1.0'": "1.0", "True": True, "None": None, "bytes": b"1", "complex": 1 + 2j,
                   "10**400": 10 ** 400, "datetime64": np.datetime64(1, "s"), "list": [1.0], "dict": {"u": 1},
                   "object": object(), "np.bool_": np.bool_(True), "1-D array": np.ones(1), "str ''": ""}
    cases = []

    def est():
        from creep_online.online import OnlineEstimator
        return OnlineEstimator(1e-3)

    for pos in ("u", "y"):
        for name, v in {**numbers_ok, **not_numbers}.items():
            args = (v, 0.5) if pos == "u" else (0.5, v)
            cases.append(Case("api", f"update({pos}={name})", api(lambda a=args: est().update(*a)),
                              expect="ok" if name in numbers_ok else "refuse"))
    arrays_ok = {"float32": np.ones(50, np.float32), "int": np.arange(50), "list": [0.0] * 50,
                 "object floats": np.array([0.5] * 50, dtype=object)}
    arrays_bad = {"text": ["1"] * 50, "bool": np.ones(50, bool), "complex": np.ones(50, complex),
                  "datetime": np.arange(50).astype("datetime64[s]"), "None": None, "2-D": np.ones((5, 10)),
                  "scalar": 1.0, "str": "1,2,3", "ragged": [[1.0], [1.0, 2.0]], "huge int": [10 ** 400] * 50,
                  "dict": {"a": 1}}
    for name, arr in {**arrays_ok, **arrays_bad}.items():
        cases.append(Case("api", f"update_block(u={name})", api(lambda a=arr: est().update_block(a, np.zeros(50))),
                          expect="ok" if name in arrays_ok else "refuse"))
    cases.append(Case("api", "update_block(mismatched lengths)", api(lambda: est().update_block(np.ones(5), np.ones(6))),
                      expect="refuse"))
    for name, n in {"'3'": "3", "nan": float("nan"), "inf": float("inf"), "-1": -1, "1.5": 1.5, "None": None,
                    "True": True, "10**400": 10 ** 400, "np.int64(5)": np.int64(5), "3.0": 3.0}.items():
        cases.append(Case("api", f"gap({name})", api(lambda v=n: est().gap(v)),
                          expect="ok" if name in ("np.int64(5)", "3.0") else "refuse"))
    cases.append(Case("api", "gap(10**9) in bounded time", api(_timed_gap), expect="ok"))
    ctor = {"dt": ["1e-3", float("nan"), 0.0, -1.0, 10 ** 400, None, np.float32(1e-3), np.int64(1)],
            "window_s": [float("nan"), 0.0, 1e-300, "10", -1.0, np.float32(5.0)],
            "t_c": [float("nan"), 1e300, 0.0, "1", np.float32(0.5)],
            "alpha0": [1.5, 0.0, float("nan"), "0.3", np.float32(0.3)],
            "refit": ["bogus", None, 1, "window"]}
    for key, values in ctor.items():
        for v in values:
            good = isinstance(v, (np.floating, np.integer)) and key != "dt" or (key == "dt" and isinstance(
                v, np.float32)) or v == "window"
            kw = {key: v} if key != "dt" else {}
            dt = v if key == "dt" else 1e-3
            cases.append(Case("api", f"OnlineEstimator({key}={v!r:.20})",
                              api(lambda dt=dt, kw=kw: _make_estimator(dt, kw)), expect="ok" if good else "refuse"))
    t = np.arange(500) * 1e-3
    u = (t > 0.05).astype(float)
    from creep_online import CreepModel, simulate as sim
    y = sim(CreepModel(**TRUE), t, u)
    for name, (tt, uu, yy) in {"t text": ([str(x) for x in t], u, y), "u complex": (t, u.astype(complex), y),
                               "t datetime": (t.astype("datetime64[ms]"), u, y), "y None": (t, u, None),
                               "dict": ({"t": 1}, u, y), "object": (object(), u, y), "u bool": (t, u > 0, y),
                               "t 2-D": (np.vstack([t, t]), u, y), "huge int": ([10 ** 400] * 500, u, y),
                               "t float32": (t.astype(np.float32), u, y)}.items():
        cases.append(Case("api", f"identify({name})", api(lambda a=(tt, uu, yy): _identify(*a)),
                          expect="either" if name == "t float32" else "refuse"))
        cases.append(Case("api", f"diagnose({name})", api(lambda a=(tt, uu, yy): _diagnose(*a)),
                          expect="either" if name == "t float32" else "refuse", timeout=120))
    for kw in ({"t_c": "1"}, {"t_c": float("inf")}, {"layer1_step": 1e300}, {"alpha0": "0.3"},
               {"resonance0": ("a", 1)}, {"offset": float("nan")}, {"t_c": 10 ** 400}):
        cases.append(Case("api", f"identify({kw})", api(lambda k=kw: _identify(t, u, y, **k)), expect="refuse"))
    for name, call in {"method bogus": lambda: sim(CreepModel(**TRUE), t, u, method="bogus"),
                       "memory -5": lambda: sim(CreepModel(**TRUE), t, u, method="paper", memory=-5),
                       "memory '3'": lambda: sim(CreepModel(**TRUE), t, u, method="paper", memory="3"),
                       "memory 1.5": lambda: sim(CreepModel(**TRUE), t, u, method="paper", memory=1.5),
                       "model dict": lambda: sim(dict(TRUE), t, u), "u text": lambda: sim(CreepModel(**TRUE), t,
                                                                                           ["1"] * 500),
                       "t nan": lambda: sim(CreepModel(**TRUE), t * np.nan, u),
                       "method None": lambda: sim(CreepModel(**TRUE), t, u, method=None)}.items():
        cases.append(Case("api", f"simulate({name})", api(call), expect="refuse"))
    for name, kw in {"alpha '0.3'": {"alpha": "0.3"}, "alpha True": {"alpha": True}, "a1 10**400": {"a1": 10 ** 400},
                     "a2 nan": {"a2": float("nan")}, "b 0": {"b": 0.0}, "a1 1e300": {"a1": 1e300},
                     "alpha np.float32": {"alpha": np.float32(0.3)}}.items():
        cases.append(Case("api", f"CreepModel({name})", api(lambda k=kw: CreepModel(**{**TRUE, **k})),
                          expect="ok" if "float32" in name else "refuse"))
    for name, kw in {"fn 1e300": {"fn": 1e300}, "fn 1e-300": {"fn": 1e-300}, "zeta '0.1'": {"zeta": "0.1"},
                     "fn nan": {"fn": float("nan")}}.items():
        cases.append(Case("api", f"CreepModel.from_resonance({name})",
                          api(lambda k=kw: CreepModel.from_resonance(**{"alpha": 0.3, "fn": 10.0, "zeta": 0.1, **k})),
                          expect="refuse"))

    def comp(**kw):
        from creep_online.online import CreepCompensator
        return CreepCompensator(kw.pop("dt", 1e-3), CreepModel(0.1, 1e-3, 1e-6, 1.0), **kw)

    for name, v in {**numbers_ok, **not_numbers}.items():
        cases.append(Case("api", f"command(r={name})", api(lambda r=v: comp().command(r)),
                          expect="ok" if name in numbers_ok else "refuse"))
    for name, arr in {**arrays_ok, **arrays_bad}.items():
        cases.append(Case("api", f"command_block(r={name})", api(lambda a=arr: comp().command_block(a)),
                          expect="ok" if name in arrays_ok else "refuse"))
    for name, kw in {"dt float32": {"dt": np.float32(1e-3)}, "dt '1e-3'": {"dt": "1e-3"},
                     "u_min float32": {"u_min": np.float32(-1.0)}, "u_max nan": {"u_max": float("nan")},
                     "bandwidth 0": {"bandwidth_hz": 0.0}, "bandwidth '5'": {"bandwidth_hz": "5"}}.items():
        cases.append(Case("api", f"CreepCompensator({name})", api(lambda k=kw: comp(**k)),
                          expect="ok" if "float32" in name else "refuse"))
    return cases


def _make_estimator(dt, kw):
    from creep_online.online import OnlineEstimator
    return OnlineEstimator(dt, **kw)


def _identify(t, u, y, **kw):
    from creep_online import identify
    return identify(t, u, y, **kw)


def _diagnose(t, u, y):
    from creep_online import diagnose
    return diagnose((t, u, y), candidates=("delay",), workers=1)


def _timed_gap():
    est = _make_estimator(1e-3, {})
    t = np.arange(3000) * 1e-3
    from creep_online import CreepModel, simulate as sim
    u = (t > 0.05).astype(float)
    est.update_block(u, sim(CreepModel(**TRUE), t, u))
    start = time.perf_counter()
    est.gap(10 ** 9)
    took = time.perf_counter() - start
    if took > 1.0:
        raise RuntimeError(f"gap(10**9) took {took:.1f} s")
    return took


# ------------------------------------------------------------------ pickle
def pickle_cases(fx: Fixtures) -> list[Case]:
    """OnlineEstimator (both refits), CreepCompensator and the trackers: pickle and deepcopy at every phase, the
    copy continuing bit for bit."""
    cases = []
    for refit in ("window", "recursive"):
        for phase, at in (("buffering", 30), ("buffering-planned", 52), ("searching", None), ("tracking", 2600),
                          ("after-change", 4400), ("re-search", 4700)):
            for how in ("pickle", "deepcopy"):
                cases.append(Case("pickle", f"OnlineEstimator({refit}) {how} {phase}",
                                  api(lambda r=refit, a=at, h=how, p=phase: _round_trip(r, a, h, p)), expect="ok",
                                  timeout=240))
    for has_model in (False, True):
        for how in ("pickle", "deepcopy"):
            cases.append(Case("pickle", f"CreepCompensator model={has_model} {how}",
                              api(lambda m=has_model, h=how: _compensator_round_trip(m, h)), expect="ok"))
    for refit in ("window", "recursive"):
        for how in ("pickle", "deepcopy"):
            cases.append(Case("pickle", f"tracker ({refit}) alone {how}",
                              api(lambda r=refit, h=how: _tracker_round_trip(r, h)), expect="ok", timeout=240))
    return cases


def _pickle_data():
    from creep_online import CreepModel, simulate as sim
    h, n = 1e-3, 8000
    t = np.arange(n) * h
    u = np.where((t % 2) > 1, 1.0, 0.0)
    y = sim(CreepModel(**TRUE), t, u)
    y[4000:] = sim(CreepModel(0.3, 0.01, 2e-4, 2.0), t, u)[4000:]
    return h, u, y + 1e-4 * np.random.default_rng(1).standard_normal(n)


def _copy(obj, how):
    return pickle.loads(pickle.dumps(obj)) if how == "pickle" else copy.deepcopy(obj)


def _round_trip(refit: str, at: int | None, how: str, phase: str) -> float:
    h, u, y = _pickle_data()
    est = _make_estimator(h, {"refit": refit})
    k = 0
    if at is None:                                    # the first sample of the search
        while est.phase != "searching":
            est.update(u[k], y[k])
            k += 1
        est.update(u[k], y[k])
        k += 1
    else:
        for k in range(at):
            est.update(u[k], y[k])
        k = at
    if phase.startswith("searching") and est.phase != "searching":
        raise RuntimeError(f"not in the phase tested ({est.phase})")
    twin = _copy(est, how)
    for j in range(k, min(k + 1500, u.size)):
        est.update(u[j], y[j])
        twin.update(u[j], y[j])
    a, b = est.estimate, twin.estimate
    if (a.alpha, a.a1, a.a2, a.b, a.quality, a.phase, len(a.events)) != \
            (b.alpha, b.a1, b.a2, b.b, b.quality, b.phase, len(b.events)):
        raise RuntimeError(f"the copy diverged: {a.alpha!r} vs {b.alpha!r}")
    return a.alpha


def _compensator_round_trip(has_model: bool, how: str) -> float:
    from creep_online import CreepModel
    from creep_online.online import CreepCompensator
    c = CreepCompensator(1e-3, CreepModel(0.3, 0.01, 1e-4, 2.0) if has_model else None, u_min=-5, u_max=5)
    r = np.sin(np.arange(2000) * 0.01)
    for k in range(700):
        c.command(r[k])
    twin = _copy(c, how)
    if not has_model:
        c.set_model(CreepModel(0.3, 0.01, 1e-4, 2.0))
        twin.set_model(CreepModel(0.3, 0.01, 1e-4, 2.0))
    a = [c.command(v) for v in r[700:]]
    b = [twin.command(v) for v in r[700:]]
    if a != b:
        raise RuntimeError("the copy diverged")
    return a[-1]


def _tracker_round_trip(refit: str, how: str) -> float:
    h, u, y = _pickle_data()
    est = _make_estimator(h, {"refit": refit})
    est.update_block(u[:3000], y[:3000])
    tr = est._tracker
    twin = _copy(tr, how)
    du = u[3000:4500] - (est._u_ref or 0.0)
    for j in range(du.size):
        tr.feed(float(du[j]), float(y[3000 + j]))
        twin.feed(float(du[j]), float(y[3000 + j]))
    if (tr.alpha, tr.a1, tr.a2, tr.b) != (twin.alpha, twin.a1, twin.a2, twin.b):
        raise RuntimeError("the tracker's copy diverged")
    return tr.alpha


# ------------------------------------------------------------------ CAN logs
def canlog_cases(fx: Fixtures) -> list[Case]:
    """One unreadable record in a CAN log of every format: skipped, counted, the replay goes on."""
    cases = []
    d = fx.workdir("canlog")
    for suffix, path in fx.canlogs.items():
        raw = path.read_bytes()
        variants = {}
        if suffix == ".blf":
            for frac in (0.3, 0.5, 0.7):
                k = int(len(raw) * frac)
                variants[f"flipped byte at {frac:.0%}"] = raw[:k] + bytes([raw[k] ^ 0xFF]) + raw[k + 1:]
            variants["truncated"] = raw[:int(len(raw) * 0.8)]
        else:
            lines = raw.split(b"\n")
            for frac in (0.3, 0.5):
                bad = list(lines)
                bad[int(len(bad) * frac)] = b"\x00\xff garbage record ### 12 zz"
                variants[f"garbage line at {frac:.0%}"] = b"\n".join(bad)
            bad = list(lines)
            k = int(len(bad) * 0.6)
            bad[k] = bad[k][: len(bad[k]) // 2]
            variants["half a line at 60%"] = b"\n".join(bad)
            variants["truncated"] = raw[:int(len(raw) * 0.8)]
        for name, content in variants.items():
            p = d / f"{name.replace(' ', '_').replace('%', '')}{suffix}"
            p.write_bytes(content)
            cases.append(Case("canlog", f"{suffix} {name}",
                              cli(["stream", "--source", f"canlog:{p}?rate={CAN_RATE:g}", "--json"]),
                              expect="ok", check=_canlog_kept(suffix, 0.8 if name == "truncated" else 1.0),
                              timeout=90))
    return cases


def _canlog_kept(suffix: str, present: float) -> Callable[[Outcome], str | None]:
    """The replay went on past the bad record: most of the ``present`` fraction of the samples arrived, and the
    estimate is right or honestly none."""
    def check(res: Outcome) -> str | None:
        d = _json(res)
        if res.code != 0 or d is None:
            return None
        kept = d.get("samples", 0) / (2.0 * CAN_RATE) / present
        if kept < (0.5 if suffix == ".blf" else 0.85):
            return "silently_wrong"
        return estimate_ok(res, alpha=PLANT_ALPHA)
    return check


# ------------------------------------------------------------------ security
def security_cases(fx: Fixtures) -> list[Case]:
    """Record names that are spreadsheet formulas; escape sequences in file names and CSV headers."""
    cases = []
    d = fx.workdir("security")
    names = ["=cmd|' -C calc'!A0", "@SUM(1+1)", "+1+1", "-2+3", "=HYPERLINK(\"http:x\")", "\tTAB"]
    fleet = d / "fleet"
    fleet.mkdir()
    for name in names:
        shutil.copy(fx.rec, fleet / f"{name}.csv")
    table = d / "table.csv"
    for name in names:
        cases.append(Case("security", f"batch record named {name!r}",
                          cli(["batch", fleet, "--workers", "1", "--out", table]), expect="custom",
                          check=_formula_neutral(table, name), timeout=200))
    esc_names = ["rec\x1b]0;pwned\x07.csv", "rec\x1b[2J.csv", "rec\x9b31m.csv", "rec\r\x1b[1A.csv"]
    for name in esc_names:
        p = d / name
        shutil.copy(fx.rec, p)
        cases.append(Case("security", f"identify file {name!r}", cli(["identify", p]), expect="ok"))
        cases.append(Case("security", f"identify missing {name!r}", cli(["identify", d / ("no" + name)]),
                          expect="refuse"))
        cases.append(Case("security", f"stream spec {name!r}", cli(["stream", "--source", f"nosuch{name}:x"]),
                          expect="refuse"))
    head = d / "header.csv"
    head.write_text("t,u\x1b]0;pwned\x07,z\n0,1,2\n")
    cases.append(Case("security", "CSV header with an escape sequence", cli(["identify", head]), expect="refuse"))
    esc_fleet = d / "escfleet"
    esc_fleet.mkdir()
    shutil.copy(fx.rec, esc_fleet / "ok.csv")
    (esc_fleet / "bad\x1b]0;pwned\x07.csv").write_text("t,u,y\n0,0,0\n")
    cases.append(Case("security", "batch failure named with an escape sequence",
                      cli(["batch", esc_fleet, "--workers", "1"]), expect="custom", timeout=200))
    return cases


def _formula_neutral(table: Path, name: str) -> Callable[[Outcome], str | None]:
    def check(res: Outcome) -> str | None:
        if not table.exists():
            return "valid_refused"
        import csv as csvmod
        with open(table, newline="") as fh:
            for row in csvmod.DictReader(fh):
                for cell in row.values():
                    if cell and cell[0] in "=+-@\t\r" and not _is_number(cell):
                        return "injection"
        return None
    return check


# ------------------------------------------------------------------ scheduler
class FakeServers:
    """A silent port, an echo service and an HTTP-like service on loopback (threads of this process)."""

    def __init__(self) -> None:
        self.ports = {}
        self._socks = []
        for kind in ("silent", "echo", "http"):
            s = socket.socket()
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(("127.0.0.1", 0))
            s.listen(64)
            self._socks.append(s)
            self.ports[kind] = s.getsockname()[1]
            threading.Thread(target=self._serve, args=(s, kind), daemon=True).start()
        closed = socket.socket()
        closed.bind(("127.0.0.1", 0))
        self.ports["closed"] = closed.getsockname()[1]
        closed.close()

    def _serve(self, s: socket.socket, kind: str) -> None:
        held = []
        while True:
            try:
                c, _ = s.accept()
            except OSError:
                return
            if kind == "silent":
                held.append(c)
            else:
                threading.Thread(target=self._answer, args=(c, kind), daemon=True).start()

    @staticmethod
    def _answer(c: socket.socket, kind: str) -> None:
        try:
            while True:
                data = c.recv(65536)
                if not data:
                    break
                c.sendall(data if kind == "echo" else b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
                if kind == "http":
                    break
        except OSError:
            pass
        finally:
            c.close()


def scheduler_cases(fx: Fixtures, servers: FakeServers) -> list[Case]:
    cases = []
    for kind, port in servers.ports.items():
        cases.append(Case("scheduler", f"batch --scheduler to a {kind} port",
                          cli(["batch", fx.rec, "--scheduler", f"tcp://127.0.0.1:{port}"]), expect="refuse",
                          timeout=90))
    for text in ("garbage", "tcp://", "http://127.0.0.1:1", "tcp://[::1:80"):
        cases.append(Case("scheduler", f"batch --scheduler {text!r}", cli(["batch", fx.rec, "--scheduler", text]),
                          expect="refuse", timeout=90))
    return cases


# ------------------------------------------------------------------ hil_sim
def hil_sim_cases(fx: Fixtures, servers: FakeServers) -> list[Case]:
    """The simulated plant's flags with hostile values: exit 0 or exit 2 with one line; no hang."""
    base = [sys.executable, "-m", "hil_sim", "--fast", "--duration", "0.01", "--rate", "1000", "--linger", "0"]
    flags = {"--rate": None, "--duration": None, "--noise": None, "--adc-bits": None, "--period": None,
             "--amplitude": None, "--t-start": None, "--adc-range": None, "--seed": None,
             "--command-rate": "capancdt", "--frames-per-packet": "capancdt", "--sensor-range": "capancdt",
             "--sensor-channels": "capancdt", "--linger": None}
    values = ("nan", "inf", "0", "-1", "1e300", "")
    cases = []
    for flag, transport in flags.items():
        for value in values:
            cmd = list(base)
            if flag in cmd:
                cmd[cmd.index(flag) + 1] = value
            else:
                cmd += [flag, value]
            if transport:
                cmd += ["--transport", transport]
            cases.append(Case("hil_sim", f"hil_sim {flag} {value!r}", proc(cmd, cwd=str(code_root())), timeout=30,
                              check=lambda res: None if res.code != 0 else None))
    for text in ("bogus", "drift:rate=nan", "{\"drift\": 3}", "{bad json", "delay:delay_s=abc", ";;;"):
        cases.append(Case("hil_sim", f"hil_sim --effects {text!r}", proc(base + ["--effects", text], cwd=str(code_root())),
                          timeout=30))
    for text in ("drop=nan", "drop=-1", "stall_s=0", "bogus=1", "drop", "drop_frames=0.5"):
        cases.append(Case("hil_sim", f"hil_sim --faults {text!r}", proc(base + ["--faults", text], cwd=str(code_root())),
                          timeout=30))
    for flag, text in (("--payload", "nan:1"), ("--payload", "1"), ("--drift", "alpha=nan"), ("--drift", "b"),
                       ("--params", "alpha=2"), ("--params", "fn=nan"), ("--link", "/no/such/dir/link")):
        cases.append(Case("hil_sim", f"hil_sim {flag} {text!r}", proc(base + [flag, text], cwd=str(code_root())), timeout=30))
    cases.append(Case("hil_sim", "hil_sim capancdt on a port already taken",
                      proc(base + ["--transport", "capancdt", "--port", str(servers.ports["silent"])], cwd=str(code_root())),
                      expect="refuse", timeout=30))
    return cases


# ------------------------------------------------------------------ bounded work
def bounded_cases(fx: Fixtures) -> list[Case]:
    plant = PlantServers(fx)
    cases = [Case("bounded", f"stream from a {transport} plant that ends (default settings)",
                  plant.ending_stream(transport, fx.workdir(f"ending-{transport}")), expect="custom",
                  check=_ended_with_estimate, timeout=200) for transport in ("serial-binary", "capancdt")]
    cases += [Case("bounded", "fit with all eight effects",
                  cli(["fit", fx.rec, "--effects", "hysteresis,nonlinear_gain,second_mode,drift,leakage,delay,"
                       "periodic_disturbance,second_creep"]), timeout=300),
             Case("bounded", "fit with five effects",
                  cli(["fit", fx.rec, "--effects", "drift,leakage,delay,second_mode,nonlinear_gain"]), timeout=300),
             Case("bounded", "stream --max-samples 10 on a file",
                  cli(["stream", "--source", f"csv:{fx.rec}", "--max-samples", "10", "--json"]), expect="ok",
                  check=lambda res: estimate_ok(res, 10)),
             Case("bounded", "stream --duration 0.5 on a realtime replay",
                  cli(["stream", "--source", f"csv:{fx.big}?realtime=1", "--duration", "0.5", "--json"]),
                  expect="ok", check=lambda res: None if res.seconds < 30 else "hang", timeout=60)]
    return cases


# ------------------------------------------------------------------ live plants (signals)
class PlantServers:
    """Streams from the simulated plant (serial pty, capaNCDT TCP) for the signal cases."""

    def __init__(self, fx: Fixtures) -> None:
        self.fx = fx

    def ending_stream(self, transport: str, work: Path) -> Callable[[Case], Outcome]:
        """A stream from a plant that ends after 4 s and does not come back (the stream's own defaults)."""
        def run(case: Case) -> Outcome:
            cmd = [sys.executable, "-m", "hil_sim", "--transport", transport, "--duration", "4", "--linger", "0"]
            if transport == "capancdt":
                cmd += ["--command-file", str(work / "command.csv")]
            plant = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, cwd=str(code_root()),
                                     start_new_session=True)
            try:
                port = plant.stdout.readline().decode().strip()
                if not port:
                    return Outcome(code=None, err="the plant did not start", hung=True)
                spec = (f"serial:{port}?rate=10000" if transport != "capancdt" else
                        f"capancdt:{port}?command={work / 'command.csv'}")
                return proc([*_creep(), "stream", "--source", spec])(case)
            finally:
                _kill_group(plant.pid)
                plant.wait()
        return run

    def signalled_stream(self, transport: str, signum: int, work: Path) -> Callable[[Case], Outcome]:
        def run(case: Case) -> Outcome:
            cmd = [sys.executable, "-m", "hil_sim", "--transport", transport, "--duration", "60", "--linger", "2"]
            if transport == "capancdt":
                cmd += ["--command-file", str(work / "command.csv")]
            plant = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, cwd=str(code_root()),
                                     start_new_session=True)
            try:
                port = plant.stdout.readline().decode().strip()
                if not port:
                    return Outcome(code=None, err="the plant did not start", hung=True)
                spec = (f"serial:{port}?rate=10000" if transport != "capancdt" else
                        f"capancdt:{port}?command={work / 'command.csv'}")
                stream = signalled([*_creep(), "stream", "--source", spec, "--trace", str(work / "trace.csv")],
                                   signum, 8.0)
                return stream(case)
            finally:
                _kill_group(plant.pid)
                plant.wait()
        return run


def _ended_with_estimate(res: Outcome) -> str | None:
    """A stream whose source went away for good: the estimate, and exit 0 or 4 (link lost)."""
    if res.code not in (0, 4):
        return "messy_error"
    return None if "alpha" in res.out else "no_estimate"


# ------------------------------------------------------------------ the sweep
def build(fx: Fixtures, only: set[str], servers: FakeServers) -> list[Case]:
    plant = PlantServers(fx)
    makers = {"flags": lambda: flag_cases(fx), "specs": lambda: spec_cases(fx), "files": lambda: file_cases(fx),
              "outputs": lambda: output_cases(fx), "signals": lambda: signal_cases(fx, plant),
              "pipes": lambda: pipe_cases(fx), "api": lambda: api_cases(fx), "pickle": lambda: pickle_cases(fx),
              "canlog": lambda: canlog_cases(fx), "security": lambda: security_cases(fx),
              "scheduler": lambda: scheduler_cases(fx, servers), "hil_sim": lambda: hil_sim_cases(fx, servers),
              "bounded": lambda: bounded_cases(fx)}
    cases: list[Case] = []
    for name in CATEGORIES:
        if name in only:
            cases += makers[name]()
    return cases


def warm() -> None:
    """Compile or load the kernels once here, so that each forked attempt starts warm."""
    from creep_online import CreepModel, identify, simulate
    from creep_online.cli import build_parser
    from creep_online.online import OnlineEstimator, warm_kernels
    import creep_online.diagnostics  # noqa: F401 - loaded here, once, for every forked attempt
    build_parser()                    # every command's module
    warm_kernels()
    t = np.arange(600) * 1e-3
    u = (t > 0.05).astype(float)
    y = simulate(CreepModel(**TRUE), t, u)
    identify(t, u, y + 1e-6 * np.sin(t * 50))
    OnlineEstimator(1e-3).update_block(u, y)


def sweep(only: set[str], sample: int = 1, offset: int = 0, verbose: bool = False, match: str | None = None) -> dict:
    """Run the chosen categories; the JSON report (counts per category and outcome, and the failures)."""
    root = Path(tempfile.mkdtemp(prefix="creep_sweep_"))
    servers = FakeServers()
    try:
        fx = Fixtures(root)
        warm()
        cases = build(fx, only, servers)
        if match:
            cases = [c for c in cases if re.search(match, c.name)]
        cases = cases[offset::sample]
        counts: dict[str, dict[str, int]] = {}
        failures = []
        start = time.monotonic()
        for i, case in enumerate(cases):
            case.data["digests"] = {str(p): _digest(p) for p in case.protect}
            res = case.run(case)
            label = classify(case, res)
            counts.setdefault(case.category, dict.fromkeys(OUTCOMES, 0))[label] += 1
            if label != "clean":
                failures.append({"category": case.category, "case": case.name, "outcome": label, "exit": res.code,
                                 "stderr": res.err.strip()[-300:], "api": res.api, "seconds": round(res.seconds, 2)})
            if verbose:
                print(f"[{i + 1}/{len(cases)}] {case.category}: {case.name[:70]} -> {label} ({res.seconds:.1f} s)",
                      file=sys.stderr, flush=True)
        totals = dict.fromkeys(OUTCOMES, 0)
        for per in counts.values():
            for k, v in per.items():
                totals[k] += v
        return {"attempts": len(cases), "seconds": round(time.monotonic() - start, 1), "totals": totals,
                "categories": counts, "failures": failures}
    finally:
        shutil.rmtree(root, ignore_errors=True)


def combine(parts: list[dict]) -> dict:
    """One report from sweeps of disjoint categories (their counts summed, their wall times side by side)."""
    report = {"attempts": 0, "seconds": 0.0, "totals": dict.fromkeys(OUTCOMES, 0), "categories": {}, "failures": [],
              "parts": []}
    for part in parts:
        report["attempts"] += part["attempts"]
        report["seconds"] = max(report["seconds"], part["seconds"])
        for k, v in part["totals"].items():
            report["totals"][k] += v
        for name, per in part["categories"].items():
            into = report["categories"].setdefault(name, dict.fromkeys(OUTCOMES, 0))
            for k, v in per.items():
                into[k] = into.get(k, 0) + v
        report["failures"] += part["failures"]
        report["parts"].append({"categories": sorted(part["categories"]), "attempts": part["attempts"],
                                "seconds": part["seconds"], "command": part.get("command")})
        report["code"] = part.get("code")
    return report


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=",".join(CATEGORIES), help="comma-separated categories")
    parser.add_argument("--sample", type=int, default=1, help="run every N-th attempt")
    parser.add_argument("--baseline", default=None,
                        help="run the sweep on this commit instead (git archive), or on a tree extracted before")
    parser.add_argument("--out", default=str(ROOT / "bench" / "results" / "reliability.json"))
    parser.add_argument("--list", action="store_true", help="print the failures too")
    parser.add_argument("--match", default=None, metavar="REGEX",
                        help="only attempts whose name matches (e.g. '^batch ' for the batch flags); parts that "
                             "together cover a category can be summed with --combine")
    parser.add_argument("-v", "--verbose", action="store_true")
    parser.add_argument("--combine", nargs="+", metavar="PART.json", default=None,
                        help="write the sum of sweeps run in parts (disjoint --only sets, run side by side) to --out")
    args = parser.parse_args()
    if args.combine:
        report = combine([json.loads(Path(p).read_text()) for p in args.combine])
        Path(args.out).write_text(json.dumps(report, indent=1) + "\n")
        print(json.dumps({k: v for k, v in report.items() if k != "failures"}, indent=1))
        return 0
    if args.baseline:
        from bench._baseline import extract
        path = args.baseline if os.path.isdir(args.baseline) else extract(args.baseline)[0]   # (a tree extracted before)
        env = dict(os.environ, PYTHONPATH=path, NUMBA_CACHE_DIR=os.path.join(path, ".numba_cache"))
        cmd = [sys.executable, __file__, "--only", args.only, "--sample", str(args.sample), "--out", args.out]
        cmd += ["--list"] * args.list + ["-v"] * args.verbose
        return subprocess.call(cmd, env=env, cwd=path)
    only = {c.strip() for c in args.only.split(",") if c.strip()}
    report = sweep(only, args.sample, verbose=args.verbose, match=args.match)
    import creep_online
    report["code"] = str(Path(creep_online.__file__).resolve().parents[1])
    report["command"] = " ".join(["python -m bench.bench_reliability", *map(shlex.quote, sys.argv[1:])])
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=1) + "\n")
    shown = report if args.list else {k: v for k, v in report.items() if k != "failures"}
    print(json.dumps(shown, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
