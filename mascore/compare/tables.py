"""The headline tables: accuracy, consistency, messages and cost per method and scenario."""

from __future__ import annotations

import numpy as np

from .. import estimation
from .benchmark import KNOBS, SETTINGS, SHOWN, BenchmarkSettings
from .target import target_cost, target_methods


def fitted_slopes(summary) -> dict[str, float]:
    """Log-log slope of CPU per agent per step against N, per method (scaling study).

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.

    Returns
    -------
    dict of str to float
        Method to the least-squares slope of ``log(cpu_us)`` on ``log(N)`` (methods run at two team
        sizes or more).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare import fitted_slopes
    >>> s = pd.DataFrame({"study": "scaling", "method": "x", "n_agents": [4, 8, 16], "cpu_us": [1.0, 4.0, 16.0]})
    >>> round(fitted_slopes(s)["x"], 6)
    2.0
    """
    scaling = summary[summary["study"] == "scaling"]
    return {m: float(np.polyfit(np.log(g["n_agents"]), np.log(g["cpu_us"]), 1)[0])
            for m, g in scaling.groupby("method", sort=False) if g["n_agents"].nunique() > 1}  # a knob: N = 8 only


def headline(summary, task: str = "team", costs=None):
    """The practitioner's table of one scenario: accuracy, consistency, messages and cost per method.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.
    task : {"team", "position", "target", "localization", "shared"} or str
        The scenario (or one declared in its own module, ``mascore.compare.scenario``, at the cells
        of its ``headline``): ``"team"``, own state at N = 8 on the ring (the case where cooperation
        cannot help: forwarding the neighbours' measurements of an agent already is the
        centralized filter); ``"position"``, the same with position-only sensing (the study
        ``position``, Gaussian noise; its own table, :func:`_position_headline`); ``"target"``,
        the common target at N = 8 on the ring; ``"shared"``,
        Ren et al.'s shared quantity at N = 8 without drop-outs.
    costs : pandas.DataFrame, optional
        One agent's CPU per step, one run, one thread (:func:`mascore.agent_cost.agent_costs`'
        table, or the committed snapshot :func:`per_agent_costs`): the column
        ``CPU µs/agent-step`` at N = 8 (the centre's step for a centralized filter; a dash
        where the method's agent step is not measured: the position and shared tasks), and for
        the team task the slope in N of that time over the three largest teams measured.
        Without it the table has no CPU column (the sweep's batch CPU is not one agent's).

    Returns
    -------
    pandas.DataFrame
        Per method: the ratio of RMS errors to the bound's with its 95 % paired bootstrap
        interval over the runs (200 seeds on the quick grid), consistency (the ANEES and whether
        it lies inside its 95 % chi-square bounds, ``consistency_text``; or containment for
        the set-membership filter), floats sent and received per agent and step (a centralized
        filter's: each agent's measurements up and the estimates it uses down), one agent's CPU
        per step if `costs` is given, and per scenario: the control spread (team), the analytic
        flops per agent and step (target, localization). A dash where a quantity does not exist;
        methods that do not apply are listed with the reason.

    Examples
    --------
    On the quick sweep (what ``python -m mascore compare`` prints):

    >>> from mascore import compare
    >>> table, summary = compare.run_compare("quick", "results", workers=2)  # doctest: +SKIP
    >>> compare.headline(summary).loc["song-eb", "floats/step"]  # doctest: +SKIP
    0.0
    """
    import pandas as pd

    from .scenario import scenarios

    new = scenarios()
    tasks = ("team", "position", "target", "localization", "shared", *new)
    if task not in tasks:
        raise ValueError(f"task must be one of {tasks}; got {task!r}")
    if task == "position":
        return _position_headline(summary, costs)
    dash = "—"
    where = new[task].headline if task in new else {"n_agents": 8, "dropout": 0.0, "graph": "ring"}
    frame = summary[summary["task"] == task]
    for coordinate, value in where.items():
        if coordinate in frame:  # a summary without a graph column: the ring
            frame = frame[frame[coordinate] == value]
    if task == "team":
        frame = frame[frame["study"] == "scaling"]
    frame = frame.set_index("method")
    methods = target_methods(task) if task in ("target", "localization") else new[task].methods() if task in new \
        else estimation.method_names(task, SHOWN)
    cpu = _agent_cpu(costs, task)
    slopes = _agent_slopes(costs, task)
    rows = []
    for m in methods:
        if m not in frame.index:
            continue
        r = frame.loc[m]
        consistency = consistency_text(r)
        row = {"method": m, "RMSE ratio [95 %]": ratio_text(r),
               "seeds": int(r["n"]), "consistency": consistency, "floats/step": r["floats"]}
        if cpu is not None:
            row[CPU_COLUMN] = _cpu_cell(cpu, m)
        if task == "team":
            row["spread (m)"] = round(r["spread_mean"], 3)
            row["non-neighbours' RMSE (m)"] = round(r["rmse_far_mean"], 3) if np.isfinite(r["rmse_far_mean"]) else dash
            if slopes is not None:
                row["CPU slope in N"] = round(float(slopes[m]), 2) if m in slopes.index else dash
        if task in ("target", "localization"):
            row["flops/agent/step"] = round(target_cost(m, 8, 2, task)[1])
        rows.append(row)
    if task in ("target", "localization"):
        for m, why in estimation.not_applicable(task).items():
            rows.append({"method": m, "RMSE ratio [95 %]": "not applicable", "seeds": 0, "consistency": why,
                         "floats/step": dash, **({CPU_COLUMN: dash} if cpu is not None else {}),
                         "flops/agent/step": dash})
    out = pd.DataFrame(rows).set_index("method")
    return out.astype({"seeds": int})


#: The one CPU column of every table and figure: one agent's step, one run, one thread (µs).
CPU_COLUMN = "CPU µs/agent-step"


def _agent_cpu(costs, task: str):
    """Method -> one agent's µs per step at N = 8 for `task` (None without `costs`; empty where not measured)."""
    if costs is None:
        return None
    rows = costs[(costs["task"] == task) & (costs["n_agents"] == 8)]
    return rows.set_index("method")["us_per_step"]


def _agent_slopes(costs, task: str):
    """Method -> slope in N of one agent's time over the three largest N measured (team task only; else None)."""
    if costs is None or task != "team":
        return None
    from ..agent_cost import slopes

    return slopes(costs[costs["task"] == "team"], top=3).loc["team", "slope"]


def _cpu_cell(cpu, method: str):
    """One agent's µs per step, 3 significant digits, or a dash where it is not measured."""
    value = cpu.get(method, np.nan)
    return float(f"{value:.3g}") if np.isfinite(value) else "—"


def _position_headline(summary, costs=None):
    """:func:`headline` of the study ``position``: the own state at N = 8, positions only.

    Per method of :data:`POSITION_METHODS` (Gaussian noise, 200 seeds): the RMSE ratio to the
    centralized filter (same data) with its 95 % interval, the NEES per dof or the set's
    containment, the set's largest position semi-axis (m), the containment under uniform
    (bounded) noise, floats (with `costs`, a dash for the CPU per agent: these agents' steps are
    not measured); Song et al.'s filters as not applicable, with the reason.
    """
    import pandas as pd

    dash = "—"
    pos = summary[(summary["study"] == "position") & (summary["task"] == "team")]
    if pos.empty:
        raise ValueError("summary has no row of the study 'position' (grid_cells holds it; rerun the sweep)")
    gauss = pos[pos["noise"] == "gaussian"].set_index("method")
    uniform = pos[pos["noise"] == "uniform"].set_index("method")
    size = gauss["set_size_mean"] if "set_size_mean" in gauss else pd.Series(np.nan, gauss.index)
    rows = []
    not_applicable = estimation.not_applicable("position")
    for m in (m for m in estimation.method_names("team") if m not in not_applicable):
        if m not in gauss.index:
            continue
        r = gauss.loc[m]
        bounded = uniform["containment_mean"].get(m, np.nan)
        rows.append({
            "method": m, "RMSE ratio [95 %]": f"{r['ratio_mean']:.3f} [{r['ratio_lo']:.3f}, {r['ratio_hi']:.3f}]",
            "consistency": consistency_text(r),
            "set size (m)": round(float(size[m]), 3) if np.isfinite(size[m]) else dash,
            "contains, uniform": f"{bounded:.3f}" if np.isfinite(bounded) else dash,
            "floats/step": r["floats"], **({CPU_COLUMN: dash} if costs is not None else {})})
    for m, why in not_applicable.items():
        rows.append({"method": m, "RMSE ratio [95 %]": "not applicable", "consistency": why,
                     "set size (m)": dash, "contains, uniform": dash, "floats/step": dash,
                     **({CPU_COLUMN: dash} if costs is not None else {})})
    return pd.DataFrame(rows).set_index("method")


def consistency_text(row) -> str:
    """A summary row's consistency in words: the ANEES and its verdict against the chi-square bounds.

    Parameters
    ----------
    row : pandas.Series
        A row of :func:`mascore.compare.summarize` (``nees_own_mean``, ``nees_bound_lo``/``hi``,
        ``containment_mean``).

    Returns
    -------
    str
        ``"ANEES 1.02, consistent"`` (inside its 95 % chi-square bounds), ``"..., overconfident"`` (above),
        ``"..., conservative"`` (below); the containment for a set-valued filter; a dash without either.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare.tables import consistency_text
    >>> consistency_text(pd.Series({"nees_own_mean": 1.3, "nees_bound_lo": 0.87, "nees_bound_hi": 1.14,
    ...                             "containment_mean": float("nan")}))
    'ANEES 1.30, overconfident'
    """
    nees, inside = row["nees_own_mean"], row["containment_mean"]
    if np.isfinite(nees):
        word = anees_verdict(row)
        text = f"ANEES {nees:.2f}" if nees < 100 else f"ANEES {nees:.1e}"
        return f"{text}, {word}" if word != "—" else f"{text} (no chi-square bounds: no NEES dimension)"
    return f"contains {inside:.3f}" if np.isfinite(inside) else "—"


def ratio_text(row) -> str:
    """A summary row's RMSE ratio with its 95 % paired bootstrap interval, as the tables show it.

    Parameters
    ----------
    row : pandas.Series
        A row of :func:`mascore.compare.summarize` (``ratio_mean``, ``ratio_lo``, ``ratio_hi``).

    Returns
    -------
    str
        ``"1.023 [1.011, 1.036]"``; a dash for a cell without a ratio.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare.tables import ratio_text
    >>> ratio_text(pd.Series({"ratio_mean": 1.0234, "ratio_lo": 1.0111, "ratio_hi": 1.0362}))
    '1.023 [1.011, 1.036]'
    """
    if not np.isfinite(row["ratio_mean"]):
        return "—"
    return f"{row['ratio_mean']:.3f} [{row['ratio_lo']:.3f}, {row['ratio_hi']:.3f}]"


def interval_table(frame, columns: str, methods=None, quantity: str = "ratio", order=None):
    """Methods against one axis of the sweep, each cell a ratio with its interval or a consistency verdict.

    The tables of the comparison beside the headline ones (another graph, drop-outs) in the same
    terms: every RMSE ratio with its 95 % paired bootstrap interval (:func:`ratio_text`), every
    ANEES with its verdict against its 95 % chi-square bounds (``consistency_text``).

    Parameters
    ----------
    frame : pandas.DataFrame
        Rows of :func:`mascore.compare.summarize`, at most one per method and value of `columns`.
    columns : str
        The summary's column whose values become the table's columns (``"graph"``, ``"dropout"``).
    methods : sequence of str, optional
        The rows, in order (default: the methods of `frame`, sorted); a method without a row is left out.
    quantity : {"ratio", "consistency"}
        What a cell shows.
    order : sequence, optional
        The columns, in order (default: the values of `columns` in `frame`, sorted); a value the
        frame does not hold is a column of dashes.

    Returns
    -------
    pandas.DataFrame
        One row per method, one column per value of `columns`; a dash where the sweep has no cell.

    Raises
    ------
    ValueError
        An unknown `quantity`, `columns` not a column of `frame`, or two rows for one cell.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare.tables import interval_table
    >>> s = pd.DataFrame({"method": ["ci-L1", "ci-L1"], "graph": ["ring", "switching"], "ratio_mean": [1.2, 1.5],
    ...                   "ratio_lo": [1.1, 1.4], "ratio_hi": [1.3, 1.6]})
    >>> interval_table(s, "graph").loc["ci-L1"].tolist()
    ['1.200 [1.100, 1.300]', '1.500 [1.400, 1.600]']
    """
    if quantity not in ("ratio", "consistency"):
        raise ValueError(f"quantity must be 'ratio' or 'consistency'; got {quantity!r}")
    if columns not in frame:
        raise ValueError(f"columns must name a column of frame ({list(frame.columns)}); got {columns!r}")
    if frame.duplicated(["method", columns]).any():
        raise ValueError(f"frame has two rows for one method and {columns}: select one cell each (task, N, study)")
    text = ratio_text if quantity == "ratio" else consistency_text
    cells = frame.assign(cell=frame.apply(text, axis=1) if len(frame) else "")
    out = cells.pivot(index="method", columns=columns, values="cell")
    shown = sorted(out.index) if methods is None else [m for m in methods if m in out.index]
    return out.reindex(index=shown, columns=out.columns if order is None else list(order)).astype(object).fillna("—")


def anees_verdict(row) -> str:
    """``"consistent"`` if a summary row's ANEES lies inside its 95 % chi-square bounds, else over/conservative.

    ``"—"`` where there is no ANEES or no bounds (a set filter, or a scenario that records no NEES).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare.tables import anees_verdict
    >>> anees_verdict(pd.Series({"nees_own_mean": 0.8, "nees_bound_lo": 0.87, "nees_bound_hi": 1.14}))
    'conservative'
    """
    nees, lo, hi = row["nees_own_mean"], row["nees_bound_lo"], row["nees_bound_hi"]
    if not (np.isfinite(nees) and np.isfinite(lo) and np.isfinite(hi)):
        return "—"
    return "overconfident" if nees > hi else "conservative" if nees < lo else "consistent"


def position_only_kf_rmse(settings: BenchmarkSettings = SETTINGS) -> tuple[float, float]:
    """Steady-state posterior position RMSE (m) of a discrete Kalman filter per agent: (position only, full state).

    From the DARE of one axis, ``[p, v]`` with ``C = [1 0]`` or ``C = I``: the independent reference for the
    Vlahakis observer, which its design (``m < n``) gives the position only.
    """
    import scipy.linalg as sla

    s = settings
    A = np.array([[1.0, s.dt], [0.0, 1.0]])
    Q = np.diag([s.q_pos, s.q_vel])
    out = []
    for C in (np.array([[1.0, 0.0]]), np.eye(2)):
        R = s.r * np.eye(C.shape[0])
        prior = sla.solve_discrete_are(A.T, C.T, Q, R)
        post = prior - prior @ C.T @ np.linalg.solve(C @ prior @ C.T + R, C @ prior)
        out.append(float(np.sqrt(2 * post[0, 0])))  # two axes
    return out[0], out[1]


#: The accuracy band of the knob table's verdict: an RMSE within 5 % of the bound's.
NEAR_BOUND = 1.05


def knob_table(summary):
    """Every knob swept within its recipe (:data:`KNOBS`), a verdict per setting, and whether a verdict flips.

    Each setting's row is its method's summary row at N = 8 on the ring without drop-outs, in the
    study that holds it (Gaussian noise). Two verdicts per setting, each from an interval, never
    from a point: **accuracy**, ``"within 5 %"`` of the bound if the 95 % interval of the RMSE
    ratio lies below :data:`NEAR_BOUND`, ``"not within 5 %"`` if it lies above, else
    ``"undecided"``; **consistency**, the ANEES against its two-sided 95 % chi-square bounds
    (``anees_verdict``, as in the headline tables: ``"consistent"`` inside, ``"overconfident"``
    above, ``"conservative"`` below; for the set-membership filter ``"contains"`` if its
    containment reaches its confidence, else ``"leaks"``; a dash for an observer without a covariance).

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize` of a sweep that holds the knobs' cells (:func:`grid_cells`).

    Returns
    -------
    pandas.DataFrame
        One row per knob and setting: ``knob``, ``scenario``, ``setting`` (``*``: the paper's own,
        the headline's), ``method``, ``seeds``, ``RMSE ratio [95 %]``, ``consistency`` (the ANEES or
        the containment, ``consistency_text``), the two verdicts, and ``flips``: the verdicts that differ between
        the knob's settings (``"no"`` when none does). Settings whose cells the sweep lacks are left out.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> rows = [dict(study="shared", task="shared", method=m, n_agents=8, graph="ring", dropout=0.0,
    ...              noise="gaussian", n=100, ratio_mean=r, ratio_lo=r - 0.01, ratio_hi=r + 0.01, nees_own_mean=v,
    ...              nees_bound_lo=0.8, nees_bound_hi=1.2, containment_mean=float("nan"))
    ...         for m, r, v in (("ren-kc-q0", 1.0, 1e17), ("ren-kc", 0.98, 4.2), ("ren-kc-q0.6", 1.02, 0.75))]
    >>> t = compare.knob_table(pd.DataFrame(rows))
    >>> t["setting"].tolist(), t["consistency verdict"].tolist()
    (['0', '0.1 *', '0.6'], ['overconfident', 'overconfident', 'conservative'])
    >>> t["flips"].unique().tolist()                      # the knob decides whether Ren's P is honest
    ['consistency']
    """
    import pandas as pd

    from .benchmark import SM_CONFIDENCE

    base = summary[(summary["n_agents"] == 8) & (summary["graph"] == "ring") & (summary["dropout"] == 0.0)
                   & (summary["noise"] == "gaussian")]
    rows = []
    for knob in KNOBS:
        found = []
        for setting, study, method in knob.settings:
            hit = base[(base["study"] == study) & (base["task"] == knob.task) & (base["method"] == method)]
            if hit.empty:
                continue
            r = hit.iloc[0]
            found.append({
                "knob": knob.name, "scenario": knob.task,
                "setting": setting + (" *" if setting in knob.recipe else ""), "method": method,
                "seeds": int(r["n"]),
                "RMSE ratio [95 %]": f"{r['ratio_mean']:.3f} [{r['ratio_lo']:.3f}, {r['ratio_hi']:.3f}]",
                "consistency": consistency_text(r),
                "accuracy verdict": _interval_verdict(r["ratio_lo"], r["ratio_hi"], NEAR_BOUND,
                                                      ("within 5 %", "not within 5 %")),
                "consistency verdict": _consistency_verdict(r, float(setting) if method in SM_CONFIDENCE else None)})
        for verdict in ("accuracy", "consistency"):
            values = {row[f"{verdict} verdict"] for row in found} - {"—", "undecided"}
            for row in found:
                row.setdefault("flips", [])
                if len(values) > 1:
                    row["flips"].append(verdict)
        for row in found:
            row["flips"] = ", ".join(row["flips"]) or "no"
        rows.extend(found)
    return pd.DataFrame(rows)


def _interval_verdict(lo: float, hi: float, band: float, words: tuple[str, str]) -> str:
    """``words[0]`` if the interval lies below `band`, ``words[1]`` if above, else ``"undecided"``."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "—"
    return words[0] if hi <= band else words[1] if lo > band else "undecided"


def _consistency_verdict(r, confidence: float | None) -> str:
    """The ANEES against its chi-square bounds (``anees_verdict``), or a set's containment against its confidence."""
    if confidence is not None:
        inside = r["containment_mean"]
        return "—" if not np.isfinite(inside) else "contains" if inside >= confidence else "leaks"
    return anees_verdict(r)


def link_table(summary, links, task: str = "target", text: bool = False):
    """Accuracy and consistency of each method over lossy and late links, beside ideal links (N = 8, ring).

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize` (its ideal-link rows of `task`).
    links : pandas.DataFrame
        Output of :func:`link_summary`, with the studies ``loss`` and ``latency`` (:data:`LINK_STUDIES`).
    task : {"target", "localization"}
        The scenario.
    text : bool
        The table as the book shows it: one row per method and links that were run (index
        ``(method, links)``), with the ratio and its 95 % paired bootstrap interval (``RMSE ratio
        [95 %]``, :func:`ratio_text`) and the ANEES with its verdict against its 95 % chi-square
        bounds (``consistency``, or the containment of a set-valued filter). Default: the means.

    Returns
    -------
    pandas.DataFrame
        One row per method (table order); columns ``(quantity, links)``: ``RMSE ratio`` (to the
        centralized filter, which keeps ideal links) and ``NEES/dof``, for ideal links (the task's
        own study), each packet loss (``loss p``: a link lost in both directions; ``one-way loss p``:
        each message lost alone, study ``loss-direction``), and one-step latency at each loss the
        summary holds; NaN where a cell was not run (the quick grid runs loss for a few methods only).
        With `text`, the long table described there.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> s = pd.DataFrame({"study": ["target", "loss"], "task": "target", "method": "ci-L1", "n_agents": 8,
    ...                   "graph": "ring", "dropout": [0.0, 0.3], "ratio_mean": [1.3, 1.4], "nees_own_mean": 0.7})
    >>> compare.link_table(s[:1], s[1:]).columns.tolist()
    [('RMSE ratio', 'ideal'), ('RMSE ratio', 'loss 0.3'), ('NEES/dof', 'ideal'), ('NEES/dof', 'loss 0.3')]
    """
    import pandas as pd

    from .target import LINK_STUDIES

    if task not in ("target", "localization"):
        raise ValueError(f"task must be 'target' or 'localization'; got {task!r}")
    s = pd.concat([summary[summary["study"] == task], links[links["study"].isin(LINK_STUDIES)]])
    s = s[(s["task"] == task) & (s["n_agents"] == 8) & (s["graph"] == "ring")]
    ideal = s[(s["study"] == task) & (s["dropout"] == 0.0)].assign(links="ideal")
    lossy = s[s["study"] == "loss"].assign(links=lambda d: [f"loss {p:g}" for p in d["dropout"]])
    one_way = s[s["study"] == "loss-direction"].assign(links=lambda d: [f"one-way loss {p:g}" for p in d["dropout"]])
    late = s[s["study"] == "latency"].assign(links=lambda d: [f"late, loss {p:g}" for p in d["dropout"]])
    if lossy.empty and late.empty:
        raise ValueError(f"summary has no cell of the studies 'loss' or 'latency' ({tuple(LINK_STUDIES)[:2]}) for "
                         f"{task!r}: rerun the sweep (grid_cells)")
    rows = pd.concat([ideal, lossy, one_way, late])
    order = [links for links in dict.fromkeys(rows["links"])]
    methods = [m for m in target_methods(task) if m in set(lossy["method"]) | set(late["method"]) | set(one_way["method"])]
    if text:
        rows = rows[rows["method"].isin(methods)]
        place = {m: k for k, m in enumerate(methods)}, {links: k for k, links in enumerate(order)}
        rows = rows.iloc[np.lexsort((rows["links"].map(place[1]), rows["method"].map(place[0])))]
        return pd.DataFrame({"RMSE ratio [95 %]": rows.apply(ratio_text, axis=1).to_numpy(),
                             "consistency": rows.apply(consistency_text, axis=1).to_numpy()},
                            index=pd.MultiIndex.from_frame(rows[["method", "links"]]))
    out = {name: rows.pivot_table(index="method", columns="links", values=col).reindex(index=methods, columns=order)
           for name, col in (("RMSE ratio", "ratio_mean"), ("NEES/dof", "nees_own_mean"))}
    return pd.concat(out, axis=1)


def send_on_delta_table(summary, links, task: str = "target", loss: float = 0.0, latency: int = 0):
    """Send-on-delta: floats sent, accuracy and consistency of CI and ICF per threshold (N = 8, ring).

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize` (its ideal-link rows of `task`: the methods sending at every step).
    links : pandas.DataFrame
        Output of :func:`link_summary`, with the studies ``send-on-delta-<delta>``.
    task : {"target", "localization"}
        The scenario.
    loss : float
        0: ideal links. Else the one-way packet loss (each message lost alone): the studies
        ``lossy-send-on-delta-<delta>`` and, for ``delta`` 0, ``loss-direction`` at that loss.
    latency : {0, 1}
        1: every message one step late: the studies ``late-send-on-delta-<delta>`` and, for
        ``delta`` 0, ``latency`` (at `loss` 0).

    Returns
    -------
    pandas.DataFrame
        Rows ``(method, delta)`` (``delta`` 0: the method sending at every step, from the task's own
        study or, with `loss`, ``loss-direction``, with `latency`, ``latency``); columns
        ``floats/agent/step`` (as sent), ``RMSE ratio`` with its 95 %
        interval ``lo``, ``hi``, and ``NEES/dof``.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> s = pd.DataFrame({"study": ["target", "send-on-delta-1"], "task": "target", "method": "ci-L1",
    ...                   "n_agents": 8, "graph": "ring", "dropout": 0.0, "floats": [14.0, 3.1],
    ...                   "ratio_mean": [1.3, 1.5], "ratio_lo": 1.2, "ratio_hi": 1.6, "nees_own_mean": 0.6})
    >>> compare.send_on_delta_table(s[:1], s[1:]).index.tolist()
    [('ci-L1', 0.0), ('ci-L1', 1.0)]
    """
    import pandas as pd

    from .target import LINK_STUDIES, SEND_ON_DELTA_METHODS

    if task not in ("target", "localization"):
        raise ValueError(f"task must be 'target' or 'localization'; got {task!r}")
    lossy, late = bool(loss), bool(latency)
    if lossy and late:
        raise ValueError("send_on_delta_table: loss and latency together have no study; give one of them")
    s = pd.concat([summary[summary["study"] == task], links[links["study"].isin(LINK_STUDIES)]])
    s = s[(s["task"] == task) & (s["n_agents"] == 8) & (s["graph"] == "ring") & (s["dropout"] == float(loss))
          & s["method"].isin(SEND_ON_DELTA_METHODS[1:])]
    delta = {"loss-direction" if lossy else "latency" if late else task: 0.0,
             **{k: v["send_delta"] for k, v in LINK_STUDIES.items()
                if "send_delta" in v and ("loss_model" in v) == lossy and bool(v.get("latency")) == late}}
    s = s[s["study"].isin(delta)].assign(delta=lambda d: d["study"].map(delta))
    if not (s["delta"] > 0).any():
        raise ValueError(f"summary has no send-on-delta cell for {task!r} at loss {loss:g}: rerun the sweep (grid_cells)")
    cols = {"floats": "floats/agent/step", "ratio_mean": "RMSE ratio", "ratio_lo": "lo", "ratio_hi": "hi",
            "nees_own_mean": "NEES/dof"}
    out = s.set_index(["method", "delta"])[list(cols)].rename(columns=cols)
    return out.sort_index(level=["method", "delta"]).rename_axis(["method", "delta"])
