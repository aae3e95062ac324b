"""The comparison sweep on one and on two local Dask workers (issue: >= 1.8x on the full grid).

``make bench`` times the quick grid (44 s on 2 workers on a quiet 2-core machine); the full grid takes about 35 minutes on
1 worker and 19 on 2.

``python -m benchmarks.bench_compare --snapshot`` also writes ``benchmarks/data/compare_full.json``,
which the chapter "Comparing the methods" shows, and the full grid's verdicts
(``benchmarks/data/compare_full_claims.json``), against which the claims page lists the claims whose
verdicts differ between the quick and the full grid, and its summary (``benchmarks/data/compare_full_summary.csv``),
which the chapters' sections "From 8 to 64 agents" draw when no full grid is stored beside the book's results.
Each run starts from an empty table in a
temporary folder; the tables of the two runs are checked equal (CPU times aside). Both runs
are the same engine (:func:`mascore.sweep.run_sweep` with ``workers=1`` and ``workers=2``).

``python -m benchmarks.bench_compare --predict`` (a second) predicts the full grid's times from
``benchmarks/data/compare_cell_cpu.csv``, the CPU seconds of block 0 of each of the 191 distinct
cells (the four blocks cost the same), measured serially by ``--measure-cells`` (2 minutes).

Where the 2-worker run lost its time (the snapshot of 2026-11-26: 670 s on 1 worker, 375 s on 2,
1.78x; 335 s would be 2x). Measured on parts, on a shared 2-core machine (CPU times):

* **Not the schedule.** The cells sum to 494 s of serial CPU, the largest 17.8 s (song-mb, N = 64).
  Handed out in the cost hint's order (:func:`mascore.compare.cell_cost`, longest first), the
  2-worker list schedule ends 0.1 s after half the work (speed-up bound 1.999); in the measured
  order (LPT) 0.0 s (2.000); in grid order, without a hint, 2.7 s (1.979). The hint is kept.
* **Dask's allocator setting: the most of it.** Dask's nanny starts each worker with
  ``MALLOC_TRIM_THRESHOLD_=65536``, which also pins glibc's mmap threshold at 128 kB: every
  larger array is mapped, faulted in page by page and unmapped. A song-eb cell at N = 32 took
  46 thousand page faults and 5.5 s of CPU serially, 2.3 million and 9.0 s with the setting
  (3.7 s of it in the kernel); the 51 cells of the scaling study and the first of the graph
  study (all the cells at N = 64, most at N = 32) 75 s serially and 120 s with it (1.60x): most
  of why 1 worker took 670 s for about 494 s of serial work. Two such processes also slow each
  other down: two copies of that cell at once (other jobs running) took 37-39 s of wall for 8.5-9.3 s of CPU
  each with the setting, 15 s for 5.3-5.4 s without (a VM's page faults cost time outside its CPU accounting).
  :func:`mascore.sweep.run_sweep` now starts its workers without it (the numbers do not change).
* **The client.** It wrote each finished cell at once (a data frame, the header read back, an
  append: 16 ms a cell, 12 s for the grid) and fetched each result by its own round trip; in a
  2-worker run that CPU is taken from the workers. The main process spent 6.7 s (1 worker) and
  5.9 s (2 workers) of CPU on 764 instant cells, now 4.0 s and 2.9 s (serially 3.0 s, now 0.8 s):
  rows are written every 2 s and results gathered in the background.
* **Fixed costs, the same for both runs.** Cluster start 2.2 s (1 worker) and 4.3 s (2 workers),
  importing mascore in the workers 2.0-2.5 s, closing 1.8-4.0 s, the final read, sort and rewrite
  of the 38,200 rows 1.2 s, the summary 0.7 s; pickling a cell's 50 rows (7.8 kB) 0.2 ms.

Prediction for the full grid: 494 s of work plus about 9 s of fixed costs on 1 worker (about
505 s), half the work plus about 13 s on 2 (start, imports, close, the client's share: about
260 s): 1.93x (measured before: 1.78x). Measured by ``--snapshot`` on 2026-11-29 on the grid of
924 cells (with the position-sensing and switching studies), nothing else running: 510 s on 1 worker,
279 s on 2, **1.83x**, the same table. The gap to the prediction is probably the two workers sharing the
memory bus and the page-fault path of the VM, which CPU times do not show (not measured).

The current full grid (2,572 cells, 128,600 runs: teams of 32 and 64 on every graph, the links, the knobs),
measured with ``python -m mascore compare --grid full --workers K`` on another 2-core machine (an Intel Xeon),
the 1-worker run with the other core idle, the 2-worker run beside a few short niced jobs (which can only
have slowed it): 2,085 s on 1 worker, 1,119 s on 2, **1.86x**, the same table and
the same verdicts (the committed snapshot). The largest cells (N = 64) run first and gain least: about 1.7x over
the first 70 cells, where two workers each stream covariances of several MB through the shared cache and memory.
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
#: The full grid's verdicts (id, verdict, undecided, why), written with :data:`SNAPSHOT`.
FULL_CLAIMS = Path(__file__).parent / "data" / "compare_full_claims.json"
#: The full grid's summary (``summary-full-0.csv`` of its run), written with :data:`SNAPSHOT`.
FULL_SUMMARY = Path(__file__).parent / "data" / "compare_full_summary.csv"


def _timed(grid: str, workers: int) -> tuple[float, pd.DataFrame, dict, bytes]:
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        table, _ = compare.run_compare(grid, out, workers=workers, progress=False)
        seconds = time.perf_counter() - start
        folder = Path(out) / "compare"
        return (seconds, table, json.loads((folder / "claims.json").read_text()),
                (folder / f"summary-{grid}-0.csv").read_bytes())


def verdicts_record(ledger: dict, cells: int) -> dict:
    """The verdicts of a comparison ledger (its ``claims.json``), small enough to commit.

    Parameters
    ----------
    ledger : dict
        The ledger as written by ``python -m mascore compare``.
    cells : int
        The number of cells of the grid it was decided on.

    Returns
    -------
    dict
        ``created_by``, ``cells`` and per claim ``id``, ``verdict``, ``undecided`` and ``why``.

    Examples
    --------
    >>> ledger = {"created_by": "mascore compare --grid full --seed 0",
    ...           "claims": [{"id": "compare/a", "verdict": "fails", "why": "N = 64", "value": 1.0}]}
    >>> verdicts_record(ledger, 3)["claims"]
    [{'id': 'compare/a', 'verdict': 'fails', 'undecided': False, 'why': 'N = 64'}]
    """
    keep = [{"id": c["id"], "verdict": c["verdict"], "undecided": bool(c.get("undecided")), "why": c.get("why")}
            for c in ledger["claims"]]
    return {"created_by": ledger["created_by"], "cells": int(cells), "claims": keep}


def run(grid: str = "quick", records: dict | None = None) -> pd.DataFrame:
    """Wall time of the grid with 1 and 2 workers, and the speed-up (``make bench``: the quick grid).

    Puts the 2-worker run's verdicts (:func:`verdicts_record`, key ``"claims"``) and its stored summary (CSV
    bytes, key ``"summary"``) in `records` when given.
    """
    t1, table1, _, _ = _timed(grid, 1)
    t2, table2, ledger, summary = _timed(grid, 2)
    same = table1.drop(columns="cpu_s").equals(table2.drop(columns="cpu_s"))
    if records is not None:
        records.update(claims=verdicts_record(ledger, table2["cell"].nunique()), summary=summary)
    return pd.DataFrame([{
        "grid": grid, "cells": table1["cell"].nunique(), "runs": len(table1),
        "cpu_s_total": round(float(table1.drop_duplicates("cell")["cpu_s"].sum()), 1),
        "wall_1_worker_s": round(t1, 1), "wall_2_workers_s": round(t2, 1), "speedup": round(t1 / t2, 2),
        "same_table": bool(same),
    }])


CELL_CPU = Path(__file__).parent / "data" / "compare_cell_cpu.csv"

#: The coordinates that set a cell's cost (cells differing only by ``block`` cost the same).
COST_AXES = ("study", "task", "method", "n_agents", "graph", "noise", "dropout", "q_scale")


def measure_cells(path: Path = CELL_CPU) -> pd.DataFrame:
    """CPU seconds of block 0 of every distinct full-grid cell, run serially in this process.

    Parameters
    ----------
    path : pathlib.Path
        Where the table is written (CSV, one row per combination of :data:`COST_AXES`).

    Returns
    -------
    pandas.DataFrame
        The coordinates and ``cpu_s``, the process CPU time (user + system) of
        :func:`mascore.compare.run_cell`: simulation and estimators, not the wall time
        (on a shared machine the CPU time is the steadier of the two). About 2 minutes.
        Run with ``MALLOC_TRIM_THRESHOLD_=65536`` in the environment (as Dask's nanny starts its
        workers), it fills the column ``cpu_s_trim`` instead.
    """
    cells = {}
    for cell in compare.grid_cells("full"):
        cells.setdefault(tuple(cell[a] for a in COST_AXES), {**cell, "block": 0})
    compare.run_cell(next(iter(cells.values())))  # imports and caches warm
    rows = []
    for cell in cells.values():
        start = time.process_time()
        compare.run_cell(cell)
        rows.append({**{a: cell[a] for a in COST_AXES}, "cpu_s": round(time.process_time() - start, 3)})
    column = "cpu_s_trim" if "MALLOC_TRIM_THRESHOLD_" in os.environ else "cpu_s"  # Dask's nanny sets it
    table = pd.DataFrame(rows).rename(columns={"cpu_s": column})
    if path.exists():  # update this column, keep the other
        old = pd.read_csv(path).drop(columns=[column], errors="ignore")
        table = old.merge(table, on=list(COST_AXES), how="outer")
    table.to_csv(path, index=False)
    return table


def list_schedule(durations, workers: int = 2, slots: int = 1) -> float:
    """Makespan of running `durations` in the given order on `workers` single-threaded workers.

    Parameters
    ----------
    durations : sequence of float
        Seconds per task, in the order they are handed out.
    workers : int
        Number of workers.
    slots : int
        Tasks a worker holds at once (running and waiting): Dask's scheduler gives a
        one-thread worker ``ceil(1.1 * 1) = 2``, so a task is committed to a worker when
        that worker starts its previous one, not when it becomes idle.

    Returns
    -------
    float
        When the last task ends, in seconds.

    Examples
    --------
    >>> from benchmarks.bench_compare import list_schedule
    >>> list_schedule([3.0, 2.0, 2.0, 1.0], workers=2)
    4.0
    >>> list_schedule([1.0, 2.0, 2.0, 3.0], workers=2)  # shortest first: one worker idles at the end
    5.0
    """
    ends = [[] for _ in range(workers)]
    for d in durations:
        opens = [e[-slots] if len(e) >= slots else 0.0 for e in ends]  # when each worker has a free slot
        w = opens.index(min(opens))
        ends[w].append((ends[w][-1] if ends[w] else 0.0) + float(d))
    return max(e[-1] for e in ends if e)


def predict(path: Path = CELL_CPU) -> pd.DataFrame:
    """The full grid's predicted run time on 1 and 2 workers, from the measured cell costs.

    Every full-grid cell takes its combination's measured ``cpu_s`` (the four blocks cost the
    same); the cells are handed out in the order of the cost hint :func:`mascore.compare.cell_cost`
    (the sweep's order) or of the measured costs (longest processing time first, LPT).

    Parameters
    ----------
    path : pathlib.Path
        The table of :func:`measure_cells`.

    Returns
    -------
    pandas.DataFrame
        One row per order and slots: ``work_s`` (the sum: one worker's time), ``makespan_2_s``,
        ``tail_loss_s`` (makespan minus half the work) and ``speedup`` (work over makespan), with
        no fixed overheads (start, dispatch, writing): the bound the schedule alone allows.
    """
    table = pd.read_csv(path)
    cost = {tuple(row[a] for a in COST_AXES): row["cpu_s"] for row in table.to_dict("records")}
    cells = compare.grid_cells("full")
    seconds = [cost[tuple(c[a] for a in COST_AXES)] for c in cells]
    work = float(sum(seconds))
    orders = {
        "cost hint (cell_cost)": sorted(range(len(cells)), key=lambda i: -compare.cell_cost(cells[i])),
        "measured (LPT)": sorted(range(len(cells)), key=lambda i: -seconds[i]),
        "grid order (no hint)": list(range(len(cells))),
    }
    rows = []
    for name, order in orders.items():
        for slots in (1, 2):
            span = list_schedule([seconds[i] for i in order], 2, slots)
            rows.append({"order": name, "slots": slots, "cells": len(cells), "work_s": round(work, 1),
                         "largest_cell_s": round(max(seconds), 2), "makespan_2_s": round(span, 1),
                         "tail_loss_s": round(span - work / 2, 1), "speedup": round(work / span, 3)})
    return pd.DataFrame(rows)


def trim_slowdown(path: Path = CELL_CPU) -> pd.DataFrame:
    """CPU of the cells measured both with glibc's defaults and with Dask's ``MALLOC_TRIM_THRESHOLD_=65536``.

    Parameters
    ----------
    path : pathlib.Path
        The table, with a ``cpu_s_trim`` column where measured (a run with the variable set).

    Returns
    -------
    pandas.DataFrame
        One row: combinations measured, their CPU both ways and the ratio.
    """
    table = pd.read_csv(path)
    table = table.dropna(subset=["cpu_s_trim"]) if "cpu_s_trim" in table else table.iloc[:0].assign(cpu_s_trim=0.0)
    return pd.DataFrame([{"combinations": len(table), "cpu_s": round(float(table["cpu_s"].sum()), 1),
                          "cpu_s_trim": round(float(table["cpu_s_trim"].sum()), 1),
                          "ratio": round(float(table["cpu_s_trim"].sum() / table["cpu_s"].sum()), 2)}])


if __name__ == "__main__":
    if "--predict" in sys.argv:
        print(predict().to_string(index=False))
        print(trim_slowdown().to_string(index=False))
        sys.exit(0)
    if "--measure-cells" in sys.argv:
        print(measure_cells().to_string(index=False))
        sys.exit(0)
    records: dict = {}
    result = run(sys.argv[1] if len(sys.argv) > 1 and not sys.argv[1].startswith("--") else "full", records)
    print(result.to_string(index=False))
    if "--snapshot" in sys.argv:
        FULL_CLAIMS.write_text(json.dumps(records["claims"], indent=1) + "\n")
        FULL_SUMMARY.write_bytes(records["summary"])
        record = result.iloc[0].to_dict()
        record.update(date=time.strftime("%Y-%m-%d"), cpu=platform.processor() or platform.machine(),
                      cores=os.cpu_count())
        SNAPSHOT.write_text(json.dumps({k: (v.item() if hasattr(v, "item") else v) for k, v in record.items()},
                                       indent=1) + "\n")
