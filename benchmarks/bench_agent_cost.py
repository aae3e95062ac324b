"""The cost of one agent per step, one run, one thread, over N = 4 ... 128 (:mod:`mascore.agent_cost`).

``make bench`` runs it (a few minutes: the team-wide set-up of Song et al.'s measurement-based
filter at N = 128 alone takes about 20 s) and writes ``results/benchmarks/bench_agent_cost.csv``;
``python -m benchmarks.bench_agent_cost --snapshot`` also writes the committed snapshot
``benchmarks/data/agent_cost.csv`` (with ``agent_cost_machine.json``) that the chapter
"Comparing the methods" reads. Times are CPU of this thread (:func:`time.thread_time`), the
median of 7 repeats after a warm-up, so other processes on the machine disturb them little;
BLAS must run on one thread (``OMP_NUM_THREADS=1``, which the Makefile sets, or threadpoolctl).
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.timing import cpu_model
from mascore import agent_cost

DATA = Path(__file__).parent / "data"
SIZES = (4, 8, 16, 32, 64, 128)


def run(sizes=SIZES, progress: bool = False) -> pd.DataFrame:
    """Every (task, method, N) of :func:`mascore.agent_cost.agent_costs`."""
    return agent_cost.agent_costs(sizes, repeats=7, min_time=0.02, progress=progress)


def machine(seconds: float) -> dict:
    """Where, when and how the table was measured."""
    import scipy

    cpu = cpu_model()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return {"date": time.strftime("%Y-%m-%d"), "cpu": cpu, "cores": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "blas": agent_cost.blas_pinned(), "load_average_1min": round(load, 2),
            "timing": "CPU of one thread (time.thread_time), median of 7 repeats of >= 20 ms after a warm-up",
            "wall_s": round(seconds, 1)}


def write_snapshot(table: pd.DataFrame, seconds: float) -> None:
    """The committed snapshot the chapter reads."""
    DATA.mkdir(exist_ok=True)
    table.to_csv(DATA / "agent_cost.csv", index=False, float_format="%.6g")
    (DATA / "agent_cost_machine.json").write_text(json.dumps(machine(seconds), indent=2) + "\n")


if __name__ == "__main__":  # pragma: no cover
    start = time.perf_counter()
    result = run(progress=True)
    elapsed = time.perf_counter() - start
    print(result.drop(columns=["work", "memory", "why"]).to_string(index=False))
    print(agent_cost.slopes(result).to_string())
    if "--snapshot" in sys.argv[1:]:
        write_snapshot(result, elapsed)
