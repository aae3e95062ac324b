"""The comparison of the methods as a study: its figures, tables and claims, on the same contract as the papers.

The computation is :mod:`mascore.compare` (scenarios, sweep, tables, verdicts, figures); this module
declares it as the chapter "Comparing the methods" and its ledger ``results/compare/claims.json``
(:data:`REGISTRY`, a comparison: :func:`mascore.registry.comparison_registries`).
"""

from __future__ import annotations

from ..compare.benchmark import SETTINGS
from ..compare.grid import CompareResult, run
from ..compare.plots import plot_cost, plot_pareto, plot_robustness
from ..compare.tables import headline
from ..compare.verdicts import compare_claims
from ..registry import FigureSpec, PaperRegistry, Study, TableSpec

__all__ = ["FIGURES", "REGISTRY", "SETTINGS", "STUDY", "TABLES", "claims", "run"]

def claims(result: CompareResult) -> list:
    """The comparison's ledger (``compare/...`` claims), from `result` alone (:func:`mascore.compare.compare_claims`).

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
    return compare_claims(result.table, phi=result.phi)


FIGURES = (
    FigureSpec("pareto", "", "Accuracy against communication: each method's own-position RMS error over the "
               "centralized filter's on the same runs (with 95 % paired bootstrap intervals) against the floats it sends per agent and step, for "
               "N = 4, 8 and 16 on the ring.", lambda r: plot_pareto(r.summary)),
    FigureSpec("cost", "", "CPU time per agent, step and run against the team size, log-log, with each method's "
               "fitted slope: the whole-team filters grow much faster than the per-agent ones.",
               lambda r: plot_cost(r.summary, r.slopes)),
    FigureSpec("robustness", "", "Own-position RMSE at N = 8 under link drop-outs, other noise distributions and a "
               "wrong process-noise covariance in the filters, beside the baseline.",
               lambda r: plot_robustness(r.summary)),
)

TABLES = (
    TableSpec("headline", "", "Own state (the case where cooperation cannot help), per method at N = 8: RMSE ratio "
              "to the centralized filter, consistency, floats sent and CPU per agent and step, control spread, and "
              "the CPU slope in N.", lambda r: headline(r.summary).reset_index()),
    TableSpec("headline_target", "", "Common target, per method at N = 8 on the ring: RMSE ratio to the centralized "
              "filter, consistency, floats sent, CPU and flops per agent and step; the papers' methods that do "
              "not apply, with the reason.", lambda r: headline(r.summary, "target").reset_index()),
    TableSpec("headline_localization", "", "Cooperative localization, per method at N = 8 on the ring: RMSE ratio of "
              "each agent's own position to the centralized filter's, consistency, floats sent, CPU and flops per "
              "agent and step; the papers' methods that do not apply, with the reason.",
              lambda r: headline(r.summary, "localization").reset_index()),
    TableSpec("headline_shared", "", "Shared quantity (Ren et al.'s task), per method at N = 8: RMSE ratio to the "
              "central fusion, consistency, floats sent and CPU per agent and step.",
              lambda r: headline(r.summary, "shared").reset_index()),
    TableSpec("headline_position", "", "Own state with positions only, per method at N = 8: RMSE ratio to the "
              "centralized filter, consistency or containment, the set-membership set's size and its containment "
              "under bounded noise, floats sent and CPU per agent and step; Song et al.'s filters as not applicable.",
              lambda r: headline(r.summary, "position").reset_index()),
    TableSpec("summary", "", "Means and 95 % intervals of every metric per condition of the sweep, with the "
              "ratio to the bound.", lambda r: r.summary),
)

#: The chapter "Comparing the methods": the sweep, its figures, tables and ledger.
STUDY = Study("compare", "comparing_methods", SETTINGS, run, FIGURES, TABLES, claims)

#: The comparison's registry: its ledger is ``results/compare/claims.json`` (``python -m mascore compare``).
REGISTRY = PaperRegistry("compare", "Comparing the methods", studies=(STUDY,), position=5, kind="comparison")
