"""The comparison's figures (compute and draw apart: each takes the summary)."""

from __future__ import annotations

import numpy as np

from .benchmark import CORE_METHODS, NOISES
from .tables import fitted_slopes


def _plt():
    from .._optional import require

    return require("matplotlib.pyplot", "the comparison's figures")


def plot_pareto(summary):
    """Accuracy against communication: RMSE ratio to the centralized filter vs floats sent per step.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.

    Returns
    -------
    matplotlib.figure.Figure
        One point per method and team size (scaling study), with 95 % intervals.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> summary = pd.DataFrame({"study": "scaling", "method": ["centralized", "local"], "n_agents": 8,
    ...                         "floats": [24.0, 4.0], "ratio_mean": [1.0, 1.4], "ratio_lo": [1.0, 1.38],
    ...                         "ratio_hi": [1.0, 1.42]})
    >>> compare.plot_pareto(summary).axes[0].get_ylabel()
    'own-position RMSE / centralized (log scale)'
    """
    plt = _plt()
    base = summary[summary["study"] == "scaling"]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    sizes = sorted(base["n_agents"].unique())
    for i, m in enumerate(CORE_METHODS):
        g = base[base["method"] == m]
        if g.empty:
            continue
        jitter = 1 + 0.06 * (np.searchsorted(sizes, g["n_agents"]) - (len(sizes) - 1) / 2)
        x = (g["floats"] + 1) * jitter
        ax.errorbar(x, g["ratio_mean"], yerr=[g["ratio_mean"] - g["ratio_lo"], g["ratio_hi"] - g["ratio_mean"]],
                    fmt="o", color=f"C{i}", label=m, capsize=2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("floats sent per agent per step + 1 (log scale; points of one method: N = "
                  + ", ".join(map(str, sizes)) + ")")
    ax.set_ylabel("own-position RMSE / centralized (log scale)")
    _plain_ticks(ax)
    top = float(base["ratio_hi"].max())
    ax.set_yticks([t for t in (1, 1.25, 1.5, 2, 3, 4, 6, 8) if t <= top * 1.05])
    ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    return fig


def plot_cost(summary, slopes: dict | None = None):
    """CPU per agent per step against team size, log-log, with the fitted slopes.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.
    slopes : dict, optional
        Method -> CPU slope in N (:attr:`CompareResult.slopes`); fitted here if not given.

    Returns
    -------
    matplotlib.figure.Figure
        One line per method (scaling study).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> summary = pd.DataFrame({"study": "scaling", "method": "local", "n_agents": [4, 8, 16],
    ...                         "cpu_us": [0.4, 0.8, 1.6]})
    >>> compare.plot_cost(summary).axes[0].get_legend_handles_labels()[1]     # a slope of 1: linear in N
    ['local (slope 1.00)']
    """
    plt = _plt()
    slopes = fitted_slopes(summary) if slopes is None else slopes
    base = summary[summary["study"] == "scaling"]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for i, m in enumerate(CORE_METHODS):
        g = base[base["method"] == m]
        if g.empty:
            continue
        ax.loglog(g["n_agents"], g["cpu_us"], "o-", color=f"C{i}", label=f"{m} (slope {slopes[m]:.2f})")
    ax.set_xlabel("team size N")
    ax.set_ylabel("CPU per agent per step and run (µs)")
    ax.set_xticks(sorted(base["n_agents"].unique()))
    _plain_ticks(ax)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


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
