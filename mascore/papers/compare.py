"""The comparison of the methods as a study: its figures, tables and claims, on the same contract as the papers.

The computation is :mod:`mascore.compare` (scenarios, sweep, tables, verdicts, figures); this module
declares it as the chapter "Comparing the methods" and its ledger ``results/compare/claims.json``
(:data:`REGISTRY`, a comparison: :func:`mascore.registry.comparison_registries`).
"""

from __future__ import annotations

from ..compare.benchmark import SETTINGS
from ..compare.cost import per_agent_costs
from ..compare.grid import CompareResult, run
from ..compare.plots import plot_cost, plot_pareto, plot_robustness
from ..compare.tables import headline, knob_table
from ..compare.verdicts import compare_claims
from ..registry import FigureSpec, PaperRegistry, Study, TableSpec

__all__ = ["FIGURES", "REGISTRY", "SETTINGS", "STUDY", "TABLES", "claims", "run"]

def claims(result: CompareResult) -> list:
    """The comparison's ledger (``compare/...`` claims), as :func:`mascore.compare.run` decided them (``result.claims``).

    Parameters
    ----------
    result : CompareResult
        The output of :func:`run`.

    Returns
    -------
    list of mascore.ledger.Claim
        The claims with their computed verdicts.

    Examples
    --------
    >>> from mascore.papers import compare
    >>> [c.id for c in compare.claims(compare.run())][:1]  # doctest: +SKIP
    ['compare/centralized-bound']
    """
    return list(result.claims) if result.claims else compare_claims(result.table, phi=result.phi)


def _costs():
    """One agent's CPU per step, the committed snapshot (:func:`mascore.compare.per_agent_costs`); None without it."""
    try:
        return per_agent_costs()
    except FileNotFoundError:
        return None


FIGURES = (
    FigureSpec("pareto", "", "Accuracy against communication, own state: each method's own-position RMS error over "
               "the centralized filter's on the same runs (with 95 % paired bootstrap intervals) against the floats "
               "it sends and receives per agent and step, for N = 4, 8 and 16 on the ring.",
               lambda r: plot_pareto(r.summary)),
    *(FigureSpec(f"pareto_{task}", "", f"Accuracy against communication, {name}: each method's RMS error over "
                 f"the {bound}'s on the same runs (95 % paired bootstrap intervals) against the floats it sends "
                 "and receives per agent and step, on the ring.", lambda r, task=task: plot_pareto(r.summary, task))
      for task, name, bound in (("target", "common target", "centralized filter"),
                                ("localization", "cooperative localization", "centralized filter"),
                                ("shared", "shared quantity", "central fusion"))),
    FigureSpec("cost", "", "One agent's CPU per step (one run, one thread; the centre's step for the centralized "
               "filter) against the team size, log-log, with each method's slope over the three largest teams: "
               "the numbers of the headline tables' CPU column.", lambda r: plot_cost(per_agent_costs())),
    FigureSpec("robustness", "", "Own-position RMSE at N = 8 under link drop-outs, other noise distributions and a "
               "wrong process-noise covariance in the filters, beside the baseline.",
               lambda r: plot_robustness(r.summary)),
)

TABLES = (
    TableSpec("headline", "", "Own state (the case where cooperation cannot help), per method at N = 8: RMSE ratio "
              "to the centralized filter, consistency, floats sent and received, one agent's CPU per step (one run, "
              "one thread), control spread, and the slope of that CPU in N.", lambda r: headline(r.summary, costs=_costs()).reset_index()),
    TableSpec("headline_target", "", "Common target, per method at N = 8 on the ring: RMSE ratio to the centralized "
              "filter, consistency, floats sent and received, one agent's CPU per step and its flops; the papers' methods that do "
              "not apply, with the reason.", lambda r: headline(r.summary, "target", _costs()).reset_index()),
    TableSpec("headline_localization", "", "Cooperative localization, per method at N = 8 on the ring: RMSE ratio of "
              "each agent's own position to the centralized filter's, consistency, floats sent and received, one agent's CPU "
              "per step and its flops; the papers' methods that do not apply, with the reason.",
              lambda r: headline(r.summary, "localization", _costs()).reset_index()),
    TableSpec("headline_shared", "", "Shared quantity (Ren et al.'s task), per method at N = 8: RMSE ratio to the "
              "central fusion, consistency, floats sent and received per agent and step.",
              lambda r: headline(r.summary, "shared", _costs()).reset_index()),
    TableSpec("headline_position", "", "Own state with positions only, per method at N = 8: RMSE ratio to the "
              "centralized filter, consistency or containment, the set-membership set's size and its containment "
              "under bounded noise, floats sent and received per agent and step; Song et al.'s filters as not applicable.",
              lambda r: headline(r.summary, "position", _costs()).reset_index()),
    TableSpec("knobs", "", "Every knob swept within its recipe at N = 8 on the ring: per setting, the RMSE ratio to "
              "the bound, consistency, a verdict on each (from its interval), and the verdicts that flip between "
              "the knob's settings.", lambda r: knob_table(r.summary)),
    TableSpec("summary", "", "Means and 95 % intervals of every metric per condition of the sweep, with the "
              "ratio to the bound.", lambda r: r.summary),
)

#: The chapter "Comparing the methods": the sweep, its figures, tables and ledger.
STUDY = Study("compare", "comparing_methods", SETTINGS, run, FIGURES, TABLES, claims)

#: The comparison's registry: its ledger is ``results/compare/claims.json`` (``python -m mascore compare``).
REGISTRY = PaperRegistry("compare", "Comparing the methods", studies=(STUDY,), position=5, kind="comparison")
