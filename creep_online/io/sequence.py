"""Sequence-number accounting: deliver samples in order, count what went wrong.

Frames carry a sequence counter. The tracker keeps a short reorder buffer so a
frame that arrives a few places late is still delivered in its place; beyond
that window the missing numbers are declared lost. Counted:

``gaps``        runs of missing numbers (events)
``missing``     samples declared lost (never delivered)
``duplicates``  copies of a number already delivered or pending
``reordered``   samples that arrived after a higher number but were delivered in place
``late``        samples that arrived after their number was declared lost (dropped)
``resets``      jumps too large to be loss (the sender restarted): tracking restarts

Counters wrap (``modulus``, e.g. 2**32 for the binary frame, 2**16 for CAN)
and are unwrapped to a monotonically growing integer.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Generic, TypeVar

T = TypeVar("T")


@dataclass
class SequenceStats:
    delivered: int = 0
    gaps: int = 0
    missing: int = 0
    duplicates: int = 0
    reordered: int = 0
    late: int = 0
    resets: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class SequenceTracker(Generic[T]):
    """Orders items by sequence number with a bounded reorder window.

    ``push(seq, item)`` returns the items now deliverable, in order, as
    ``(unwrapped_seq, item)`` pairs. ``window`` is how many newer samples may
    arrive before a missing one is given up; ``reset_jump`` is the jump (either
    way) treated as a sender restart rather than loss.
    """

    window: int = 16
    modulus: int | None = None
    reset_jump: int = 1_000_000
    history: int = 4096
    stats: SequenceStats = field(default_factory=SequenceStats)
    _next: int | None = None
    _pending: dict = field(default_factory=dict)
    _max_seen: int = -1
    _lost: set = field(default_factory=set)
    _maybe_restart: bool = False

    def expect_restart(self) -> None:
        """The link was re-established: a counter that went backwards means the sender restarted."""
        self._maybe_restart = True

    def _unwrap(self, seq: int) -> int:
        if self.modulus is None or self._next is None:
            return seq
        m = self.modulus
        ref = self._next
        base = ref - (ref % m)
        cand = base + seq
        # choose the representative closest to what we expect
        if cand - ref > m // 2:
            cand -= m
        elif ref - cand > m // 2:
            cand += m
        return cand

    def push(self, seq: int, item: T) -> list[tuple[int, T]]:
        st = self.stats
        if self._next is None:
            self._next = seq
            self._max_seen = seq - 1
        s = self._unwrap(seq)
        restarted = self._maybe_restart and s < self._next and s not in self._pending
        self._maybe_restart = False
        if restarted or s - self._next > self.reset_jump or self._next - s > self.reset_jump:
            out = self.flush()
            st.resets += 1
            self._next = s
            self._max_seen = s - 1
            self._lost.clear()
            return out + self.push_unwrapped(s, item)
        return self.push_unwrapped(s, item)

    def push_unwrapped(self, s: int, item: T) -> list[tuple[int, T]]:
        st = self.stats
        if s < self._next:
            if s in self._lost:
                self._lost.discard(s)
                st.late += 1
            else:
                st.duplicates += 1
            return []
        if s in self._pending:
            st.duplicates += 1
            return []
        if s < self._max_seen:
            st.reordered += 1
        else:
            self._max_seen = s
        self._pending[s] = item
        return self._drain()

    def _drain(self) -> list[tuple[int, T]]:
        out: list[tuple[int, T]] = []
        pending = self._pending
        while pending:
            item = pending.pop(self._next, None)
            if item is not None:
                out.append((self._next, item))
                self._next += 1
                continue
            if self._max_seen - self._next < self.window:
                break
            self._give_up(min(pending))
        self.stats.delivered += len(out)
        return out

    def _give_up(self, upto: int) -> None:
        """Declare numbers next..upto-1 lost."""
        n = upto - self._next
        self.stats.gaps += 1
        self.stats.missing += n
        if n <= self.history:
            self._lost.update(range(self._next, upto))
        if len(self._lost) > self.history:
            cutoff = upto - self.history
            self._lost = {x for x in self._lost if x >= cutoff}
        self._next = upto

    def flush(self) -> list[tuple[int, T]]:
        """Deliver everything pending (the stream stalled or ended), declaring holes lost."""
        out: list[tuple[int, T]] = []
        while self._pending:
            first = min(self._pending)
            if first > self._next:
                self._give_up(first)
            out.append((first, self._pending.pop(first)))
            self._next = first + 1
        self.stats.delivered += len(out)
        return out

    @property
    def next_seq(self) -> int | None:
        return self._next

    @property
    def pending(self) -> int:
        return len(self._pending)
