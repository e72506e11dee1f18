"""The application's own bus: EstimatorListener on a can.Notifier (thread and asyncio), CanSource(bus=...).

Real python-can: the simulated plant sends on the in-process ``virtual`` bus, the readers are python-can
buses on the same channel (each receives every frame).
"""
from __future__ import annotations

import asyncio
import time

import pytest

can = pytest.importorskip("can", reason="python-can is an optional extra (creep_online[can])")

from creep_online import DataError  # noqa: E402
from creep_online.errors import TransportError  # noqa: E402
from creep_online.io.can_listener import EstimatorListener  # noqa: E402
from creep_online.io.can_source import CanSource  # noqa: E402
from creep_online.online import OnlineEstimator  # noqa: E402
from hil_sim import PlantConfig, generate, parse_params, run_virtual_plant  # noqa: E402

RATE = 10_000.0
FAULTS = "drop=2,dup=2,reorder=2"


class Recorder:
    """An estimator that keeps what it is given: update(u, y) and gap(n), in order."""

    def __init__(self) -> None:
        self.dt = 1.0 / RATE
        self.calls: list[tuple] = []

    def update(self, u: float, y: float) -> None:
        self.calls.append(("u", u, y))

    def gap(self, n: int) -> None:
        self.calls.append(("gap", n))


def _bus(channel: str) -> can.BusABC:
    return can.Bus(interface="virtual", channel=channel, receive_own_messages=False)


def _plant(channel: str, duration: float, faults: str = "", frame: str = "block"):
    rec = generate(PlantConfig(parse_params(""), rate=RATE, duration=duration, t_start=0.05, seed=1))
    th, runner = run_virtual_plant(rec, RATE, channel, can_frame=frame, realtime=False, faults=faults, seed=5)
    return rec, th, runner


def _wait(condition, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail("the listener did not receive the whole record in time")
        time.sleep(0.02)


def _wait_until_quiet(listener: EstimatorListener, quiet_s: float = 1.0) -> None:
    """The plant has sent everything: wait until the notifier has taken the last frames queued on the bus (its
    count of frames stays put for ``quiet_s``; a loaded machine delays its thread)."""
    seen = -1
    while (frames := listener.stats.as_dict()["frames"]) != seen:
        seen = frames
        time.sleep(quiet_s)


def _drain(src: CanSource, last_seq: int) -> list:
    out: list = []
    deadline = time.monotonic() + 120
    while not out or out[-1].seq < last_seq:
        assert time.monotonic() < deadline, src.stats.summary()
        out += src.read(0.05)
    return out


@pytest.mark.parametrize("frame", ["block", "pair"])
def test_listener_feeds_what_can_source_reads_from_the_same_frames(frame):
    """The listener and CanSource on one channel: the same samples, the same lost ones told as gaps."""
    ch = f"t_listener_same_{frame}"
    bus = _bus(ch)
    recorder = Recorder()
    listener = EstimatorListener(recorder, window=32)
    source = CanSource(f"virtual", ch, rate=RATE, on_event=None)
    rec, th, runner = _plant(ch, 0.3, FAULTS, frame)
    notifier = can.Notifier(bus, [listener])
    th.start()
    try:
        th.join(60)
        read = _drain(source, runner.n_samples - 1)
        # every frame the source read has reached the listener too (under load its notifier thread lags)
        _wait(lambda: listener.stats.as_dict()["frames"] >= source.stats.as_dict()["frames"])
    finally:
        notifier.stop()
        bus.shutdown()
        source.close()
    fed = [(c[1], c[2]) for c in recorder.calls if c[0] == "u"]
    assert fed == [(s.u, s.y) for s in read]
    assert listener.fed == len(read)
    lost = sum(c[1] for c in recorder.calls if c[0] == "gap")
    assert lost == listener.lost == source.stats.missing > 0
    assert listener.fed + listener.lost == runner.n_samples
    mine, theirs = listener.stats.as_dict(), source.stats.as_dict()
    for key in ("samples", "frames", "missing", "gaps", "duplicates", "reordered", "malformed", "no_input"):
        assert mine[key] == theirs[key], key


def test_listener_on_a_notifier_thread_identifies_the_plant():
    ch = "t_listener_thread"
    bus = _bus(ch)
    est = OnlineEstimator(1.0 / RATE)
    listener = EstimatorListener(est)
    rec, th, runner = _plant(ch, 1.5, FAULTS)
    with can.Notifier(bus, [listener]):
        th.start()
        th.join(60)
        _wait(lambda: listener.fed + listener.lost >= runner.n_samples - 32)
        _wait_until_quiet(listener)
        live = listener.estimate             # read from this thread while the notifier's may feed
    bus.shutdown()
    assert listener.stopped and listener.fed + listener.lost == runner.n_samples
    s = listener.stats.as_dict()
    assert s["missing"] == 14 and s["gaps"] == 2 and s["duplicates"] == 14 and s["reordered"] == 14
    assert est.gaps == 14 and est.samples == runner.n_samples
    truth = parse_params("")
    e = listener.estimate
    assert live.samples <= e.samples and e.phase == "tracking"
    assert abs(e.alpha / truth.alpha - 1) < 0.01 and abs(e.b / truth.b - 1) < 0.01
    assert abs(e.fn_hz / truth.fn - 1) < 0.02


def test_listener_on_an_asyncio_notifier():
    ch = "t_listener_asyncio"
    recorder = Recorder()

    async def main() -> EstimatorListener:
        bus = _bus(ch)
        listener = EstimatorListener(recorder)
        notifier = can.Notifier(bus, [listener], loop=asyncio.get_running_loop())
        rec, th, runner = _plant(ch, 0.5)
        th.start()
        deadline = time.monotonic() + 60
        while listener.fed < runner.n_samples - 32 and time.monotonic() < deadline:
            await asyncio.sleep(0.02)
        notifier.stop()
        bus.shutdown()
        th.join(10)
        listener.n_samples = runner.n_samples
        return listener

    listener = asyncio.run(main())
    assert listener.fed == listener.n_samples and listener.lost == 0
    seqs_ok = [c[0] for c in recorder.calls] == ["u"] * listener.n_samples
    assert seqs_ok


def test_stop_feeds_the_held_samples_and_ignores_later_messages():
    ch = "t_listener_stop"
    bus = _bus(ch)
    recorder = Recorder()
    listener = EstimatorListener(recorder, window=64)
    rec, th, runner = _plant(ch, 0.05)
    th.start()
    th.join(30)
    messages = []
    while (msg := bus.recv(0.2)) is not None:
        messages.append(msg)
    bus.shutdown()
    lost = messages.pop(-3)                 # a frame lost: the two after it wait in the reorder window
    for msg in messages:
        listener(msg)                       # a Listener is callable (python-can's convention)
    assert listener.fed == runner.n_samples - 3 * 7 and listener.lost == 0
    listener.stop()
    assert listener.fed == runner.n_samples - 7 and listener.lost == 7
    assert ("gap", 7) in recorder.calls
    listener(lost)
    assert listener.fed == runner.n_samples - 7


def test_bus_errors_are_counted_not_raised():
    listener = EstimatorListener(Recorder())
    listener.on_error(can.CanOperationError("bus off\nsecond line"))
    assert listener.errors == 1 and listener.last_error == "bus off"
    assert "bus error: bus off" in listener.stats.events[-1]


def test_listener_refuses_what_it_cannot_use_in_one_line():
    with pytest.raises(DataError, match="update"):
        EstimatorListener(object())

    class NoStep:
        def update(self, u, y):
            pass

    with pytest.raises(DataError, match="rate="):
        EstimatorListener(NoStep())
    assert EstimatorListener(NoStep(), rate=5000).messages.dt == pytest.approx(2e-4)


def test_can_source_reads_a_bus_the_application_owns_and_leaves_it_open():
    ch = "t_source_shared"
    bus = _bus(ch)
    source = CanSource(bus=bus, rate=RATE, on_event=None)
    assert source.name.startswith("can:") and not source.reconnect
    rec, th, runner = _plant(ch, 0.2)
    th.start()
    th.join(30)
    samples = _drain(source, runner.n_samples - 1)
    source.close()
    assert len(samples) == runner.n_samples and source.stats.missing == 0
    assert samples[10].u == pytest.approx(rec.u[10], abs=5.1e-7) and samples[10].t == pytest.approx(10 / RATE)
    assert not bus._is_shutdown              # the application's bus: still open
    bus.send(can.Message(arbitration_id=0x7FF, data=b"\x01", is_extended_id=False))
    bus.shutdown()


def test_can_source_needs_a_bus_or_an_interface():
    with pytest.raises(DataError, match="bus="):
        CanSource(rate=RATE)
    bus = _bus("t_source_both")
    try:
        with pytest.raises(DataError, match="either"):
            CanSource("virtual", "t_source_both", bus=bus, rate=RATE)
        with pytest.raises(Exception, match="rate"):
            CanSource(bus=bus)
    finally:
        bus.shutdown()


def test_a_lost_shared_bus_is_a_transport_error_in_one_line():
    bus = _bus("t_source_lost")
    source = CanSource(bus=bus, rate=RATE, on_event=None)
    bus.shutdown()                           # the application closed (or lost) its bus
    with pytest.raises(TransportError) as info:
        source.read(0.01)
    assert "application's bus disappeared" in str(info.value) and "\n" not in str(info.value)
