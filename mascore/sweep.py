"""Parameter sweeps: a grid of cells, each seeded from its coordinates, run serially or on Dask.

A sweep is a list of **cells**, dictionaries of coordinates such as
``{"method": "song-eb", "n_agents": 8, "noise": "gaussian", "dropout": 0.1, "block": 3}``,
usually built as the union of a few :class:`Grid` products. A task maps one cell to
a list of result rows. :func:`run_sweep` runs the cells that are not yet in
the output table and appends each cell's rows to it as soon as they arrive, so an
interrupted sweep resumes where it stopped; the table is finally rewritten
sorted by cell, so the same sweep gives the same file however and wherever it ran.

Randomness comes only from :func:`cell_seed`: a ``numpy.random.SeedSequence``
built from the sweep's base seed and the values of the cell's **seed axes**.
Leaving an axis out of the seed axes (for example the method) gives every value
of that axis the same random numbers: common random numbers.

The cells run serially in this process (``workers=0``), on a local Dask cluster
of worker processes (``workers=K``), or on any Dask cluster given by its
scheduler address (``scheduler="tcp://HOST:8786"``). Dask's nanny starts each
worker with one BLAS thread, so a cell computes the same floating-point numbers
in a worker as in a serial run with ``OMP_NUM_THREADS=1``. The local cluster's
workers keep the C library's memory allocator settings, as a serial run does
(Dask's default ``MALLOC_TRIM_THRESHOLD_=65536`` made large-array cells up to
twice as slow); workers of another cluster are best started the same way,
``dask worker --no-nanny`` with ``OMP_NUM_THREADS=1``.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
from collections.abc import Callable, Hashable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from ._optional import require
from ._progress import progress_bar
from ._validation import check_positive_int

__all__ = ["Grid", "cell_id", "cell_seed", "dask_client", "demo_task", "run_sweep"]

#: The column holding each row's cell identifier.
CELL_COLUMN = "cell"


@dataclass(frozen=True)
class Grid:
    """The Cartesian product of named axes.

    Parameters
    ----------
    axes : mapping of str to sequence
        Axis name to its values (numbers, strings or booleans), in order.

    Examples
    --------
    >>> from mascore.sweep import Grid
    >>> grid = Grid({"method": ["a", "b"], "seed": [0, 1, 2]})
    >>> len(grid), grid.cells()[4]
    (6, {'method': 'b', 'seed': 1})
    """

    axes: Mapping[str, Sequence[Any]]

    def __post_init__(self) -> None:
        if not isinstance(self.axes, Mapping) or not self.axes:
            raise ValueError(f"axes must be a non-empty mapping of axis name to values; got {self.axes!r}")
        for name, values in self.axes.items():
            if not isinstance(name, str) or not name.isidentifier() or name == CELL_COLUMN:
                raise ValueError(f"axis names must be identifiers other than {CELL_COLUMN!r}; got {name!r}")
            if isinstance(values, (str, bytes)) or not isinstance(values, Iterable) or len(list(values)) == 0:
                raise ValueError(f"axis {name!r} must be a non-empty sequence of values; got {values!r}")
            for v in values:
                if not isinstance(v, (str, bool, int, float, np.integer, np.floating)):
                    raise TypeError(f"axis {name!r}: values must be numbers, strings or booleans; got {v!r}")

    def __len__(self) -> int:
        """Number of cells.

        Returns
        -------
        int
            The product of the axis lengths.

        Examples
        --------
        >>> from mascore.sweep import Grid
        >>> len(Grid({"n": [4, 8], "p": [0.0, 0.1, 0.3]}))
        6
        """
        return int(np.prod([len(list(v)) for v in self.axes.values()]))

    def cells(self) -> list[dict[str, Any]]:
        """Every cell of the product, the last axis varying fastest.

        Returns
        -------
        list of dict
            One dictionary of coordinates per cell.

        Examples
        --------
        >>> from mascore.sweep import Grid
        >>> Grid({"n": [4, 8], "p": [0.0]}).cells()
        [{'n': 4, 'p': 0.0}, {'n': 8, 'p': 0.0}]
        """
        names = list(self.axes)
        return [dict(zip(names, _plain(values))) for values in itertools.product(*self.axes.values())]


def _plain(values: Iterable[Any]) -> tuple:
    """NumPy scalars as Python ones (stable text and hashing)."""
    return tuple(v.item() if isinstance(v, np.generic) else v for v in values)


def cell_id(cell: Mapping[str, Any]) -> str:
    """A cell's identifier: its coordinates as sorted, compact JSON.

    Parameters
    ----------
    cell : mapping of str to number, str or bool
        The cell's coordinates.

    Returns
    -------
    str
        The same text for the same coordinates, whatever their order.

    Examples
    --------
    >>> from mascore.sweep import cell_id
    >>> cell_id({"seed": 3, "method": "local"})
    '{"method":"local","seed":3}'
    """
    if not isinstance(cell, Mapping):
        raise TypeError(f"cell must be a mapping of axis name to value; got {type(cell).__name__}")
    return json.dumps(dict(zip(cell, _plain(cell.values()))), sort_keys=True, separators=(",", ":"))


def cell_seed(cell: Mapping[str, Any], seed_axes: Sequence[str], base_seed: int = 0) -> np.random.SeedSequence:
    """The seed of a cell, from its coordinates on `seed_axes` only.

    Parameters
    ----------
    cell : mapping of str to value
        The cell's coordinates.
    seed_axes : sequence of str
        The axes whose values choose the random numbers. Axes not listed share
        their random numbers (common random numbers across, e.g., methods).
    base_seed : int
        The sweep's seed, a non-negative integer.

    Returns
    -------
    numpy.random.SeedSequence
        Pass it to ``numpy.random.default_rng``.

    Raises
    ------
    KeyError
        A seed axis is not a coordinate of the cell.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.sweep import cell_seed
    >>> a = cell_seed({"method": "x", "block": 2}, ["block"], 7)
    >>> b = cell_seed({"method": "y", "block": 2}, ["block"], 7)
    >>> np.random.default_rng(a).random() == np.random.default_rng(b).random()   # same block, same draws
    True
    """
    if isinstance(base_seed, bool) or not isinstance(base_seed, (int, np.integer)) or base_seed < 0:
        raise ValueError(f"base_seed must be a non-negative integer; got {base_seed!r}")
    if isinstance(seed_axes, str):
        raise TypeError(f"seed_axes must be a sequence of axis names, not the string {seed_axes!r}")
    missing = [a for a in seed_axes if a not in cell]
    if missing:
        raise KeyError(f"seed axes {missing} are not coordinates of the cell {cell_id(cell)}")
    text = cell_id({a: cell[a] for a in seed_axes})
    digest = hashlib.sha256(text.encode()).digest()
    words = [int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4)]
    return np.random.SeedSequence([int(base_seed), *words])


def run_sweep(
    cells: Sequence[Mapping[str, Any]],
    task: Callable[[dict[str, Any]], list[dict[str, Any]]],
    out: str | Path,
    *,
    workers: int = 0,
    scheduler: str | None = None,
    progress: bool = True,
    sort_by: Sequence[str] | None = None,
    cost: Callable[[dict[str, Any]], float] | None = None,
    group: Callable[[dict[str, Any]], Hashable | None] | None = None,
):
    """Run `task` on every cell not yet in `out`; return the whole table.

    Parameters
    ----------
    cells : sequence of mapping
        The cells (see :meth:`Grid.cells`); duplicates are run once.
    task : callable
        ``task(cell) -> list of row dicts``. It must be importable by the
        workers (a module-level function) and derive all randomness from the
        cell (:func:`cell_seed`). Each row gets the cell's coordinates and the
        ``cell`` identifier added.
    out : str or pathlib.Path
        CSV file of the table. Rows of cells already in it are kept and those
        cells are skipped (resume); the rows of finished cells are appended every
        2 seconds, and when the sweep stops (also by an error or an interrupt).
        Delete the file when the task's code has changed: its rows are not recomputed.
    workers : int
        0 runs the cells in this process; ``K >= 1`` starts a local Dask
        cluster of K single-threaded worker processes for the sweep.
    scheduler : str, optional
        Address of a running Dask scheduler (``"tcp://127.0.0.1:8786"``);
        overrides `workers`.
    progress : bool
        Show a progress bar counting cells.
    sort_by : sequence of str, optional
        Columns the final table is sorted by (default: the cell identifier,
        then the row order within each cell).
    cost : callable, optional
        ``cost(cell) -> float``, a rough estimate of a cell's run time: the cells are
        started in decreasing order of cost (longest first), so that on a cluster
        no worker is left with one long cell at the end. The table does not depend on it.
    group : callable, optional
        ``group(cell) -> key``: the pending cells of one (hashable) key run together, as one
        call ``task([cell, ...]) -> [rows of each cell, ...]`` (one task on a cluster), so that
        the task can share work between them (say, the seed blocks of one method, whose
        data-independent covariances are then computed once); a key of None runs its cell
        alone, as ``task([cell])``. With `group`, `task` takes a list of cells. The rows of a
        cell must not depend on the other cells of its call: the table does not depend on it.

    Returns
    -------
    pandas.DataFrame
        The whole table at `out`: every row of every cell in `cells`, and of cells already there.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from mascore.sweep import Grid, run_sweep
    >>> from mascore.sweep import demo_task
    >>> out = Path(tempfile.mkdtemp()) / "demo.csv"
    >>> table = run_sweep(Grid({"scale": [1.0, 2.0], "block": [0, 1]}).cells(), demo_task, out, progress=False)
    >>> len(table), list(table.columns)[:3]
    (4, ['block', 'cell', 'scale'])
    """
    import pandas as pd

    if not callable(task):
        raise TypeError(f"task must be callable, cell -> list of row dicts; got {type(task).__name__}")
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 0:
        raise ValueError(f"workers must be a non-negative integer (0 = run in this process); got {workers!r}")
    if scheduler is not None and (not isinstance(scheduler, str) or "://" not in scheduler):
        raise ValueError(f"scheduler must be an address such as 'tcp://127.0.0.1:8786'; got {scheduler!r}")
    out = Path(out)
    todo: dict[str, dict] = {}
    for cell in cells:
        todo.setdefault(cell_id(cell), dict(cell))
    done = _done_cells(out)
    pending = [(cid, cell) for cid, cell in todo.items() if cid not in done]
    batches = _batches(pending, group)
    if cost is not None:
        batches.sort(key=lambda batch: -sum(float(cost(cell)) for _, cell in batch))
    out.parent.mkdir(parents=True, exist_ok=True)
    bar = progress_bar(range(len(todo)), enabled=progress, desc="sweep", unit="cell", initial=len(todo) - len(pending),
                       total=len(todo))
    bar_update = getattr(bar, "update", lambda n: None)
    writer = _Appender(out)
    results = _results(batches, task, workers, scheduler, grouped=group is not None)
    try:
        for batch_rows in results:
            for rows in batch_rows:
                writer.add(rows)
            bar_update(len(batch_rows))
    finally:  # keep every finished cell, also when interrupted
        writer.flush()
        results.close()
        getattr(bar, "close", lambda: None)()
    table = pd.read_csv(out, keep_default_na=False, na_values=[""], low_memory=False)
    if pending:  # rewrite in canonical order; a finished table is only read (readers may share it)
        table["_order"] = np.arange(len(table))
        keys = list(sort_by) if sort_by else [CELL_COLUMN]
        table = table.sort_values([*keys, "_order"], kind="stable").drop(columns="_order")
        table = table[sorted(table.columns)].reset_index(drop=True)
        table.to_csv(out, index=False)
    return table


def _done_cells(out: Path) -> set[str]:
    """Cell identifiers already in the table at `out` (none if it does not exist)."""
    if not out.exists() or out.stat().st_size == 0:
        return set()
    import pandas as pd

    return set(pd.read_csv(out, usecols=[CELL_COLUMN])[CELL_COLUMN])


class _Appender:
    """Appends finished cells' rows to the CSV at `out`, a batch at most every `interval` seconds.

    Writing each cell as it arrives cost about 16 ms (a data frame, the header read
    back, a CSV append): 12 s of the client's time on the full comparison grid, taken
    from the workers when they have every core. Here the rows wait in memory
    for at most `interval` seconds (and are written when the sweep stops, also by an
    exception or an interrupt), so a resumed sweep loses at most that much work.
    """

    def __init__(self, out: Path, interval: float = 2.0) -> None:
        import time

        self.out, self.interval, self._clock = out, float(interval), time.monotonic
        self.rows: list[dict] = []
        self.columns: list[str] | None = None  # the file's, once known
        self.exists = out.exists() and out.stat().st_size > 0
        if self.exists:
            import pandas as pd

            self.columns = list(pd.read_csv(out, nrows=0).columns)
        self.last = self._clock()

    def add(self, rows: list[dict]) -> None:
        """Take one cell's rows; write the waiting rows if `interval` seconds have passed."""
        keys = sorted(set().union(*rows))
        if self.columns is None:
            self.columns = keys  # a new file: its header is the first cell's columns, sorted
        elif keys != sorted(self.columns):
            raise ValueError(f"the rows of this cell have columns {keys}, but {self.out} has {self.columns}; "
                             "write to a new file")
        self.rows.extend(rows)
        if self._clock() - self.last >= self.interval:
            self.flush()

    def flush(self) -> None:
        """Write the waiting rows (with the header if the file is new)."""
        self.last = self._clock()
        if not self.rows:
            return
        import pandas as pd

        frame = pd.DataFrame(self.rows, columns=self.columns)
        frame.to_csv(self.out, mode="a" if self.exists else "w", header=not self.exists, index=False)
        self.exists, self.rows = True, []


def _batches(pending: list[tuple[str, dict]], group: Callable | None) -> list[list[tuple[str, dict]]]:
    """The pending cells in the calls of the task: one each, or those of one `group` key together (first-seen order)."""
    if group is None:
        return [[item] for item in pending]
    if not callable(group):
        raise TypeError(f"group must be callable, cell -> hashable key or None; got {type(group).__name__}")
    batches: dict[object, list[tuple[str, dict]]] = {}
    for cid, cell in pending:
        key = group(dict(cell))
        try:
            batches.setdefault(("cell", cid) if key is None else ("group", key), []).append((cid, cell))
        except TypeError:
            raise TypeError(f"group(cell) must return a hashable key or None; cell {cid} gave {key!r}") from None
    return list(batches.values())


def _labelled(task: Callable, batch: list[tuple[str, dict]], grouped: bool = False) -> list[list[dict]]:
    """Run the task on a batch of cells (one, unless `grouped`) and label each cell's rows with the cell."""
    if grouped:
        out = task([dict(cell) for _, cell in batch])
        if not isinstance(out, list) or len(out) != len(batch):
            raise TypeError(f"a grouped task must return one list of rows per cell ({len(batch)}); "
                            f"got {type(out).__name__} for the cells from {batch[0][0]}")
    else:
        out = [task(dict(cell)) for _, cell in batch]
    labelled = []
    for (cid, cell), rows in zip(batch, out):
        if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
            raise TypeError(f"task must return a non-empty list of row dicts; cell {cid} gave {type(rows).__name__}")
        labelled.append([{**row, **cell, CELL_COLUMN: cid} for row in rows])
    return labelled


def _results(batches: list[list[tuple[str, dict]]], task: Callable, workers: int, scheduler: str | None,
             grouped: bool = False):
    """Yield each batch's list of its cells' labelled rows, in completion order."""
    if not batches:
        return
    if scheduler is None and workers == 0:
        for batch in batches:
            yield _labelled(task, batch, grouped)
        return
    distributed = require("distributed", "sweeps on Dask (run_sweep with workers or scheduler)")
    with dask_client(workers, scheduler) as client:
        futures = [client.submit(_labelled, task, batch, grouped, pure=False, priority=len(batches) - i,
                                 key=f"cells-{i}-{hashlib.sha1(batch[0][0].encode()).hexdigest()}")
                   for i, batch in enumerate(batches)]  # in the order given: longest first
        # the results are gathered in the background, not by one round trip per cell from this thread
        for future, rows in distributed.as_completed(futures, with_results=True, loop=client.loop):
            future.release()
            yield rows


@contextlib.contextmanager
def dask_client(workers: int, scheduler: str | None = None) -> Iterator[Any]:
    """A Dask client on a local cluster of single-threaded worker processes, or on a running scheduler.

    The one place where mascore starts Dask workers: ``run_sweep``, ``mascore compare``
    and ``mascore reproduce --workers`` all use it. The local workers start with one BLAS
    thread (Dask's nanny) and the C library's memory allocator settings, as a serial run
    with ``OMP_NUM_THREADS=1``, so a task computes the same numbers in a worker as in this
    process. A script that starts them without ``if __name__ == "__main__":`` gets one
    line that says so (each worker process imports the main module again).

    Parameters
    ----------
    workers : int
        Local worker processes (>= 1); ignored when `scheduler` is given.
    scheduler : str, optional
        Address of a running Dask scheduler (``"tcp://HOST:8786"``).

    Yields
    ------
    distributed.Client
        The client (not the default client of the process); it and the local cluster are
        closed when the ``with`` block ends, on an error too.

    Raises
    ------
    RuntimeError
        The local workers could not start from a script without a main guard (the message
        says how to fix it).
    ValueError
        `workers` is not a positive integer (without `scheduler`).

    Examples
    --------
    >>> from mascore.sweep import dask_client
    >>> with dask_client(2) as client:                        # doctest: +SKIP
    ...     client.submit(sum, [1, 2]).result()
    3
    """
    distributed = require("distributed", "running on Dask (workers or scheduler)")
    if scheduler is not None:
        client = distributed.Client(scheduler, set_as_default=False)
        cluster = None
    else:
        import dask

        workers = check_positive_int(workers, "workers")
        with dask.config.set(_LOCAL_CLUSTER_CONFIG):
            try:
                # no dashboard; the scheduler's HTTP endpoint on a free local port (not 8787, which another
                # cluster on the machine may hold)
                cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                   dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": False},
                                                   silence_logs=40)
            except RuntimeError as exc:
                if not _unguarded_main(exc):
                    raise
                raise RuntimeError(_NO_MAIN_GUARD) from None
        client = distributed.Client(cluster, set_as_default=False)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


#: Dask's settings for the local cluster of :func:`dask_client` (set for its start only: the workers take them).
#:
#: - Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which also fixes glibc's mmap threshold
#:   at 128 kB: every larger array is then mapped and unmapped, and its pages faulted in again (the N = 64 cells
#:   of the comparison ran 35-60 % slower, most of it in the kernel, than in a serial run). The workers start
#:   with the C library's defaults, like a serial run.
#: - The cluster has no dashboard, so nothing reads Dask's own monitoring: the workers' statistical profiler
#:   (a stack sample of the running task every 10 ms), the system monitor (CPU, memory and disk every 0.5 s),
#:   the nanny's memory check every 0.1 s and the event loops' 20-ms health tick. They cost an idle cluster of
#:   two workers about 13 % of a core (client, scheduler and nannies 5 %, each worker 4 %), taken from the
#:   sweep on a machine whose cores run the workers; with the profiler off and the rest at 1-5 s, under 2 %.
_LOCAL_CLUSTER_CONFIG = MappingProxyType({
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.admin.system-monitor.disk": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
})


#: What to do when local Dask workers fail to start from a script without a main guard.
_NO_MAIN_GUARD = ("local Dask workers could not start: the script that starts them must put its code under "
                  "`if __name__ == \"__main__\":` (each worker process imports the main module again); "
                  "or pass workers=0 to run serially")


def _unguarded_main(exc: BaseException) -> bool:
    """Whether a failure to start local workers is the spawn of a main module without ``__main__`` guard."""
    text = "".join(str(e) for e in (exc, exc.__cause__, exc.__context__) if e is not None)
    return any(key in text for key in ("Nanny failed to start", "bootstrapping phase", "freeze_support"))


def demo_task(cell: Mapping[str, Any]) -> list[dict[str, Any]]:
    """A tiny task for examples and tests: two draws scaled by the cell's ``scale``.

    Parameters
    ----------
    cell : mapping
        Coordinates with ``scale`` (a number) and ``block`` (the seed axis).

    Returns
    -------
    list of dict
        One row ``{"value": ...}``: the mean of two standard normal draws from
        :func:`cell_seed` on ``block`` (so cells of equal ``block`` share them), times ``scale``.

    Examples
    --------
    >>> from mascore.sweep import demo_task
    >>> demo_task({"scale": 2.0, "block": 0})[0]["value"] == 2 * demo_task({"scale": 1.0, "block": 0})[0]["value"]
    True
    """
    draws = np.random.default_rng(cell_seed(cell, ["block"])).standard_normal(2)
    return [{"value": float(cell["scale"] * draws.mean())}]
