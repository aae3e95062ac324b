"""Timing benchmarks of mascore (see ``benchmarks/__main__.py``)."""
