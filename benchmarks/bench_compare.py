"""The comparison sweep on one and on two local Dask workers (issue: >= 1.8x on the full grid).

``make bench`` times the quick grid (about two minutes); the full grid takes about 12 minutes.

``python -m benchmarks.bench_compare --snapshot`` also writes ``benchmarks/data/compare_full.json``,
which the chapter "Comparing the methods" shows. Each run starts from an empty table in a
temporary folder; the tables of the two runs are checked equal (CPU times aside).
"""

from __future__ import annotations

import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from mascore import compare

SNAPSHOT = Path(__file__).parent / "data" / "compare_full.json"


def _timed(grid: str, workers: int) -> tuple[float, pd.DataFrame]:
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        table, _ = compare.run_compare(grid, out, workers=workers, progress=False)
        return time.perf_counter() - start, table


def run(grid: str = "quick") -> pd.DataFrame:
    """Wall time of the grid with 1 and 2 workers, and the speed-up (``make bench``: the quick grid)."""
    t1, table1 = _timed(grid, 1)
    t2, table2 = _timed(grid, 2)
    same = table1.drop(columns="cpu_s").equals(table2.drop(columns="cpu_s"))
    return pd.DataFrame([{
        "grid": grid, "cells": table1["cell"].nunique(), "runs": len(table1),
        "cpu_s_total": round(float(table1.drop_duplicates("cell")["cpu_s"].sum()), 1),
        "wall_1_worker_s": round(t1, 1), "wall_2_workers_s": round(t2, 1), "speedup": round(t1 / t2, 2),
        "same_table": bool(same),
    }])


if __name__ == "__main__":
    result = run(sys.argv[1] if len(sys.argv) > 1 and not sys.argv[1].startswith("--") else "full")
    print(result.to_string(index=False))
    if "--snapshot" in sys.argv:
        record = result.iloc[0].to_dict()
        record.update(date=time.strftime("%Y-%m-%d"), cpu=platform.processor() or platform.machine(),
                      cores=os.cpu_count())
        SNAPSHOT.write_text(json.dumps({k: (v.item() if hasattr(v, "item") else v) for k, v in record.items()},
                                       indent=1) + "\n")
