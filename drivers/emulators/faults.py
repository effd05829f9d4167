"""Fault injection shared by the tracker and emScon emulators and the reference bridge.

A ``FaultDeck`` answers "which fault, if any, hits this request": first the one-shot faults queued with
``inject`` (in order), else one seeded uniform draw per fault name, checked in the deck's order.
"""
from __future__ import annotations

import random
import threading
from collections import deque
from typing import Callable, Sequence


class FaultDeck:
    """Queued one-shot faults, then seeded random draws over ``names`` (thread-safe)."""

    def __init__(self, names: Sequence[str], rng: random.Random) -> None:
        self.names = tuple(names)
        self._rng = rng
        self._lock = threading.Lock()
        self._queued: deque[str] = deque()

    def inject(self, *names: str) -> None:
        """Queue one-shot faults for the next draws; ``ValueError`` naming any unknown fault."""
        bad = [n for n in names if n not in self.names]
        if bad:
            raise ValueError(f"unknown faults {bad} (expected {', '.join(self.names)})")
        with self._lock:
            self._queued.extend(names)

    def draw(self, probability: Callable[[str], float]) -> str | None:
        """The next queued fault, else the first name whose draw falls below ``probability(name)`` (or None)."""
        with self._lock:
            if self._queued:
                return self._queued.popleft()
            draws = [(name, self._rng.random()) for name in self.names]
        return next((name for name, u in draws if u < probability(name)), None)
