"""``creep-online batch``: a fleet identified on a real dask.distributed cluster.

The fleet is ``hil_sim.fleet`` (seeded random units of one actuator type, two of them faulty) written
as CSV files, plus a malformed file and a long-format file with a bad cell in one record. The cluster
of the in-process tests is a LocalCluster of two single-threaded *thread* workers (processes=False):
the real scheduler, the real task submission and result path, without spawning interpreters
(each costs several seconds of imports here); the process workers the CLI starts by default run in
the Ctrl-C test. ``--scheduler`` is tested against that in-test cluster's address from a separate
``creep-online`` process (a real TCP client).
"""
from __future__ import annotations

import csv
import json
import os
import pty
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dask.distributed", reason="the fleet extra (dask) is not installed")

from creep_online.errors import DataError  # noqa: E402
from creep_online.fleet import COLUMNS, summarize, write_table  # noqa: E402
from creep_online.fleet.job import run_record  # noqa: E402
from creep_online.fleet.runner import run_on_dask  # noqa: E402
from creep_online.fleet.summary import robust_z  # noqa: E402
from ptyio import read_until_exit  # noqa: E402
from creep_online.identification import identify  # noqa: E402
from creep_online.io import load_csv  # noqa: E402
from creep_online.io.fleet_records import find_records  # noqa: E402
from hil_sim.fleet import make_fleet, write_fleet, write_long  # noqa: E402

FAULTS = {2: "loose", 6: "depoled"}
N_UNITS = 10
PARAMS = ("alpha", "a1", "a2", "b")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """The fleet's folder (10 units + broken.csv), its long-format file (3 units + a bad one) and units."""
    root = tmp_path_factory.mktemp("fleet")
    units = make_fleet(N_UNITS, seed=7, faults=FAULTS)
    write_fleet(units, root / "records")
    (root / "records" / "broken.csv").write_text("t,u,y\n0,0,0\n0.001,1,nan\n")
    long = write_long(units[:3], root / "long.csv")
    with long.open("a") as fh:  # a fourth record whose third row has a non-number
        for k in range(40):
            fh.write(f"bad unit,{k * 1e-3},1,{'x' if k == 2 else 0.5}\n")
    return root, units


@pytest.fixture(scope="module")
def direct(fleet):
    """identify() called directly on every unit's record: {id: IdentificationResult}."""
    _, units = fleet
    return {u.id: identify(u.t, u.u, u.y) for u in units}


@pytest.fixture(scope="module")
def cluster():
    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address="127.0.0.1:0") as c:
        yield c


def _assert_matches(row, result):
    for name in PARAMS:
        assert row[name] == pytest.approx(getattr(result.model, name), rel=1e-7), (row["id"], name)
    assert row["fit_percent"] == pytest.approx(result.fit_percent, rel=1e-7)


# ------------------------------------------------------------------ finding records (no cluster)
def test_a_folder_a_glob_and_a_long_file_name_the_same_records(fleet):
    root, units = fleet
    folder = find_records(str(root / "records"))
    assert [j.id for j in folder] == ["broken"] + [u.id for u in units]
    assert [j.id for j in find_records(str(root / "records" / "unit*.csv"))] == [u.id for u in units]
    long = find_records(str(root / "long.csv"))
    assert [j.id for j in long] == [u.id for u in units[:3]] + ["bad unit"]
    for job, unit in zip(long[:3], units):
        rec = job.load()
        assert np.array_equal(rec.t, unit.t) and np.array_equal(rec.u, unit.u) and np.array_equal(rec.y, unit.y)
    assert long[3].error == f"{root / 'long.csv'}: line {1 + 3 * 5000 + 3} (id bad unit), column y: not a number: 'x'"
    single = find_records(str(root / "records" / "unit0001.csv"))
    assert [(j.id, j.path) for j in single] == [("unit0001", str(root / "records" / "unit0001.csv"))]


def test_nothing_to_read_is_one_line(tmp_path):
    with pytest.raises(DataError, match="no .csv files in this folder"):
        find_records(str(tmp_path))
    with pytest.raises(DataError, match="no files match this pattern"):
        find_records(str(tmp_path / "*.csv"))
    with pytest.raises(DataError, match="no such file or folder"):
        find_records(str(tmp_path / "missing.csv"))
    (tmp_path / "long.csv").write_text("id,t,u,y\nA,0,0,0\n,1,1,1\n")
    with pytest.raises(DataError, match=r"line 3: no id"):
        find_records(str(tmp_path / "long.csv"))
    (tmp_path / "long.csv").write_bytes(b"id,t,u,y\nA,0,0,\xff\n")
    with pytest.raises(DataError, match=r"long.csv: not a UTF-8 text file"):
        find_records(str(tmp_path / "long.csv"))
    (tmp_path / "long.csv").write_text("\n\nid,t,u,y\nA,0,0,0\nA,1,inf,0\nB,0,1,2\nB,1,2\n")
    bad_a, bad_b = find_records(str(tmp_path / "long.csv"))
    assert bad_a.error.endswith("line 5 (id A), column u: 'inf' (NaN/inf not allowed)")
    assert bad_b.error.endswith("line 7 (id B) has 3 field(s), expected at least 4")


def test_same_file_names_in_two_folders_get_distinct_ids(tmp_path):
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "x.csv").write_text("t,u,y\n")
    ids = [j.id for j in find_records(str(tmp_path / "*" / "x.csv"))]
    assert ids == [str(tmp_path / "a" / "x"), str(tmp_path / "b" / "x")]


def test_a_job_that_carries_its_samples_loads_as_its_file_did(tmp_path):
    """``batch --send-records``: the file is read where the batch runs, and the job carries its samples, its
    file's warnings and, for an unreadable file, the one-line error a worker would have given."""
    t = np.arange(200) * 1e-3
    lines = "\n".join(f"{a:.3f},{1.0 if a > 0 else 0.0},{0.5 * a:.6f}" for a in t)
    (tmp_path / "good.csv").write_text("t,u,y\n" + lines)                # no end-of-line: a warning
    (tmp_path / "bad.csv").write_text("t,u,y\n0,0,0\n0.001,1,nan\n")
    jobs = {job.id: job for job in find_records(str(tmp_path))}
    with pytest.warns(UserWarning, match="has no end-of-line"):
        direct = load_csv(str(tmp_path / "good.csv"))
    carried = {name: job.carrying_samples() for name, job in jobs.items()}
    for path in tmp_path.iterdir():                                           # the workers cannot see the files
        path.unlink()
    good, bad = carried["good"], carried["bad"]
    assert good.path is None and bad.path is None and bad.samples is None
    assert any("has no end-of-line" in note for note in good.notes)
    record = good.load()
    for name in ("t", "u", "y"):
        assert np.array_equal(getattr(record, name), getattr(direct, name))
    assert record.t.size == t.size and record.u[0] == 0.0 and record.u[1] == 1.0
    assert "line 3, column y" in bad.error
    with pytest.raises(DataError, match="line 3, column y"):
        bad.load()
    assert good.carrying_samples() is good                                    # carried once: nothing to read


def test_a_bad_record_is_a_row_with_the_identify_error(fleet):
    root, _ = fleet
    job = next(j for j in find_records(str(root / "records")) if j.id == "broken")
    row = run_record(job)
    with pytest.raises(DataError) as exc:
        load_csv(job.path)
    assert row["error"] == str(exc.value) and row["alpha"] is None and set(row) == set(COLUMNS)


def test_diagnose_gives_the_verdict_column(tmp_path):
    """A fleet unit is the plain creep model plus white noise: the diagnosis must find nothing missing."""
    from hil_sim.fleet import make_unit
    write_fleet([make_unit(0, seed=3, duration=0.2)], tmp_path)
    row = run_record(find_records(str(tmp_path))[0], diagnose_it=True)
    assert row["error"] == "" and row["verdict"] == "none"
    assert run_record(find_records(str(tmp_path))[0])["verdict"] == ""


def test_robust_z_is_the_modified_z_score():
    x = np.array([1.0, 2.0, 3.0, 4.0, 100.0])
    assert robust_z(x) == pytest.approx(0.6745 * (x - 3.0) / 1.0)
    same = np.array([5.0, 5.0, 5.0, 5.0, 7.0])   # MAD = 0: the mean absolute deviation stands in
    assert robust_z(same) == pytest.approx((same - 5.0) / (1.2533 * 0.4))


def test_outliers_need_five_records_and_a_flipped_gain_is_one():
    from creep_online.fleet.summary import flag_outliers
    rng = np.random.default_rng(5)

    def rows(n):
        return [{"id": f"u{k}", "error": "", "alpha": 0.02 * (1 + 0.01 * rng.normal()), "fn_hz": 350.0 + rng.normal(),
                 "zeta": 0.08 * (1 + 0.01 * rng.normal()), "b": 1.8 * (1 + 0.01 * rng.normal())} for k in range(n)]
    few = rows(4)
    few[0]["fn_hz"] = 100.0
    assert flag_outliers(few) == {} and all(r["outlier"] == "" for r in few)
    fleet = rows(30)
    fleet[3]["b"] *= -1.0        # same magnitude, wired backwards
    fleet[7]["fn_hz"] = 250.0
    flags = flag_outliers(fleet)
    assert set(flags) == {"u3", "u7"} and flags["u3"] == {"b": -np.inf} and set(flags["u7"]) == {"fn_hz"}
    assert fleet[3]["outlier"] == "b" and fleet[7]["outlier"] == "fn_hz"


# ------------------------------------------------------------------ the cluster
def test_fleet_on_a_local_cluster_matches_direct_identify(fleet, direct, cluster):
    from dask.distributed import Client
    root, units = fleet
    jobs = find_records(str(root / "records"))
    with Client(cluster) as client:
        rows = {r["id"]: r for r in run_on_dask(jobs, client)}
    assert set(rows) == {j.id for j in jobs}
    for unit in units:
        assert rows[unit.id]["error"] == "" and rows[unit.id]["samples"] == unit.t.size
        _assert_matches(rows[unit.id], direct[unit.id])
        sd = direct[unit.id].uncertainty
        assert all(rows[unit.id][f"{k}_sd"] == pytest.approx(sd[k], rel=1e-6) for k in PARAMS)
    assert "line 3, column y" in rows["broken"]["error"]
    summary = summarize(list(rows.values()))
    flagged = {o["id"]: set(o["z"]) for o in summary["outliers"]}
    assert "fn_hz" in flagged[units[2].id] and "b" in flagged[units[6].id]
    assert summary["failures"] == [{"id": "broken", "error": rows["broken"]["error"]}]
    assert summary["identified"] == N_UNITS


def _cli(*args, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "creep_online", "batch", *args], capture_output=True,
                          text=True, timeout=120, **kwargs)


def test_cli_on_an_existing_scheduler_writes_table_page_and_json(fleet, direct, cluster, tmp_path):
    root, units = fleet
    out = _cli(str(root / "records"), "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "t.csv"),
               "--json")
    assert out.returncode == 1, out.stderr           # one record failed: the batch ran, the exit code says so
    summary = json.loads(out.stdout)
    assert summary["records"] == summary["planned"] == N_UNITS + 1 and summary["failed"] == 1
    assert summary["scheduler"] == cluster.scheduler_address
    with open(tmp_path / "t.csv") as fh:
        table = list(csv.DictReader(fh))
    assert tuple(table[0]) == COLUMNS and [r["id"] for r in table] == ["broken"] + [u.id for u in units]
    for r in table[1:]:
        _assert_matches({k: float(r[k]) for k in (*PARAMS, "fit_percent")} | {"id": r["id"]}, direct[r["id"]])
    assert table[0]["alpha"] == "" and "line 3, column y" in table[0]["error"]
    assert "fn_hz" in table[3]["outlier"].split(",") and "b" in table[7]["outlier"].split(",")
    page = (tmp_path / "t.html").read_text()
    assert page.count("<svg") == 4 and "broken" in page and units[2].id in page
    assert summary["html"] == str(tmp_path / "t.html")


def test_long_format_on_the_cluster_to_parquet(fleet, direct, cluster, tmp_path):
    import pyarrow.parquet as pq
    from dask.distributed import Client
    root, units = fleet
    with Client(cluster) as client:
        rows = list(run_on_dask(find_records(str(root / "long.csv")), client))
    write_table(rows, tmp_path / "t.parquet")
    table = {r["id"]: r for r in pq.read_table(tmp_path / "t.parquet").to_pylist()}
    assert set(table) == {u.id for u in units[:3]} | {"bad unit"}
    for unit in units[:3]:
        _assert_matches(table[unit.id], direct[unit.id])
    assert table["bad unit"]["alpha"] is None and "column y: not a number: 'x'" in table["bad unit"]["error"]


def test_an_earlier_table_is_not_a_record_and_no_record_is_overwritten(fleet, cluster, tmp_path, capsys):
    from creep_online.cli import main
    root, units = fleet
    folder = tmp_path / "records"
    folder.mkdir()
    for unit in units[:2]:
        (folder / f"{unit.id}.csv").write_bytes((root / "records" / f"{unit.id}.csv").read_bytes())
    assert main(["batch", str(folder), "--out", str(folder / f"{units[0].id}.csv")]) == 2
    assert "refusing to overwrite the input file" in capsys.readouterr().err
    argv = ["batch", str(folder), "--scheduler", cluster.scheduler_address, "--out", str(folder / "fleet.csv"),
            "--json"]
    for _ in range(2):   # the second run finds the first run's table in the folder
        assert main(argv) == 0
        summary = json.loads(capsys.readouterr().out)
        assert [r["id"] for r in summary["rows"]] == [u.id for u in units[:2]]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_the_first_stop_signal_only_sets_the_batchs_flag_and_a_second_one_interrupts(signum):
    """``_signals.flagged``: the batch asks a flag between records rather than take a KeyboardInterrupt wherever
    its main thread is (inside Dask's client code it left the loop a half-done call); a second signal still
    interrupts, and the handler before is back afterwards. SIGTERM (a service manager's stop) alike."""
    from creep_online import _signals
    before = signal.getsignal(signum)
    if before is signal.SIG_IGN:
        pytest.skip(f"{signum} is ignored in this process (a background job)")
    with _signals.flagged() as pressed:
        assert pressed() is None
        os.kill(os.getpid(), signum)
        time.sleep(0.01)                       # (the handler runs between bytecodes of the main thread)
        assert pressed() == signum
        with pytest.raises(KeyboardInterrupt) as raised:
            os.kill(os.getpid(), signum)
            time.sleep(0.5)
        assert _signals.exit_code(raised.value) == 128 + signum
    assert signal.getsignal(signum) is before


def test_ctrl_c_stops_cleanly_and_keeps_the_rows_done(fleet, tmp_path):
    """A terminal: the progress bar shows; Ctrl-C (SIGINT to the process group) after the first records."""
    root, _ = fleet
    many = tmp_path / "many"
    many.mkdir()
    for k in range(40):
        os.symlink(root / "records" / f"unit{k % N_UNITS:04d}.csv", many / f"r{k:02d}.csv")
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "creep_online", "batch", str(many), "--workers", "1",
                             "--out", str(tmp_path / "t.csv")], stdin=subprocess.DEVNULL, stdout=slave,
                            stderr=slave, start_new_session=True,
                            # SIGINT back to its default: a suite started in the background by a shell
                            # has it ignored, and the child would inherit that (no KeyboardInterrupt)
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # (the slave stays open here until the end: when every holder has closed it, Linux may report EIO on the
    # master before the last lines written reach it, and the tail of the output was lost on a loaded machine)
    seen, done = b"", 0
    deadline = time.monotonic() + 90
    while done < 2 and time.monotonic() < deadline and proc.poll() is None:
        if select.select([master], [], [], 1.0)[0]:
            seen += os.read(master, 4096)
            counts = re.findall(rb"\] (\d+)/40 records", seen)
            done = int(counts[-1]) if counts else 0
    os.killpg(proc.pid, signal.SIGINT)
    shown = read_until_exit(master, proc, timeout=60)    # what the terminal shows after Ctrl-C
    os.close(slave)
    os.close(master)
    assert done >= 2, seen[-300:]
    assert proc.returncode == 130, shown
    text = shown.decode(errors="replace")
    assert "Traceback" not in text
    # the terminal's text without cursor moves: the status line's refresh thread and its erase may interleave
    # with the last lines on a loaded machine (a display race; the words are intact)
    plain = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).replace("\r", "\n")
    said = re.findall(r"creep-online batch: interrupted after (\d+) of 40 records; their rows are in \S*t\.csv",
                      plain)
    assert len(said) == 1, plain[-600:]
    kept = int(said[0])
    with open(tmp_path / "t.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert 2 <= kept < 40 and len(rows) == kept and all(r["alpha"] for r in rows)


# ------------------------------------------------------------------ without the extra, and --help
def _blocked(modules: tuple[str, ...], code: str) -> subprocess.CompletedProcess:
    block = "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in modules)
    return subprocess.run([sys.executable, "-c", block + code], capture_output=True, text=True, timeout=60)


def test_without_dask_one_line_names_the_extra_and_the_core_still_imports(fleet, tmp_path):
    root, _ = fleet
    out = _blocked(("dask", "distributed", "pyarrow"),
                   "import creep_online.fleet.job, creep_online.io.fleet_records, creep_online.reports.fleet_report\n"
                   "from creep_online.cli import main\n"
                   f"sys.exit(main(['batch', {str(root / 'records')!r}]))")
    assert out.returncode == 2 and out.stdout == ""
    assert out.stderr == "creep-online batch: error: batch identification needs Dask " \
                         "(pip install 'creep_online[fleet]')\n"
    out = _blocked(("pyarrow",), "from creep_online.cli import main\n"
                   f"sys.exit(main(['batch', {str(root / 'records')!r}, '--out', {str(tmp_path / 't.parquet')!r}]))")
    assert out.returncode == 2 and out.stderr == "creep-online batch: error: a .parquet table needs pyarrow " \
                                                 "(pip install 'creep_online[fleet]'), or write .csv\n"


def test_help_imports_neither_dask_nor_pyarrow():
    code = ("import sys, io, contextlib; from creep_online.cli import main\n"
            "for argv in (['--help'], ['batch', '--help']):\n"
            "    with contextlib.redirect_stdout(io.StringIO()):\n"
            "        try: main(argv)\n"
            "        except SystemExit: pass\n"
            "sys.__stdout__.write(str(sorted(m for m in ('dask', 'distributed', 'pyarrow', 'scipy', 'numba') "
                "if m in sys.modules)) + '\\n')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
