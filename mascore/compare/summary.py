"""The summary of a sweep's table: per group, means with intervals, the RMS-error ratio to the bound, the ANEES's bounds.

Below the grid and the claims, which both read it (:func:`summarize`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..settings import check_settings_type
from .benchmark import SETTINGS, BenchmarkSettings
from .scenario import nees_dimension, reference_method
from .stats import anees_bounds, mean_interval, rms_ratio

__all__ = ["summarize"]


def summarize(table, by: Sequence[str] = ("study", "task", "method", "graph", "n_agents", "noise", "dropout",
                                         "q_scale"), settings: BenchmarkSettings = SETTINGS):
    """Means and 95 % intervals per group, the RMS-error ratio to the bound, and the ANEES's chi-square bounds.

    The accuracy is the ratio of RMS errors over the group's runs, the method's against the
    reference's (the task's centralized filter, ``central-fusion`` on the shared task, or a scenario's
    ``reference``) on the same seed blocks and runs, with its
    95 % paired bootstrap interval (``mascore.compare.stats.rms_ratio``). The consistency is
    the ANEES (the mean over runs of the per-run NEES per dof) with a bootstrap interval and the
    two-sided 95 % chi-square bounds of a consistent filter for the group's runs and the task's
    NEES dimension (``mascore.compare.stats.anees_bounds``). The other metrics: mean and
    normal-approximation 95 % interval over runs.

    Parameters
    ----------
    table : pandas.DataFrame
        Rows of :func:`~mascore.compare.run_cell` with their cell coordinates and ``cell`` identifier
        (the sweep's table).
    by : sequence of str
        Grouping columns.
    settings : BenchmarkSettings
        The benchmark's settings (its step counts give the CPU per step).

    Returns
    -------
    pandas.DataFrame
        One row per group: ``n`` runs, ``n_diverged`` of them with a non-finite error (left out of
        the means and the ratio, and counted here), and ``mean``/``lo``/``hi`` of
        ``rmse_own``, ``nees_own``, ``containment``, ``spread``, ``rmse_far``,
        ``set_size`` (NaN where the table has none); ``ratio_mean``/``lo``/``hi``:
        the ratio of RMS errors to the bound and its interval; ``nees_bound_lo``/``hi``:
        the ANEES's chi-square bounds; plus ``floats`` and ``cpu_us`` (CPU per agent per
        step and run, µs). A group whose task's reference has no rows has NaN ratios.

    Raises
    ------
    ValueError
        A table without rows or without the columns named, an empty `by`, or a task that is
        neither built in nor a scenario's.
    TypeError
        `table` is not a DataFrame, or `by` not a sequence of names.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare import run_cell, summarize
    >>> cell = {"study": "scaling", "task": "team", "n_agents": 4, "noise": "gaussian", "dropout": 0.0,
    ...         "q_scale": 1.0, "block": 0}
    >>> rows = [{**r, **cell, "method": m, "cell": m} for m in ("centralized", "local")
    ...         for r in run_cell({**cell, "method": m})]
    >>> s = summarize(pd.DataFrame(rows))
    >>> bool((s.set_index("method").loc["local", "ratio_mean"] > 1.0))      # no cooperation costs accuracy
    True
    """
    import pandas as pd

    check_settings_type(settings, BenchmarkSettings)
    if not isinstance(table, pd.DataFrame):
        raise TypeError(f"table must be a pandas DataFrame of run_cell rows (the sweep's table); "
                        f"got {type(table).__name__}")
    if isinstance(by, str) or not isinstance(by, Sequence):
        raise TypeError(f"by must be a sequence of column names; got {by!r}")
    by = list(by)
    if not by:
        raise ValueError("by must name at least one grouping column (default: study, task, method, ...)")
    needed = {"task", "method", "n_agents", "cell", "block", "run", "rmse_own", "cpu_s", "floats", "nees_own",
              "containment", "spread"} | set(by) - {"graph"}
    missing = sorted(needed - set(table.columns))
    if missing:
        raise ValueError(f"table lacks the columns {missing} (rows of run_cell with their cell coordinates; "
                         f"by = {by})")
    if table.empty:
        raise ValueError("table has no rows: nothing to summarize (run the sweep's cells first)")
    t = table.copy()
    if "graph" not in t:
        t["graph"] = "ring"
    for col in ("rmse_far", "set_size"):  # tables of before these metrics
        if col not in t:
            t[col] = np.nan
    references = {task: reference_method(task) for task in t["task"].unique()}
    bound = t[t["method"] == t["task"].map(references)]
    keys = [c for c in by if c != "method"] + ["block", "run"]
    ref = bound.set_index(keys)["rmse_own"].rename("bound_rmse")
    t = t.join(ref, on=keys)
    steps = np.where(t["task"] == "shared", settings.shared_steps, settings.n_steps)
    t["cpu_us"] = 1e6 * t["cpu_s"] / (t["n_agents"] * steps * t.groupby("cell")["run"].transform("size"))
    out, memo = [], {}  # memo: the bootstrap's resamples, drawn once per number of runs in this call
    # the runs of every group in one order, (block, run): the bootstrap pairs them (sorted once, each group keeps it)
    t = t.sort_values(["block", "run"], kind="stable")
    for key, g in t.groupby(by, sort=False, dropna=False):
        row = dict(zip(by, key if isinstance(key, tuple) else (key,)))
        row["n"] = len(g)
        row["n_diverged"] = int((~np.isfinite(g["rmse_own"].to_numpy(float))).sum())  # left out of the statistics
        for col in ("rmse_own", "ratio", "nees_own", "containment", "spread", "rmse_far", "set_size"):
            if col == "ratio":
                m, lo, hi = rms_ratio(g["rmse_own"].to_numpy(), g["bound_rmse"].to_numpy(), memo=memo)
            elif col == "nees_own":
                m, lo, hi = mean_interval(g[col].to_numpy(), memo=memo)
            else:
                m, half = _mean_ci(g[col].to_numpy())
                lo, hi = m - half, m + half
            row[f"{col}_mean"], row[f"{col}_lo"], row[f"{col}_hi"] = m, lo, hi
        runs = int(np.isfinite(g["nees_own"].to_numpy()).sum())
        dim = nees_dimension(row.get("task", g["task"].iloc[0]))
        row["nees_bound_lo"], row["nees_bound_hi"] = anees_bounds(runs, dim) if runs and dim else (np.nan, np.nan)
        floats = g["floats"].to_numpy()  # one value per method, but as sent under send-on-delta: their mean
        row["floats"] = float(floats[0]) if (floats == floats[0]).all() else float(floats.mean())
        row["cpu_us"] = float(g["cpu_us"][~g["cell"].duplicated()].median())  # one value per cell
        out.append(row)
    return pd.DataFrame(out).sort_values(by, kind="stable", ignore_index=True)  # N numerically, not as text


def _mean_ci(x: np.ndarray) -> tuple[float, float]:
    """Mean and the half-width of its 95 % normal-approximation interval (NaN-aware)."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan")
    half = 1.96 * x.std(ddof=1) / np.sqrt(x.size) if x.size > 1 else float("nan")
    return float(x.mean()), float(half)
