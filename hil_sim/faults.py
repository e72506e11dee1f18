"""Fault injection plan and the ledger of what was injected.

``--faults garbage=N,bitflip=N,drop=N,dup=N,reorder=N,stall=N,disconnect=N,badheader=N``
with N an exact count (integer >= 1) or a per-frame probability (0 < p < 1);
``stall_s=`` and ``disconnect_s=`` set the durations, ``drop_frames=`` how many
measuring frames a capaNCDT drop skips (``badheader`` and ``drop_frames`` are
the capaNCDT transport's: a frame there is one TCP packet). Faults land on distinct
frames at least ``spacing`` frames apart and away from both ends, so each one
is separately observable and the receiver's counters can be compared exactly
with the ledger.
"""
from __future__ import annotations

import math

import json
from dataclasses import dataclass, field

import numpy as np

KINDS = ("garbage", "bitflip", "drop", "dup", "reorder", "stall", "disconnect", "badheader")


@dataclass
class FaultSpec:
    counts: dict = field(default_factory=dict)      # kind -> count or probability
    stall_s: float = 1.5
    disconnect_s: float = 0.5
    drop_frames: int = 1                            # capancdt: measuring frames skipped by one drop

    @classmethod
    def parse(cls, text: str | None) -> "FaultSpec":
        spec = cls()
        for item in (text or "").split(","):
            item = item.strip()
            if not item:
                continue
            if "=" not in item:
                raise ValueError(f"--faults: expected kind=value, got {item!r}")
            k, v = (s.strip() for s in item.split("=", 1))
            try:
                value = float(v)
            except ValueError:
                raise ValueError(f"--faults: {k} must be a number, got {v!r}") from None
            if not (math.isfinite(value) and value >= 0 and value <= 1e9):
                raise ValueError(f"--faults: {k} must be a finite number >= 0, got {v!r}")
            if k in ("stall_s", "disconnect_s"):
                if value <= 0:
                    raise ValueError(f"--faults: {k} must be > 0 s, got {v!r}")
                setattr(spec, k, value)
            elif k == "drop_frames":
                if not value.is_integer() or value < 1:
                    raise ValueError(f"--faults: drop_frames must be a whole number >= 1, got {v!r}")
                spec.drop_frames = int(value)
            elif k in KINDS:
                spec.counts[k] = value
            else:
                raise ValueError(f"--faults: unknown fault {k!r}; choose from {', '.join(KINDS)}, stall_s, disconnect_s, "
                                 "drop_frames")
        return spec


@dataclass
class Ledger:
    """What the plant injected, for tests to compare with the receiver's counters."""

    frames_sent: int = 0
    samples_per_frame: int = 1
    dropped: list = field(default_factory=list)        # frame indices
    duplicated: list = field(default_factory=list)
    reordered: list = field(default_factory=list)
    bitflips: list = field(default_factory=list)
    garbage: list = field(default_factory=list)        # frame indices a burst preceded
    garbage_bytes: int = 0
    stalls: list = field(default_factory=list)
    disconnects: list = field(default_factory=list)
    disconnect_lost_samples: int = 0
    late_max_s: float = 0.0                            # worst pacing lag of the sender
    bad_headers: list = field(default_factory=list)    # capancdt: packets sent with a corrupt header
    bad_header_samples: int = 0                        # capancdt: measuring frames in those packets
    dropped_samples: int = 0                           # capancdt: measuring frames skipped by drops

    def to_dict(self) -> dict:
        d = dict(self.__dict__)
        d["counts"] = {k: len(getattr(self, a)) for k, a in
                       (("drop", "dropped"), ("dup", "duplicated"), ("reorder", "reordered"),
                        ("bitflip", "bitflips"), ("garbage", "garbage"), ("stall", "stalls"),
                        ("disconnect", "disconnects"), ("badheader", "bad_headers"))}
        return d

    def write(self, path: str) -> None:
        with open(path, "w") as f:
            json.dump(self.to_dict(), f)


def plan(spec: FaultSpec, n_frames: int, seed: int, spacing: int = 40, margin: int = 100,
         frame_rate: float | None = None) -> dict[int, str]:
    """frame index -> fault kind, deterministic for a seed.

    A disconnect loses the frames of its outage; it is placed so that the
    outage (doubled, plus half a second for the reader to come back) ends before the record
    does, or the loss would be invisible to a receiver (no later frame).
    """
    rng = np.random.default_rng(seed + 7919)
    wanted: list[str] = []
    for kind in KINDS:
        v = spec.counts.get(kind, 0.0)
        if v <= 0:
            continue
        n = int(v) if v >= 1 else int(rng.binomial(n_frames, v))
        wanted += [kind] * n
    if not wanted:
        return {}
    slots = np.arange(margin, max(margin, n_frames - margin - 2), spacing)
    if len(slots) < len(wanted):
        raise ValueError(f"--faults: {len(wanted)} faults do not fit in {n_frames} frames "
                         f"(at most {len(slots)} with {spacing}-frame spacing); lower the counts or run longer")
    rng.shuffle(wanted)
    n_disc = wanted.count("disconnect")
    if n_disc:
        reserve = int(((2 * spec.disconnect_s + 0.5) * frame_rate) if frame_rate else 0)
        early = slots[slots < n_frames - margin - reserve]
        if len(early) < n_disc:
            raise ValueError(f"--faults: {n_disc} disconnect(s) of {spec.disconnect_s:g} s do not fit in the record; "
                             "run longer")
        disc = []
        for _ in range(n_disc):     # outages must not overlap each other or other faults
            if len(early) == 0:
                raise ValueError(f"--faults: {n_disc} disconnects of {spec.disconnect_s:g} s do not fit in the "
                                 "record; run longer")
            d = int(rng.choice(early))
            disc.append(d)
            early = early[(early < d - reserve - spacing) | (early > d + reserve + spacing)]
        for d in disc:
            slots = slots[(slots < d - spacing) | (slots > d + reserve + spacing)]
        if len(slots) < len(wanted) - n_disc:
            raise ValueError("--faults: too many faults for the record; lower the counts or run longer")
        rest = rng.choice(slots, size=len(wanted) - n_disc, replace=False)
        others = [k for k in wanted if k != "disconnect"]
        return {**{int(f): "disconnect" for f in disc}, **{int(f): k for f, k in zip(rest, others)}}
    chosen = rng.choice(slots, size=len(wanted), replace=False)
    return {int(f): k for f, k in zip(chosen, wanted)}
