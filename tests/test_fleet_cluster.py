"""``creep-online batch --scheduler`` on a cluster the user started: real ``dask scheduler`` and ``dask worker``
processes, each in a directory of its own (loopback only), and the batch run from a third one with a relative
folder. Then the tables' metadata and the summary page's plots.
"""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dask.distributed", reason="the fleet extra (dask) is not installed")
pq = pytest.importorskip("pyarrow.parquet", reason="the fleet extra (pyarrow) is not installed")

from creep_online import __version__  # noqa: E402
from creep_online.fleet import COLUMNS  # noqa: E402
from creep_online.fleet.row import UNITS  # noqa: E402
from creep_online.fleet.summary import Z_THRESHOLD, flag_outliers  # noqa: E402
from creep_online.identification import identify  # noqa: E402
from creep_online.reports import fleet_report  # noqa: E402
from hil_sim.fleet import make_fleet, write_fleet  # noqa: E402

N_UNITS = 6
REVERSED = 4          # the unit wired backwards
DASK = str(Path(sys.executable).with_name("dask"))


def _start(args: list[str], cwd: Path, log: Path) -> subprocess.Popen:
    with log.open("w") as fh:
        return subprocess.Popen([DASK, *args], cwd=cwd, stdout=fh, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)


@pytest.fixture(scope="module")
def external_cluster(tmp_path_factory):
    """A scheduler and one single-threaded worker, started as a user would, each in its own directory."""
    root = tmp_path_factory.mktemp("cluster")
    for name in ("scheduler_home", "worker_home"):
        (root / name).mkdir()
    info = root / "scheduler.json"
    procs = [_start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                     "--scheduler-file", str(info)], root / "scheduler_home", root / "scheduler.log")]
    try:
        deadline = time.monotonic() + 60
        while not (info.exists() and info.stat().st_size):
            assert procs[0].poll() is None and time.monotonic() < deadline, (root / "scheduler.log").read_text()
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(_start(["worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
                             "--host", "127.0.0.1", "--local-directory", str(root / "worker_home" / "dask")],
                            root / "worker_home", root / "worker.log"))
        from dask.distributed import Client
        with Client(address, timeout=30) as client:
            client.wait_for_workers(1, timeout=90)
        yield address
    finally:
        for proc in reversed(procs):
            _stop(proc)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """Where the user runs the batch: a folder ``data`` of records (one unit wired backwards)."""
    home = tmp_path_factory.mktemp("site")
    units = make_fleet(N_UNITS, seed=3, faults={REVERSED: "reversed"})
    write_fleet(units, home / "data")
    return home, units


def _batch(home: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "creep_online", "batch", *args], cwd=home, capture_output=True,
                          text=True, timeout=300)


def test_a_relative_folder_on_a_cluster_started_elsewhere(external_cluster, site):
    home, units = site
    out = _batch(home, "data", "--scheduler", external_cluster, "--out", "fleet.parquet", "--json")
    assert out.returncode == 0, out.stderr + out.stdout[-2000:]
    summary = json.loads(out.stdout)
    assert summary["identified"] == N_UNITS and summary["failed"] == 0
    assert summary["scheduler"] == external_cluster
    table = pq.read_table(home / "fleet.parquet")
    rows = {r["id"]: r for r in table.to_pylist()}
    for unit in units:
        direct = identify(unit.t, unit.u, unit.y)
        for name in ("alpha", "a1", "a2", "b"):
            assert rows[unit.id][name] == pytest.approx(getattr(direct.model, name), rel=1e-7)
        assert rows[unit.id]["source"] == f"data/{unit.id}.csv"     # as the user named it
    assert rows[units[REVERSED].id]["b"] < 0 and "b" in rows[units[REVERSED].id]["outlier"].split(",")

    meta = table.schema.metadata
    assert meta[b"creep_online.tool"] == b"creep-online"
    assert meta[b"creep_online.version"].decode() == __version__
    options = json.loads(meta[b"creep_online.options"])
    assert options == {"records": "data", "diagnose": False, "retune": True, "polish": True,
                       "scheduler": external_cluster, "workers": None, "send_records": False}
    assert json.loads(meta[b"creep_online.units"]) == {k: UNITS[k] for k in COLUMNS}
    assert table.schema.field("fn_hz").metadata == {b"unit": b"Hz"}
    assert table.schema.field("id").metadata is None

    page = (home / "fleet.html").read_text()
    assert page.count("<svg") == 4 and "b (signed)" in page and units[REVERSED].id in page


def test_a_csv_table_gets_a_metadata_sidecar_its_readers_never_see(external_cluster, site):
    home, units = site
    out = _batch(home, "data", "--scheduler", external_cluster, "--out", "fleet.csv", "--no-polish")
    assert out.returncode == 0, out.stderr
    with open(home / "fleet.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))        # a plain CSV: the header first, one row per record
    assert tuple(rows[0]) == COLUMNS and [r["id"] for r in rows] == [u.id for u in units]
    side = json.loads((home / "fleet.csv.meta.json").read_text())
    assert side["table"] == "fleet.csv" and side["tool"] == "creep-online" and side["version"] == __version__
    assert side["options"]["polish"] is False and side["options"]["records"] == "data"
    assert side["units"]["b"] == UNITS["b"] and side["units"]["fn_hz"] == "Hz"
    again = _batch(home, "data", "--scheduler", external_cluster, "--out", "data/fleet.csv")
    assert again.returncode == 0, again.stderr     # a table and its sidecar inside the folder are no records
    assert (home / "data" / "fleet.csv.meta.json").exists()
    third = _batch(home, "data", "--scheduler", external_cluster, "--out", "data/fleet.csv", "--json")
    assert json.loads(third.stdout)["records"] == N_UNITS


def test_records_sent_as_data_need_no_file_on_the_workers(external_cluster, site, tmp_path):
    """``--send-records``: the same table; and jobs carrying their samples are identified with the files gone."""
    from dask.distributed import Client
    from creep_online.fleet.runner import run_on_dask
    from creep_online.io.fleet_records import find_records
    home, units = site
    out = _batch(home, "data", "--scheduler", external_cluster, "--out", "sent.parquet", "--send-records")
    assert out.returncode == 0, out.stderr
    by_path = {r["id"]: r for r in pq.read_table(home / "fleet.parquet").to_pylist()}
    table = pq.read_table(home / "sent.parquet")
    assert json.loads(table.schema.metadata[b"creep_online.options"])["send_records"] is True
    for row in table.to_pylist():
        for name in ("alpha", "a1", "a2", "b", "fit_percent", "noise_std"):
            assert row[name] == by_path[row["id"]][name], (row["id"], name)

    folder = tmp_path / "gone"
    write_fleet(units[:3], folder)
    late = folder / f"{units[2].id}.csv"
    late.write_text(late.read_text().rstrip("\n"))                     # no end-of-line: a warning
    (folder / "bad.csv").write_text("t,u,y\n0,0,0\n0.001,1,nan\n")
    jobs = [job.carrying_samples() for job in find_records(str(folder))]
    for path in folder.iterdir():
        path.unlink()
    folder.rmdir()
    assert all(job.path is None for job in jobs)
    with Client(external_cluster, timeout=30) as client:
        rows = {r["id"]: r for r in run_on_dask(jobs, client)}
    assert "line 3, column y" in rows["bad"]["error"]
    assert "has no end-of-line" in rows[units[2].id]["warnings"]
    for unit in units[:3]:
        assert rows[unit.id]["error"] == "" and rows[unit.id]["alpha"] == by_path[unit.id]["alpha"]


# ------------------------------------------------------------------ the summary page's plots (no cluster)
def _fleet_rows(n: int = 40, seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    rows = [{"id": f"u{k:02d}", "alpha": 0.12 * np.exp(rng.normal(0, 0.05)), "fn_hz": 420 * np.exp(rng.normal(0, 0.04)),
             "zeta": 0.08 * np.exp(rng.normal(0, 0.1)), "b": 2.5 * np.exp(rng.normal(0, 0.05)), "error": "",
             "warnings": ""} for k in range(n)]
    return rows


def _drawn(rows: list[dict], name: str):
    plt = fleet_report.pyplot()
    fig, ax = plt.subplots()
    values = np.array([r[name] for r in rows])
    fleet_report._draw(ax, name, values, [(r["id"], r[name]) for r in rows if name in r["outlier"].split(",")])
    fig.canvas.draw()
    return fig, ax


def _band(ax) -> tuple[float, float]:
    handles, labels = ax.get_legend_handles_labels()
    patch = handles[[k for k, text in enumerate(labels) if text.startswith("not an outlier")][0]]
    xs = patch.get_x(), patch.get_x() + patch.get_width()
    return min(xs), max(xs)


@pytest.mark.parametrize("seed", range(5))
def test_a_reversed_gain_is_drawn_on_its_own_side_outside_the_band(seed):
    rows = _fleet_rows(seed=seed)
    rows[3]["b"] *= -1.0
    flag_outliers(rows)
    assert rows[3]["outlier"] == "b"
    fig, ax = _drawn(rows, "b")
    lo, hi = _band(ax)
    assert 0 < lo < 2.5 < hi                                  # the majority's band, on the positive side
    assert not lo <= rows[3]["b"] <= hi
    left, right = ax.get_xlim()
    assert left < rows[3]["b"] < 0 < lo < hi <= right
    red = [line.get_xdata()[0] for line in ax.get_lines() if line.get_color() == "red"]
    assert red == [rows[3]["b"]]
    ticks = [t.get_text() for t in ax.get_xticklabels() if t.get_text()]
    assert any(t.startswith("-") for t in ticks) and sum(not t.startswith("-") for t in ticks) >= 3
    fleet_report.pyplot().close(fig)


@pytest.mark.parametrize("name", ["alpha", "fn_hz", "zeta", "b"])
def test_each_plot_has_value_and_count_axes_and_the_rule_s_band(name):
    rows = _fleet_rows(seed=11)
    rows[7]["fn_hz"] = 250.0
    flag_outliers(rows)
    fig, ax = _drawn(rows, name)
    counts = [int(t.get_text()) for t in ax.texts if t.get_text().isdigit()]
    assert sum(counts) == len(rows)                          # every record counted on a bar
    assert ax.get_ylabel() == "records" and ax.get_xlabel() == fleet_report.LABELS[name]
    yticks = [float(t) for t in ax.get_yticks()]
    assert all(float(t).is_integer() for t in yticks) and len(yticks) >= 3
    xlabels = [t.get_text() for t in ax.get_xticklabels() if t.get_text()]
    assert len(xlabels) >= 3
    x = np.log10([r[name] for r in rows])
    med = np.median(x)
    mad = np.median(np.abs(x - med))
    lo, hi = _band(ax)
    assert lo == pytest.approx(10 ** (med - Z_THRESHOLD * mad / 0.6745), rel=1e-9)
    assert hi == pytest.approx(10 ** (med + Z_THRESHOLD * mad / 0.6745), rel=1e-9)
    fleet_report.pyplot().close(fig)
