"""Wall-clock timing for benchmarks and the book's cost tables (reported, never asserted)."""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["median_time"]


def median_time(fn: Callable[[], object], repeat: int = 7, number: int = 1) -> float:
    """Median wall-clock seconds of ``number`` calls of `fn`, over `repeat` rounds, after one warm-up call."""
    if repeat < 1 or number < 1:
        raise ValueError(f"repeat and number must be positive integers; got {repeat} and {number}")
    fn()  # warm-up (compilation, caches)
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - start) / number)
    times.sort()
    return times[len(times) // 2]
