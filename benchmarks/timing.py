"""Helpers shared by the benchmarks: the timing (it lives in the package, where the book uses it too), the CPU."""

from pathlib import Path

from mascore._timing import median_time

__all__ = ["cpu_model", "median_time"]


def cpu_model() -> str:
    """The processor's model name from ``/proc/cpuinfo`` ("unknown" where there is none)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"
