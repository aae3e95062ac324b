"""The comparison's figures (compute and draw apart: each takes the summary)."""

from __future__ import annotations

import numpy as np

from .benchmark import CORE_METHODS, NOISES, POSITION_METHODS, SHARED_METHODS
from .target import target_methods


def _plt():
    from .._optional import require

    return require("matplotlib.pyplot", "the comparison's figures")


#: The scenarios of :func:`plot_pareto`: task -> (its study in the sweep, the bound's name, what is scored).
PARETO_SCENARIOS = {
    "team": ("scaling", "centralized", "own-position RMSE"),
    "position": ("position", "centralized", "own-position RMSE"),
    "target": ("target", "centralized", "target-position RMSE"),
    "localization": ("localization", "centralized", "own-position RMSE"),
    "shared": ("shared", "central fusion", "RMSE"),
}


def _pareto_methods(task: str) -> tuple[str, ...]:
    if task == "team":
        return CORE_METHODS
    if task == "position":
        return POSITION_METHODS
    if task == "shared":
        return SHARED_METHODS
    return target_methods(task)


def plot_pareto(summary, task: str = "team"):
    """Accuracy against communication: RMSE ratio to the bound vs floats sent and received per agent and step.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.
    task : {"team", "position", "target", "localization", "shared"}
        The scenario (:data:`PARETO_SCENARIOS`): its study's cells on the ring without drop-outs
        (Gaussian noise), every method at its recipe, every team size the sweep holds.

    Returns
    -------
    matplotlib.figure.Figure
        One point per method and team size, with 95 % intervals; the floats are those of
        :func:`floats_per_step` (:func:`target_cost` for the target and localization tasks),
        a centralized filter's counted up and down.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> summary = pd.DataFrame({"study": "scaling", "method": ["centralized", "local"], "n_agents": 8,
    ...                         "graph": "ring", "dropout": 0.0, "noise": "gaussian",
    ...                         "floats": [24.0, 4.0], "ratio_mean": [1.0, 1.4], "ratio_lo": [1.0, 1.38],
    ...                         "ratio_hi": [1.0, 1.42]})
    >>> compare.plot_pareto(summary).axes[0].get_ylabel()
    'own-position RMSE / centralized (log scale)'
    """
    if task not in PARETO_SCENARIOS:
        raise ValueError(f"task must be one of {tuple(PARETO_SCENARIOS)}; got {task!r}")
    plt = _plt()
    study, bound, scored = PARETO_SCENARIOS[task]
    base = summary[(summary["study"] == study) & (summary["graph"] == "ring") & (summary["dropout"] == 0.0)
                   & (summary["noise"] == "gaussian")]
    if base.empty:
        raise ValueError(f"summary has no row of the study {study!r} on the ring (rerun the sweep: grid_cells)")
    methods = [m for m in _pareto_methods(task) if m in set(base["method"])]
    fig, ax = plt.subplots(figsize=(7, 5))
    sizes = sorted(base["n_agents"].unique())
    colours = plt.get_cmap("tab10" if len(methods) <= 10 else "tab20")
    for i, m in enumerate(methods):
        g = base[base["method"] == m]
        jitter = 1 + 0.06 * (np.searchsorted(sizes, g["n_agents"]) - (len(sizes) - 1) / 2)
        x = (g["floats"] + 1) * jitter
        ax.errorbar(x, g["ratio_mean"], yerr=[g["ratio_mean"] - g["ratio_lo"], g["ratio_hi"] - g["ratio_mean"]],
                    fmt="o", color=colours(i), label=m, capsize=2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("floats sent and received per agent per step + 1 (log scale; N = "
                  + ", ".join(map(str, sizes)) + ")")
    ax.set_ylabel(f"{scored} / {bound} (log scale)")
    _plain_ticks(ax)
    top = float(base.loc[base["method"].isin(methods), "ratio_hi"].max())
    ticks = (1, 1.25, 1.5, 2, 3, 4, 6, 8) if top < 10 else (1, 1.5, 2, 3, 5, 10, 20, 50, 100, 200, 500, 1000)
    ax.set_yticks([t for t in ticks if t <= top * 1.05])
    ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
    _legend_below(fig, ax)
    return fig


def plot_cost(costs, task: str = "team"):
    """One agent's CPU per step (one run, one thread) against team size, log-log, with the fitted slopes.

    Parameters
    ----------
    costs : pandas.DataFrame
        :func:`mascore.agent_cost.agent_costs`' table (or the committed snapshot,
        :func:`per_agent_costs`): the numbers of the headline tables' CPU column.
    task : {"team", "target", "localization"}
        The scenario.

    Returns
    -------
    matplotlib.figure.Figure
        One line per method of the task (the centre's step for a centralized filter), each
        labelled with its slope over the three largest N measured.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> costs = pd.DataFrame({"task": "team", "method": "local", "n_agents": [4, 8, 16],
    ...                       "us_per_step": [10.0, 20.0, 40.0], "flops": [1.0, 2.0, 4.0]})
    >>> compare.plot_cost(costs).legends[0].get_texts()[0].get_text()     # a slope of 1: linear in N
    'local (slope 1.00)'
    """
    from ..agent_cost import slopes as fitted

    plt = _plt()
    rows = costs[costs["task"] == task].dropna(subset=["us_per_step"])
    if rows.empty:
        raise ValueError(f"costs has no measured row of the task {task!r}")
    slope = fitted(rows, top=3)["slope"]
    fig, ax = plt.subplots(figsize=(7, 5))
    methods = list(dict.fromkeys(rows["method"]))
    colours = plt.get_cmap("tab10" if len(methods) <= 10 else "tab20")
    for i, m in enumerate(methods):
        g = rows[rows["method"] == m].sort_values("n_agents")
        ax.loglog(g["n_agents"], g["us_per_step"], "o-", color=colours(i),
                  label=f"{m} (slope {slope[(task, m)]:.2f})")
    ax.set_xlabel("team size N")
    ax.set_ylabel("one agent's CPU per step (µs)")
    ax.set_xticks(sorted(rows["n_agents"].unique()))
    _plain_ticks(ax)
    _legend_below(fig, ax)
    return fig


def plot_scale(summary, task: str = "target", grid: str = "quick"):
    """Accuracy against team size: each method's RMSE ratio to the centralized filter, one panel per graph.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`: the study `task`'s cells without drop-outs, every team size and
        graph the sweep holds (the full grid: N = 8 to 64 on the ring, geometric and switching graphs).
    task : {"target", "localization"}
        The scenario.
    grid : str
        The sweep the summary comes from, named in the figure's title.

    Returns
    -------
    matplotlib.figure.Figure
        One panel per graph of the summary (ring, geometric, switching), N on a log axis, the ratio
        (log scale) with its 95 % interval; a method stops at the largest N it was run at
        (:func:`mascore.estimation.agent_limits`).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> summary = pd.DataFrame({"study": "target", "task": "target", "method": "ci-L1", "graph": "ring",
    ...                         "dropout": 0.0, "n_agents": [8, 16], "ratio_mean": [1.3, 1.4],
    ...                         "ratio_lo": [1.28, 1.37], "ratio_hi": [1.32, 1.43]})
    >>> [ax.get_title() for ax in compare.plot_scale(summary).axes]
    ['ring']
    """
    if task not in ("target", "localization"):
        raise ValueError(f"task must be 'target' or 'localization'; got {task!r}")
    plt = _plt()
    rows = summary[(summary["study"] == task) & (summary["task"] == task) & (summary["dropout"] == 0.0)]
    if rows.empty:
        raise ValueError(f"summary has no row of the study {task!r} (rerun the sweep: grid_cells)")
    graphs = [g for g in ("ring", "geometric", "switching") if g in set(rows["graph"])]
    methods = [m for m in target_methods(task) if m in set(rows["method"])]
    sizes = sorted(rows["n_agents"].unique())
    fig, axes = plt.subplots(1, len(graphs), figsize=(3.6 * len(graphs) + 0.8, 4.4), sharey=True, squeeze=False)
    colours = plt.get_cmap("tab10" if len(methods) <= 10 else "tab20")
    for ax, graph in zip(axes[0], graphs):
        for i, m in enumerate(methods):
            g = rows[(rows["graph"] == graph) & (rows["method"] == m)].sort_values("n_agents")
            if not g.empty:
                ax.errorbar(g["n_agents"], g["ratio_mean"], fmt="o-", color=colours(i), label=m, capsize=2, ms=4,
                            yerr=[g["ratio_mean"] - g["ratio_lo"], g["ratio_hi"] - g["ratio_mean"]])
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(sizes)
        ax.set_title(graph)
        ax.set_xlabel("team size N")
        ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
        _plain_ticks(ax)
    axes[0, 0].set_ylabel(f"{PARETO_SCENARIOS[task][2]}\n/ centralized (log scale)")  # two lines: within the axes
    fig.suptitle(f"{task}: the {grid} grid", fontsize=10)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    for ax in axes[0, 1:]:  # a method absent from the first panel
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    ncol = min(6, len(labels))
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.045 * -(-len(labels) // ncol) + 0.02, 1, 1))
    return fig


def _legend_below(fig, ax, ncol: int = 4) -> None:
    """The axes' legend under the panel, off the data, in rows of at most `ncol` entries that fit its width."""
    handles, labels = ax.get_legend_handles_labels()
    ncol = max(1, min(ncol, 110 // (max(map(len, labels)) + 8)))  # about 110 characters of 8 pt across 7 in
    rows = -(-len(labels) // ncol)
    fig.legend(handles, labels, loc="lower center", ncol=min(ncol, len(labels)), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.055 * rows + 0.01, 1, 1))


def plot_robustness(summary):
    """Own-position RMSE (m) under drop-outs, noise distributions and a wrong Q, at N = 8.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.

    Returns
    -------
    matplotlib.figure.Figure
        Three panels: RMSE against the drop-out probability, against the noise
        distribution, and against ``q_scale``.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> rows = [("scaling", "gaussian", 0.0, 1.0), ("dropout", "gaussian", 0.3, 1.0),
    ...         ("noise", "uniform", 0.0, 1.0), ("wrong-q", "gaussian", 0.0, 10.0)]
    >>> summary = pd.DataFrame([{"study": st, "task": "team", "method": "local", "n_agents": 8, "noise": nz,
    ...                          "dropout": p, "q_scale": q, "rmse_own_mean": 0.05, "rmse_own_lo": 0.049}
    ...                         for st, nz, p, q in rows])
    >>> [ax.get_xlabel() for ax in compare.plot_robustness(summary).axes]
    ['link drop-out probability', 'noise distribution', 'filter Q / true Q']
    """
    plt = _plt()
    team = summary[(summary["task"] == "team") & (summary["n_agents"] == 8)]
    base = team[team["study"] == "scaling"]
    fig, axes = plt.subplots(1, 3, figsize=(11, 4.2), sharey=True)
    panels = (("dropout", "dropout", "link drop-out probability"), ("noise", "noise", "noise distribution"),
              ("wrong-q", "q_scale", "filter Q / true Q"))
    for ax, (study, col, label) in zip(axes, panels):
        frame = team[team["study"] == study]
        for i, m in enumerate(CORE_METHODS):
            g = _concat(base[base["method"] == m], frame[frame["method"] == m]).sort_values(col, key=_order(col))
            if g.empty:
                continue
            x = np.arange(len(g)) if col == "noise" else g[col]
            ax.errorbar(x, g["rmse_own_mean"], yerr=g["rmse_own_mean"] - g["rmse_own_lo"], fmt="o-", color=f"C{i}",
                        label=m, capsize=2)
            if col == "noise":
                ax.set_xticks(np.arange(len(g)), g["noise"])
        if col == "q_scale":
            ax.set_xscale("log")
            ax.set_xticks(sorted(frame[col].unique().tolist() + [1.0]))
            ax.xaxis.set_major_formatter("{x:g}")
        ax.set_xlabel(label)
    axes[0].set_ylabel("own-position RMSE (m, log scale)")
    axes[0].set_yscale("log")
    axes[0].set_yticks([0.03, 0.04, 0.05, 0.07, 0.1, 0.15])
    axes[0].yaxis.set_major_formatter("{x:g}")
    axes[0].yaxis.set_minor_formatter("")
    handles, labels = axes[0].get_legend_handles_labels()
    ncol = (len(labels) + 1) // 2  # two rows, so that the legend is no wider than the column
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.13 if ncol < len(labels) else 0.07, 1, 1))
    return fig


def _plain_ticks(ax) -> None:
    """Tick labels as plain numbers (1, 2, 4, 16) on log axes, not powers of ten."""
    from matplotlib.ticker import FuncFormatter

    fmt = FuncFormatter(lambda v, _: f"{v:g}")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(fmt)
        axis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def _concat(*frames):
    import pandas as pd

    return pd.concat(frames, ignore_index=True)


def _order(col: str):
    if col == "noise":
        return lambda s: s.map({n: i for i, n in enumerate(NOISES)})
    return None


def plot_send_on_delta(summary, links, task: str = "target"):
    """Send-on-delta's trade: RMSE ratio against the floats actually sent, per threshold, for CI and ICF.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize` (the methods sending at every step).
    links : pandas.DataFrame
        Output of :func:`link_summary`, with the studies ``send-on-delta-<delta>`` (:func:`send_on_delta_table`).
    task : {"target", "localization"}
        The scenario.

    Returns
    -------
    matplotlib.figure.Figure
        One line per method from its every-step point (delta 0) to its largest threshold, each point
        labelled with its delta, 95 % intervals on the ratio.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> s = pd.DataFrame({"study": ["target", "send-on-delta-1"], "task": "target", "method": "ci-L1",
    ...                   "n_agents": 8, "graph": "ring", "dropout": 0.0, "floats": [14.0, 3.1],
    ...                   "ratio_mean": [1.3, 1.5], "ratio_lo": 1.2, "ratio_hi": 1.6, "nees_own_mean": 0.6})
    >>> compare.plot_send_on_delta(s[:1], s[1:]).axes[0].get_xlabel()
    'floats sent per agent per step (log scale)'
    """
    from .tables import send_on_delta_table

    plt = _plt()
    t = send_on_delta_table(summary, links, task)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, (method, g) in enumerate(t.groupby(level="method", sort=False)):
        g = g.droplevel("method")
        ax.errorbar(g["floats/agent/step"], g["RMSE ratio"], yerr=[g["RMSE ratio"] - g["lo"], g["hi"] - g["RMSE ratio"]],
                    fmt="o-", color=f"C{i}", label=method, capsize=2)
        for d, row in g.iterrows():
            ax.annotate(f"δ = {d:g}", (row["floats/agent/step"], row["RMSE ratio"]), textcoords="offset points",
                        xytext=(6, 6), fontsize=9, color=f"C{i}")
    ax.set_xscale("log")
    ax.set_xlabel("floats sent per agent per step (log scale)")
    ax.set_ylabel("RMSE / centralized")
    _plain_ticks(ax)
    lo, hi = float(t["floats/agent/step"].min()), float(t["floats/agent/step"].max())
    ax.set_xticks([v for v in (0.5, 1, 2, 3, 5, 7, 10, 14, 20, 30, 50, 100, 150, 300) if 0.8 * lo <= v <= 1.25 * hi])
    ax.set_xlim(0.8 * lo, 1.25 * hi)
    _legend_below(fig, ax, ncol=2)
    return fig
