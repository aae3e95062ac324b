"""The timing helper shared by the benchmarks (it lives in the package, where the book uses it too)."""

from mascore._timing import median_time

__all__ = ["median_time"]
