"""The actuator command as a known schedule, zero-order held at a sensor's sampling instants.

A sensor that streams only the position (a capaNCDT controller) leaves the
input u to be supplied separately. On an identification bench the excitation
is a signal the experimenter wrote beforehand and a controller or function
generator plays, starting with the acquisition: a schedule file ``t,u`` (one
row per change of the command, times in seconds from the start, increasing).
Between rows the command holds its value, as the DAC that plays it does, so
the input at a sensor instant t is the last row with time <= t (the first
row's value before it). docs/transports.md, "capaNCDT", says how the start is
aligned with the sensor's frame counter.
"""
from __future__ import annotations

from bisect import bisect_right
from pathlib import Path

import numpy as np

from ..errors import DataError
from .input_files import read_input


class CommandSchedule:
    """Piecewise-constant command u(t) from change times ``t`` (increasing) and values ``u``."""

    def __init__(self, t: np.ndarray, u: np.ndarray, source: str = "command") -> None:
        t = np.asarray(t, dtype=float).ravel()
        u = np.asarray(u, dtype=float).ravel()
        if t.size == 0 or t.size != u.size:
            raise DataError(f"{source}: a command schedule needs at least one row of t,u")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(u))):
            raise DataError(f"{source}: the command schedule contains NaN or inf")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise DataError(f"{source}: the command schedule's times must increase strictly")
        self.t, self.u, self.source = t, u, source
        self._t_list, self._u_list = t.tolist(), u.tolist()   # for the per-sample lookup

    @classmethod
    def load(cls, path: str | Path) -> "CommandSchedule":
        """Read a ``t,u`` CSV file (an optional header line, comment lines starting with '#')."""
        name = str(path)
        try:
            text = read_input(path, what="command schedule (t,u file)", max_line=4096).decode("utf-8-sig")
        except DataError as exc:
            raise DataError(f"cannot read the command schedule: {exc}") from None
        except UnicodeDecodeError as exc:
            raise DataError(f"{name}: not a text file (undecodable byte at offset {exc.start})") from None
        t: list[float] = []
        u: list[float] = []
        for number, line in enumerate(text.splitlines(), 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            cells = [c.strip() for c in line.split(",")]
            try:
                tv, uv = float(cells[0]), float(cells[1])
            except (ValueError, IndexError):
                if not t and not any(_is_number(c) for c in cells):   # the header
                    continue
                raise DataError(f"{name}, line {number}: expected 't,u' (two numbers), got {line[:60]!r}") from None
            t.append(tv)
            u.append(uv)
        return cls(np.array(t), np.array(u), source=name)

    def at(self, t: np.ndarray | float) -> np.ndarray:
        """The held command at times ``t`` (s from the start)."""
        idx = np.searchsorted(self.t, t, side="right") - 1
        return self.u[np.maximum(idx, 0)]

    def at_time(self, t: float) -> float:
        """The held command at one time ``t`` (s): :meth:`at` for a single sample, without numpy's overhead."""
        return self._u_list[max(bisect_right(self._t_list, t) - 1, 0)]

    def write(self, path: str | Path) -> None:
        """Save as ``t,u`` CSV with exact (repr) numbers, so :meth:`load` returns the same schedule."""
        lines = ["t,u"] + [f"{float(a)!r},{float(b)!r}" for a, b in zip(self.t, self.u)]
        Path(path).write_text("\n".join(lines) + "\n")


def held_at_rate(times: np.ndarray, values: np.ndarray) -> CommandSchedule:
    """The schedule of a command sampled at ``times``: one row per change (and the first sample)."""
    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    keep = np.concatenate([[True], values[1:] != values[:-1]]) if values.size else np.zeros(0, bool)
    return CommandSchedule(times[keep], values[keep])


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
