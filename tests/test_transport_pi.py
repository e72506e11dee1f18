"""PI controllers: pipython itself, unchanged, against hil_sim's emulated controller over a real pty or TCP.

The emulator (``python -m hil_sim.pi_controller``) runs in its own process;
the tests rebuild its plant from the same arguments (``plant_config``) as the
independent reference for every value read.
"""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

pytest.importorskip("pipython", reason="pipython is an optional extra (creep_online[pi])")

from pipython import GCSDevice, GCSError  # noqa: E402
from pipython.pidevice.interfaces.piserial import PISerial  # noqa: E402
from pipython.pidevice.interfaces.pisocket import PISocket  # noqa: E402

from creep_online.cli import main  # noqa: E402
from creep_online.io import open_source  # noqa: E402
from hil_sim.harness import PlantProcess  # noqa: E402
from creep_online.io.pi_links import FORMS, Connection, parse_connection  # noqa: E402
from hil_sim.pi_controller import build_parser, plant_config, plant_configs  # noqa: E402
from hil_sim.plant import generate  # noqa: E402


def random_params(seed: int) -> str:
    """A plant over the issue's ranges (alpha 0.02-0.4, fn 100-800 Hz, zeta 0.03-0.3, b 0.5-5)."""
    rng = np.random.default_rng(seed)
    return (f"alpha={rng.uniform(0.02, 0.4):.4f},fn={rng.uniform(100, 800):.1f},"
            f"zeta={rng.uniform(0.03, 0.3):.3f},b={rng.uniform(0.5, 5):.3f}")


def _count(events: list[dict], name: str) -> int:
    return sum(e.get("event") == name for e in list(events))


def controller(args: list[str]):
    """(the emulator process, its plant record rebuilt here from the same arguments)."""
    plant = generate(plant_config(build_parser().parse_args(args)))
    return PlantProcess(args, module="hil_sim.pi_controller"), plant


def test_pipython_configures_the_recorder_and_reads_the_plant():
    seed, rtr = 2, 3
    args = ["--rate", "5000", "--duration", "1", "--params", random_params(seed), "--schedule", "staircase",
            "--period", "0.2", "--seed", str(seed), "--fast", "--table-points", "1200"]
    proc, plant = controller(args)
    with proc, GCSDevice(gateway=PISerial(proc.port, 115200)) as dev:
        assert type(dev.gcsdevice).__name__ == "GCS2Device"      # pipython chose GCS 2 from CSV?
        assert "E-727" in dev.qIDN() and dev.qSAI() == ["1"]
        dev.RTR(rtr)
        assert dev.qRTR() == rtr
        dev.DRC([1, 2], ["1", "1"], [7, 2])
        assert dev.qDRC([1, 2]) == {1: ["1", 7], 2: ["1", 2]}
        dev.DRT(0, 4, 0)
        assert dev.qDRT([1]) == {1: [4, "0"]}
        n = min(1200, (plant.u.size - 1) // rtr + 1)
        assert dev.qDRL([1, 2]) == {1: n, 2: n}
        u, y = [], []
        for offset in range(1, n + 1, 500):                    # in chunks, as the pi: source reads
            count = min(500, n - offset + 1)
            header = dev.qDRR([1, 2], offset, count)
            while dev.bufstate is not True:
                time.sleep(0.001)
            u += dev.bufdata[0]
            y += dev.bufdata[1]
        assert header["SAMPLE_TIME"] == pytest.approx(rtr / 5000.0)
        assert header["NAME0"] == "Voltage of output channel 1" and header["NAME1"] == "Current Position of axis 1"
        cycles = np.arange(n) * rtr
        np.testing.assert_allclose(u, plant.u[cycles], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(y, plant.y[cycles], rtol=1e-9, atol=1e-12)
        with pytest.raises(GCSError) as refused:
            dev.DRC(1, "1", 99)                                # no such record option
        assert refused.value.val == 17
        with pytest.raises(GCSError) as unknown:
            dev.send("XYZ 1")
        assert unknown.value.val == 2
        assert dev.qERR() == 0


def test_pi_source_streams_recordings_and_counts_the_hand_over_gaps():
    rate, rtr, points = 10_000.0, 2, 3000
    args = ["--rate", f"{rate:g}", "--duration", "3", "--params", random_params(5), "--t-start", "0.05",
            "--table-points", str(points)]
    proc, plant = controller(args)
    with proc:
        src = open_source(f"pi:{proc.port}?rtr={rtr}", on_event=None)
        got = []
        deadline = time.monotonic() + 60
        while src.recordings < 4 and time.monotonic() < deadline:
            got += src.read(0.05)
        src.close()
        # the source counts a recording when it sends the trigger; the emulator's "trigger" event comes back
        # through its stdout on the harness' reader thread, later on a loaded machine (CI once saw 3 of 4)
        deadline = time.monotonic() + 10
        while _count(proc.events, "trigger") < src.recordings and time.monotonic() < deadline:
            time.sleep(0.01)
        triggers = [e["cycle"] for e in proc.events if e.get("event") == "trigger"]
    assert src.rate == pytest.approx(rate / rtr) and "E-727" in src.idn
    assert len(triggers) >= 4 and len(got) >= 3 * points
    seq = np.array([s.seq for s in got])
    assert np.all(np.diff(seq) > 0)
    for k in range(3):                          # three whole recordings
        chunk = got[k * points:(k + 1) * points]
        cycles = triggers[k] + np.arange(points) * rtr
        np.testing.assert_allclose([s.y for s in chunk], plant.y[cycles], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose([s.u for s in chunk], plant.u[cycles], rtol=1e-9, atol=1e-12)
        # numbering from the host clock (relative to the first DRT): within half of this and of the
        # first DRT round trip (+1 ms) of the controller's own trigger time
        bound = src.trigger_uncertainty_s[0] + src.trigger_uncertainty_s[k] + 1e-3
        assert abs(chunk[0].seq - triggers[k] / rtr) <= bound * rate / rtr
        assert chunk[0].t == pytest.approx(chunk[0].seq * rtr / rate)
    for k in range(2):                          # the points lost while re-triggering: estimated vs true
        estimated = got[(k + 1) * points].seq - got[k * points].seq - points
        true = (triggers[k + 1] - triggers[k]) // rtr - points
        bound = src.trigger_uncertainty_s[k] + src.trigger_uncertainty_s[k + 1] + 1e-3
        assert abs(estimated - true) <= bound * rate / rtr
    stats = src.stats.as_dict()
    assert stats["missing"] == seq[-1] - seq[0] + 1 - len(got) and stats["gaps"] <= len(triggers) - 1
    assert stats["duplicates"] == stats["late"] == stats["disconnects"] == 0


def test_a_slow_recording_is_not_taken_for_a_finished_one():
    """10 points/s (RTR 100 at 1 kHz): polls faster than the points come must not re-trigger."""
    proc, plant = controller(["--rate", "1000", "--duration", "3", "--params", random_params(3)])
    with proc:
        src = open_source(f"pi:{proc.port}?rtr=100", on_event=None)
        got = []
        deadline = time.monotonic() + 30
        while len(got) < 8 and time.monotonic() < deadline:
            got += src.read(0.05)
        src.close()
    assert src.recordings == 1 and src.stats.missing == 0 and src.rate == pytest.approx(10.0)
    np.testing.assert_allclose([s.y for s in got], plant.y[np.arange(len(got)) * 100], rtol=1e-9, atol=1e-12)


@pytest.fixture(scope="module")
def live_controller():
    """One real-time controller for the CLI tests (a refused command changes nothing in it)."""
    args = ["--rate", "10000", "--duration", "8", "--params", random_params(7), "--schedule", "square",
            "--period", "1", "--t-start", "0.05", "--noise", "1e-4"]
    proc, _ = controller(args)
    with proc:
        yield proc


def test_gcs_error_is_one_line(live_controller, capsys):
    port = live_controller.port
    code = main(["stream", "--source", f"pi:{port}?u_record=99", "--max-samples", "100"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err == (f"creep-online stream: error: pi:{port}: the controller refused 'DRC 1 1 99 2 1 2': "
                   "GCS error 17 (Parameter out of range)")


def test_stream_cli_identifies_the_controllers_plant(live_controller, capsys):
    code = main(["stream", "--source", f"pi:{live_controller.port}", "--max-samples", "30000", "--json"])
    truth = live_controller.ready["model"]
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["samples"] >= 30000
    assert out["source_stats"]["missing"] == 0 and out["source_stats"]["frames"] > 10
    assert out["alpha"] == pytest.approx(truth["alpha"], abs=0.01)
    assert out["b"] == pytest.approx(truth["b"], rel=0.02)
    assert out["a2"] == pytest.approx(truth["a2"], rel=0.05)


@pytest.mark.parametrize("link", ["serial", "tcp"])
def test_a_controller_that_goes_away_is_a_lost_link_and_exit_4(capsys, link):
    """The controller's end of the link goes away mid-stream (a pulled cable on the pty; a closed socket on TCP)."""
    tcp = ["--tcp"] if link == "tcp" else []
    proc, _ = controller([*tcp, "--rate", "5000", "--duration", "5", "--disconnect-after", "0.8"])
    spec = f"pi:tcp:{proc.port}" if link == "tcp" else f"pi:{proc.port}"
    with proc:
        code = main(["stream", "--source", f"{spec}?reconnect=0&timeout=0.5", "--duration", "20", "--json"])
        proc.wait_event("disconnect", timeout=5)
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    lines = captured.err.strip().splitlines()
    assert code == 4 and out["samples"] > 1000 and out["source_stats"]["disconnects"] == 1
    said = f"creep-online stream: link lost: {spec}: controller disappeared ("
    assert lines[-1].startswith(said + ("no answer to " if link == "serial" else ""))
    assert lines[-1].endswith("reconnect is off") and "Traceback" not in captured.err


def test_reconnect_after_a_pulled_cable_numbers_on_from_the_clock(tmp_path):
    rate = 5000.0
    link = str(tmp_path / "pi_port")
    args = ["--rate", f"{rate:g}", "--duration", "4", "--params", random_params(9), "--link", link,
            "--disconnect-after", "0.6", "--back-after", "0.4"]
    proc, plant = controller(args)
    events: list[str] = []
    with proc:
        src = open_source(f"pi:{link}?timeout=0.3", on_event=events.append)
        got = []
        deadline = time.monotonic() + 60
        while src.stats.reconnects < 1 or len(got) < 5000:
            got += src.read(0.05)
            assert time.monotonic() < deadline, src.stats.summary()
        src.close()
        triggers = [e["cycle"] for e in proc.events if e.get("event") == "trigger"]
    assert src.stats.disconnects == 1 and len(triggers) == 2
    assert any("controller disappeared (no answer to" in e for e in events)
    seq = np.array([s.seq for s in got])
    first_after = int(np.flatnonzero(np.diff(seq) > 1)[0]) + 1     # the outage is one gap
    before, after = got[:first_after], got[first_after:]
    np.testing.assert_allclose([s.y for s in before], plant.y[np.arange(len(before))], rtol=1e-9, atol=1e-12)
    cycles = triggers[1] + np.arange(len(after))
    np.testing.assert_allclose([s.y for s in after], plant.y[cycles], rtol=1e-9, atol=1e-12)
    bound = src.trigger_uncertainty_s[0] + src.trigger_uncertainty_s[1] + 1e-3
    assert abs(after[0].seq - triggers[1]) <= bound * rate
    assert src.stats.missing == after[0].seq - before[-1].seq - 1 > 0.4 * rate


# ------------------------------------------------------------------ the connection forms
@pytest.mark.parametrize("target, expected", [
    ("tcp:192.168.0.10", Connection("tcp", "192.168.0.10", 50000)),
    ("tcp:pi-e727.lab:50001", Connection("tcp", "pi-e727.lab", 50001)),
    ("usb:0123456789", Connection("usb", "0123456789")),
    ("rs232:/dev/ttyUSB0", Connection("rs232", "/dev/ttyUSB0")),
    ("RS232:COM3", Connection("rs232", "COM3")),
    ("/dev/ttyUSB0", Connection("rs232", "/dev/ttyUSB0")),
    ("COM3", Connection("rs232", "COM3")),
    ("/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0",
     Connection("rs232", "/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0")),
])
def test_connection_forms(target, expected):
    assert parse_connection(target) == expected


@pytest.mark.parametrize("spec", ["pi:192.168.0.10:50000", "pi:tcp://192.168.0.10:50000", "pi:192.168.0.10",
                                  "pi:usb:", "pi:tcp:", "pi:serial:/dev/ttyUSB0", "pi:tcp:host:port:1"])
def test_an_unknown_form_is_one_line_listing_the_forms(spec, capsys):
    code = main(["stream", "--source", spec, "--max-samples", "10"])
    err = capsys.readouterr().err
    assert code == 2 and err == f"creep-online stream: error: {spec}: not a PI connection; use {FORMS}\n"


def test_a_bad_tcp_port_and_options_that_do_not_apply_are_one_line(capsys):
    assert main(["stream", "--source", "pi:tcp:127.0.0.1:70000"]) == 2
    assert capsys.readouterr().err == ("creep-online stream: error: pi:tcp:127.0.0.1:70000: the TCP port must be "
                                       "a number 1..65535, got '70000'\n")
    assert main(["stream", "--source", "pi:tcp:127.0.0.1?baudrate=9600"]) == 2
    assert capsys.readouterr().err.endswith(": baudrate applies to RS-232 connections only\n")
    assert main(["stream", "--source", "pi:/dev/ttyUSB0?axes=1,1"]) == 2
    assert "option axes='1,1' is not valid" in capsys.readouterr().err


def test_usb_goes_to_pipythons_piusb_and_fails_in_one_line(capsys):
    """No PI USB device here: pipython's PIUSB (pyusb) finds none, or has no libusb backend; one line either way."""
    code = main(["stream", "--source", "pi:usb:0123456789", "--max-samples", "10"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err in ("creep-online stream: error: pi:usb:0123456789: cannot open (no USB backend: install libusb-1.0)\n",
                   "creep-online stream: error: pi:usb:0123456789: no PI USB device with this serial number "
                   "(found: none); a controller on a virtual COM port is pi:rs232:PORT\n")


def test_a_refused_tcp_connection_is_one_line(capsys):
    import socket
    with socket.socket() as probe:               # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    assert main(["stream", "--source", f"pi:tcp:127.0.0.1:{port}", "--max-samples", "10"]) == 2
    assert capsys.readouterr().err == (f"creep-online stream: error: pi:tcp:127.0.0.1:{port}: cannot open "
                                       "(Connection refused)\n")


# ------------------------------------------------------------------ TCP, names, several axes
# pipython's stock PISocket raises EBADF when GCSDevice closes it a second time on garbage collection
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_pipython_over_tcp_reads_the_plant():
    """pipython's own PISocket (ConnectTCPIP) against the emulator's TCP port."""
    args = ["--tcp", "--rate", "5000", "--duration", "1", "--params", random_params(4), "--fast",
            "--table-points", "900"]
    proc, plant = controller(args)
    host, port = proc.port.split(":")
    with proc, GCSDevice("E-727", gateway=PISocket(host, int(port))) as dev:
        assert type(dev.gcsdevice).__name__ == "GCS2Device" and "E-727" in dev.qIDN()
        dev.DRC([1, 2], ["1", "1"], [7, 2])
        dev.DRT(0, 4, 0)
        header = dev.qDRR([1, 2], 1, 900)
        while dev.bufstate is not True:
            time.sleep(0.001)
        assert header["SAMPLE_TIME"] == pytest.approx(1 / 5000.0)
        np.testing.assert_allclose(dev.bufdata[0], plant.u[:900], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(dev.bufdata[1], plant.y[:900], rtol=1e-9, atol=1e-12)


def test_rs232_spelling_baudrate_and_controller_name(capsys):
    proc, plant = controller(["--rate", "2000", "--duration", "3", "--params", random_params(6)])
    with proc:
        with open_source(f"pi:rs232:{proc.port}?baudrate=460800&controller=E-727", on_event=None) as src:
            got = []
            deadline = time.monotonic() + 30
            while len(got) < 200 and time.monotonic() < deadline:
                got += src.read(0.05)
        assert src.connection == Connection("rs232", proc.port) and src.baudrate == 460800
        np.testing.assert_allclose([s.y for s in got], plant.y[:len(got)], rtol=1e-9, atol=1e-12)
        assert main(["stream", "--source", f"pi:{proc.port}?baud=9600&controller=E-709", "--max-samples", "10"]) == 2
    assert capsys.readouterr().err == (f"creep-online stream: error: pi:{proc.port}: the controller answering is "
                                       "not an E-709 (*IDN?: Physik Instrumente (PI) GmbH & Co. KG, E-727 (hil_sim "
                                       "emulation), 0000000000, 01.000)\n")


def test_several_axes_over_tcp_one_estimate_each(capsys):
    """Two axes with different plants behind one controller: stream gives each axis its own estimate."""
    params = f"{random_params(11)};{random_params(12)}"
    args = ["--tcp", "--axes", "2", "--rate", "10000", "--duration", "6", "--params", params,
            "--schedule", "square", "--period", "1", "--t-start", "0.05", "--noise", "1e-4"]
    proc, _ = controller(args)
    plants = [generate(cfg) for cfg in plant_configs(build_parser().parse_args(args))]
    with proc:
        code = main(["stream", "--source", f"pi:tcp:{proc.port}?axes=1,2", "--max-samples", "30000", "--json"])
        truths = proc.ready["models"]
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and [a["axis"] for a in out["axes"]] == ["1", "2"]
    assert out["alpha"] == out["axes"][0]["alpha"] and out["source_stats"]["missing"] == 0
    assert plants[0].y[-1] != plants[1].y[-1]
    for axis, truth in zip(out["axes"], truths):
        assert axis["samples"] >= 30000
        assert axis["alpha"] == pytest.approx(truth["alpha"], abs=0.01)
        assert axis["b"] == pytest.approx(truth["b"], rel=0.02)
        assert axis["a2"] == pytest.approx(truth["a2"], rel=0.05)


def test_the_emulator_exits_after_its_record():
    proc, _ = controller(["--tcp", "--rate", "2000", "--duration", "0.5", "--linger", "0.5"])
    with proc:
        with open_source(f"pi:tcp:{proc.port}", on_event=None) as src:
            src.read(0.05)
        started = time.monotonic()
        end = proc.wait_event("end", timeout=30)
        assert proc.proc.wait(10) == 0 and time.monotonic() - started < 10
    assert end["recorded"] == 1000


def test_a_tcp_controller_that_comes_back_is_reconnected():
    rate = 5000.0
    args = ["--tcp", "--rate", f"{rate:g}", "--duration", "4", "--params", random_params(10),
            "--disconnect-after", "0.6", "--back-after", "0.4"]
    proc, plant = controller(args)
    with proc:
        src = open_source(f"pi:tcp:{proc.port}?timeout=0.3", on_event=None)
        got = []
        deadline = time.monotonic() + 60
        while src.stats.reconnects < 1 or len(got) < 5000:
            got += src.read(0.05)
            assert time.monotonic() < deadline, src.stats.summary()
        src.close()
        triggers = [e["cycle"] for e in proc.events if e.get("event") == "trigger"]
    assert src.stats.disconnects == 1 and len(triggers) == 2
    seq = np.array([s.seq for s in got])
    first_after = int(np.flatnonzero(np.diff(seq) > 1)[0]) + 1
    after = got[first_after:]
    np.testing.assert_allclose([s.y for s in after], plant.y[triggers[1] + np.arange(len(after))], rtol=1e-9,
                               atol=1e-12)
    assert src.stats.missing == after[0].seq - got[first_after - 1].seq - 1 > 0.4 * rate
