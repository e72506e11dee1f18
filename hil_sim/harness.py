"""Start ``python -m hil_sim`` as a child process and talk to it (tests, demo, bench).

The child's first stdout line is its port; every other line is a JSON event,
collected by a reader thread. The process is always stopped on exit (SIGTERM,
then SIGKILL after a grace period), so a failing test never leaves a plant
running.
"""
from __future__ import annotations

import json
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


class PlantProcess:
    """``with PlantProcess(["--rate", "10000", ...]) as plant: plant.port, plant.wait_event("end")``.

    ``module`` is the program to run (``hil_sim.pi_controller`` for the emulated PI controller).
    """

    def __init__(self, args: list[str], *, startup_timeout: float = 120.0, module: str = "hil_sim") -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = str(REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        self.proc = subprocess.Popen([sys.executable, "-m", module, *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=env)
        self.events: list[dict] = []
        self._q: queue.Queue = queue.Queue()
        self._stderr: list[str] = []
        self.port = self._first_line(startup_timeout)
        self._reader = threading.Thread(target=self._read_events, daemon=True)
        self._reader.start()
        threading.Thread(target=self._read_stderr, daemon=True).start()
        self.ready = self.wait_event("ready", timeout=startup_timeout)

    def _first_line(self, timeout: float) -> str:
        box: list[str] = []
        th = threading.Thread(target=lambda: box.append(self.proc.stdout.readline()), daemon=True)
        th.start()
        th.join(timeout)
        if not box or not box[0].strip():
            try:
                self.proc.wait(5.0)
            except subprocess.TimeoutExpired:
                pass
            err = self.proc.stderr.read()[-2000:] if self.proc.poll() is not None else ""
            self.stop()
            raise RuntimeError(f"hil_sim did not print its port (exit code {self.proc.returncode}); stderr: {err}")
        return box[0].strip()

    def _read_events(self) -> None:
        for line in self.proc.stdout:
            try:
                ev = json.loads(line)
            except ValueError:
                continue
            self.events.append(ev)
            self._q.put(ev)

    def _read_stderr(self) -> None:
        for line in self.proc.stderr:
            self._stderr.append(line)

    @property
    def stderr(self) -> str:
        return "".join(self._stderr)

    def wait_event(self, name: str, timeout: float = 60.0) -> dict:
        """The first event called ``name`` (already seen or arriving within timeout)."""
        for ev in self.events:
            if ev.get("event") == name:
                return ev
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"hil_sim: no '{name}' event within {timeout:g} s; stderr: {self.stderr[-1000:]}")
            try:
                ev = self._q.get(timeout=min(left, 0.5))
            except queue.Empty:
                if self.proc.poll() is not None and self._q.empty():
                    for ev in self.events:
                        if ev.get("event") == name:
                            return ev
                    raise RuntimeError(f"hil_sim exited ({self.proc.returncode}) before '{name}': {self.stderr[-1000:]}")
                continue
            if ev.get("event") == name:
                return ev

    def stop(self, grace: float = 10.0) -> int | None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(grace)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(grace)
        return self.proc.returncode

    def __enter__(self) -> "PlantProcess":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
