"""The headline tables: accuracy, consistency, messages and cost per method and scenario."""

from __future__ import annotations

import numpy as np

from .benchmark import POSITION_METHODS, POSITION_NOT_APPLICABLE, SETTINGS, SHARED_METHODS, TEAM_METHODS, BenchmarkSettings
from .target import LOCALIZATION_NOT_APPLICABLE, TARGET_NOT_APPLICABLE, target_cost, target_methods


def fitted_slopes(summary) -> dict[str, float]:
    """Log-log slope of CPU per agent per step against N, per method (scaling study).

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.

    Returns
    -------
    dict of str to float
        Method to the least-squares slope of ``log(cpu_us)`` on ``log(N)``.

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
            for m, g in scaling.groupby("method", sort=False)}


def headline(summary, task: str = "team"):
    """The practitioner's table of one scenario: accuracy, consistency, messages and cost per method.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.
    task : {"team", "position", "target", "localization", "shared"}
        The scenario: ``"team"``, own state at N = 8 on the ring (the case where cooperation
        cannot help: forwarding the neighbours' measurements of an agent already is the
        centralized filter); ``"position"``, the same with position-only sensing (the study
        ``position``, Gaussian noise; its own table, :func:`_position_headline`); ``"target"``,
        the common target at N = 8 on the ring; ``"shared"``,
        Ren et al.'s shared quantity at N = 8 without drop-outs.

    Returns
    -------
    pandas.DataFrame
        Per method: the ratio of RMS errors to the bound's with its 95 % paired bootstrap
        interval over the runs (200 seeds on the quick grid), consistency (the ANEES and whether
        it lies inside its 95 % chi-square bounds, :func:`consistency_text`; or containment for
        the set-membership filter), floats sent per agent and step, CPU per agent and step (µs, a batch of
        runs: see the chapter), and per scenario: the control spread and the CPU slope in N
        (team), the analytic flops per agent and step (target). A dash where a quantity does
        not exist; methods that do not apply are listed with the reason.

    Examples
    --------
    On the quick sweep (what ``python -m mascore compare`` prints):

    >>> from mascore import compare
    >>> table, summary = compare.run_compare("quick", "results", workers=2)  # doctest: +SKIP
    >>> compare.headline(summary).loc["song-eb", "floats/step"]  # doctest: +SKIP
    0.0
    """
    import pandas as pd

    if task not in ("team", "position", "target", "localization", "shared"):
        raise ValueError(f"task must be 'team', 'position', 'target', 'localization' or 'shared'; got {task!r}")
    if task == "position":
        return _position_headline(summary)
    dash = "—"
    frame = summary[(summary["task"] == task) & (summary["n_agents"] == 8) & (summary["dropout"] == 0.0)]
    if task == "team":
        frame = frame[frame["study"] == "scaling"]
    frame = frame[frame.get("graph", "ring") == "ring"].set_index("method")
    methods = {"team": TEAM_METHODS, "target": target_methods("target"),
               "localization": target_methods("localization"), "shared": SHARED_METHODS}[task]
    slopes = fitted_slopes(summary) if task == "team" else {}
    rows = []
    for m in methods:
        if m not in frame.index:
            continue
        r = frame.loc[m]
        consistency = consistency_text(r)
        row = {"method": m, "RMSE ratio [95 %]": f"{r['ratio_mean']:.3f} [{r['ratio_lo']:.3f}, {r['ratio_hi']:.3f}]",
               "seeds": int(r["n"]), "consistency": consistency, "floats/step": r["floats"],
               "CPU µs/agent/step": round(r["cpu_us"], 2)}
        if task == "team":
            row["spread (m)"] = round(r["spread_mean"], 3)
            row["non-neighbours' RMSE (m)"] = round(r["rmse_far_mean"], 3) if np.isfinite(r["rmse_far_mean"]) else dash
            row["CPU slope in N"] = round(slopes[m], 2) if m in slopes else dash
        if task in ("target", "localization"):
            row["flops/agent/step"] = round(target_cost(m, 8, 2, task)[1])
        rows.append(row)
    if task in ("target", "localization"):
        reasons = TARGET_NOT_APPLICABLE if task == "target" else LOCALIZATION_NOT_APPLICABLE
        for m, why in reasons.items():
            rows.append({"method": m, "RMSE ratio [95 %]": "not applicable", "seeds": 0, "consistency": why,
                         "floats/step": dash, "CPU µs/agent/step": dash, "flops/agent/step": dash})
    out = pd.DataFrame(rows).set_index("method")
    return out.astype({"seeds": int})


def _position_headline(summary):
    """:func:`headline` of the study ``position``: the own state at N = 8, positions only.

    Per method of :data:`POSITION_METHODS` (Gaussian noise, 200 seeds): the RMSE ratio to the
    centralized filter (same data) with its 95 % interval, the NEES per dof or the set's
    containment, the set's largest position semi-axis (m), the containment under uniform
    (bounded) noise, floats and CPU; Song et al.'s filters as not applicable, with the reason.
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
    for m in POSITION_METHODS:
        if m not in gauss.index:
            continue
        r = gauss.loc[m]
        bounded = uniform["containment_mean"].get(m, np.nan)
        rows.append({
            "method": m, "RMSE ratio [95 %]": f"{r['ratio_mean']:.3f} [{r['ratio_lo']:.3f}, {r['ratio_hi']:.3f}]",
            "consistency": consistency_text(r),
            "set size (m)": round(float(size[m]), 3) if np.isfinite(size[m]) else dash,
            "contains, uniform": f"{bounded:.3f}" if np.isfinite(bounded) else dash,
            "floats/step": r["floats"], "CPU µs/agent/step": round(r["cpu_us"], 2)})
    for m, why in POSITION_NOT_APPLICABLE.items():
        rows.append({"method": m, "RMSE ratio [95 %]": "not applicable", "consistency": why,
                     "set size (m)": dash, "contains, uniform": dash, "floats/step": dash, "CPU µs/agent/step": dash})
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
        word = ("overconfident" if nees > row["nees_bound_hi"] else "conservative" if nees < row["nees_bound_lo"]
                else "consistent")
        return f"ANEES {nees:.2f}, {word}" if nees < 100 else f"ANEES {nees:.1e}, {word}"
    return f"contains {inside:.3f}" if np.isfinite(inside) else "—"


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
