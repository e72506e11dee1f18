"""A seeded fleet of actuators of one type, for the batch tests and ``bench/bench_batch.py``.

Every unit is the nominal plant (a nanopositioner: alpha 0.02, fn 350 Hz,
zeta 0.08, b 1.8) with its own manufacturing spread, log-normal with standard
deviations of 5 % (alpha), 3 % (fn), 10 % (zeta) and 3 % (b). A few units
are faulty in a way a fleet summary must catch: ``"loose"`` (fn 30 % low, a
loosened mount), ``"depoled"`` (b halved) or ``"reversed"`` (b of the other sign: an
actuator wired backwards). Each unit's record is a
staircase with a reversal (``STAIRCASE``: up, further up, back down), simulated
exactly and sampled at ``fs`` with white noise at ``snr_db``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from creep_online.io import save_csv
from creep_online.model import CreepModel
from creep_online.simulate import simulate

NOMINAL = {"alpha": 0.02, "fn": 350.0, "zeta": 0.08, "b": 1.8}
SPREAD = {"alpha": 0.05, "fn": 0.03, "zeta": 0.10, "b": 0.03}
#: (fraction of the duration, level) of the input staircase: up, further up, back down.
STAIRCASE = ((0.05, 1.0), (0.4, 1.6), (0.7, 0.6))
#: What each kind of fault does to a unit's parameters (factors).
FAULTS = {"loose": {"fn": 0.7}, "depoled": {"b": 0.5}, "reversed": {"b": -1.0}}


@dataclass
class Unit:
    """One actuator of the fleet: its id, true model, fault (or None) and record."""

    id: str
    model: CreepModel
    fault: str | None
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray


def make_unit(index: int, seed: int = 0, *, fault: str | None = None, fs: float = 5000.0,
              duration: float = 1.0, snr_db: float = 40.0) -> Unit:
    """Unit ``index`` of the fleet drawn with ``seed`` (same arguments, same record)."""
    rng = np.random.default_rng([seed, index])
    p = {k: v * float(np.exp(rng.normal(0.0, SPREAD[k]))) for k, v in NOMINAL.items()}
    for k, factor in FAULTS.get(fault or "", {}).items():
        p[k] *= factor
    model = CreepModel.from_resonance(p["alpha"], p["fn"], p["zeta"], p["b"])
    t = np.arange(int(round(duration * fs))) / fs
    u = np.zeros_like(t)
    for frac, level in STAIRCASE:
        u[t >= frac * duration - 1e-12] = level
    clean = simulate(model, t, u)
    y = clean + rng.normal(0.0, float(np.std(clean)) * 10 ** (-snr_db / 20), t.size)
    return Unit(f"unit{index:04d}", model, fault, t, u, y)


def make_fleet(n: int, seed: int = 0, *, faults: dict[int, str] | None = None, **kwargs) -> list[Unit]:
    """``n`` units; ``faults`` maps unit index to a fault name (``"loose"``, ``"depoled"``, ``"reversed"``)."""
    faults = faults or {}
    return [make_unit(i, seed, fault=faults.get(i), **kwargs) for i in range(n)]


def write_fleet(units: list[Unit], folder: str | Path) -> list[Path]:
    """One ``t,u,y`` CSV per unit (``<id>.csv``) in ``folder``; the paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for unit in units:
        paths.append(folder / f"{unit.id}.csv")
        save_csv(paths[-1], unit.t, unit.u, unit.y)
    return paths


def write_long(units: list[Unit], path: str | Path) -> Path:
    """All units in one long-format CSV ``id,t,u,y`` (one block of rows per unit)."""
    path = Path(path)
    with path.open("w") as fh:
        fh.write("id,t,u,y\n")
        for unit in units:
            for t, u, y in zip(unit.t, unit.u, unit.y):
                fh.write(f"{unit.id},{float(t)!r},{float(u)!r},{float(y)!r}\n")
    return path
