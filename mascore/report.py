"""The reproduction report: the state of every paper's ledger on one page.

:func:`verdict_summary` counts verdicts per paper; :func:`attention_list` gives one
line for every claim that is approximate, does not reproduce or fails, linked to
its chapter's ledger; :func:`errata_list` gives, per paper, the errata and
readings recorded in its registry. The book's report page shows the three.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from ._optional import require
from .compare.scenario import reference_method
from .formatting import math_text
from .ledger import VERDICTS, deviation_sentence, verdict_words
from .registry import paper_keys, paper_registry

__all__ = ["MarkdownText", "attention_list", "best_methods", "errata_list", "math_text", "method_words",
           "reading_paths", "verdict_summary", "why"]

#: Verdicts the report lists one by one (everything else is counted only).
ATTENTION = ("approximately", "does-not-reproduce", "fails")


@dataclass(frozen=True)
class MarkdownText:
    """Markdown that Jupyter (and the book) renders; ``str()`` gives the text.

    Parameters
    ----------
    text : str
        The Markdown.

    Examples
    --------
    >>> from mascore.report import MarkdownText
    >>> str(MarkdownText("**bold**"))
    '**bold**'
    """

    text: str

    def _repr_markdown_(self) -> str:
        return self.text

    def __str__(self) -> str:
        return self.text


def verdict_summary(records: Sequence[dict]):
    """Claims per paper (rows, book order, by the papers' names) and verdict (columns, in words), with totals.

    Parameters
    ----------
    records : sequence of dict
        Claim records with a ``paper`` key.

    Returns
    -------
    pandas.DataFrame
        Counts, with a total row and column; rows named by the papers' citations
        (``"Ren, Beard and Kingston 2005"``), columns by the verdicts in words (``"does not reproduce"``).

    Examples
    --------
    >>> from mascore.ledger import Claim
    >>> ok = Claim("ren2005/a", "Sec. 2", "A number.", 2.0, 2.01, {"rel": 0.01}).to_dict() | {"paper": "ren2005"}
    >>> off = Claim("ren2005/b", "Sec. 3", "Another.", 2.0, 3.0, {"rel": 0.01}).to_dict() | {"paper": "ren2005"}
    >>> from mascore.report import verdict_summary
    >>> verdict_summary([ok, off]).loc["Ren, Beard and Kingston 2005"].to_dict()
    {'reproduces': 1, 'does not reproduce': 1, 'total': 2}
    """
    pd = require("pandas", "this table")

    _check_records(records, ("paper", "verdict"))
    papers = [p for p in paper_keys() if any(r["paper"] == p for r in records)]
    table = pd.DataFrame(0, index=pd.Index(papers), columns=list(VERDICTS))
    for r in records:
        table.loc[r["paper"], r["verdict"]] += 1
    table = table.loc[:, table.sum() > 0]
    table["total"] = table.sum(axis=1)
    own = [sum(bool(r.get("own_check")) for r in records if r["paper"] == p) for p in papers]
    if any(own):  # the checks of our own that the papers do not state, counted in the verdicts beside them
        table["of them, our own checks"] = own
    table.loc["all papers"] = table.sum()
    table.index = [paper_registry(p).citation if p in papers else p for p in table.index]
    table.columns = [verdict_words(c) if c in VERDICTS else c for c in table.columns]
    return table


def ledger_label(paper: str, study: str) -> str:
    """The MyST target of a chapter's ledger section: ``{paper}-{study}-ledger``."""
    return f"{paper}-{study}-ledger"


def attention_list(records: Sequence[dict]) -> MarkdownText:
    """A table of every claim that is approximate, does not reproduce or fails, linked to its ledger, with why.

    Parameters
    ----------
    records : sequence of dict
        Claim records with a ``paper`` key (:func:`mascore.ledger.load_claims`).

    Returns
    -------
    MarkdownText
        The table (or a sentence when every claim reproduces or holds).

    Examples
    --------
    >>> from mascore.ledger import Claim
    >>> ok = Claim("ren2005/a", "Sec. 2", "A number.", 2.0, 2.01, {"rel": 0.01}).to_dict() | {"paper": "ren2005"}
    >>> off = Claim("ren2005/b", "Sec. 3", "Another.", 2.0, 3.0, {"rel": 0.01}).to_dict() | {"paper": "ren2005"}
    >>> from mascore.report import attention_list
    >>> text = str(attention_list([ok, off]))
    >>> "Another." in text, "A number." in text
    (True, False)
    """
    _check_records(records, ("paper", "verdict", "where", "statement"))
    rows = ["| verdict | paper, where | claim | why |", "|---|---|---|---|"]
    for verdict in ATTENTION:
        for r in (r for r in records if r["verdict"] == verdict):
            reg = paper_registry(r["paper"])
            study = r.get("study") or reg.studies[0].name
            cells = (f"**{verdict_words(verdict)}**", f"{reg.citation}, {r['where']}",
                     f"{math_text(r['statement'])} ({{ref}}`ledger <{ledger_label(r['paper'], study)}>`)",
                     math_text(why(r)))
            rows.append("| " + " | ".join(c.replace("|", "\\|").replace("\n", " ") for c in cells) + " |")
    return MarkdownText("\n".join(rows) if len(rows) > 2 else "Every claim reproduces or holds.")


def _module_whys() -> dict[str, str]:
    """Claim id -> why, from the ``WHY`` mappings of the papers' study modules."""
    from .registry import study_modules

    out: dict[str, str] = {}
    for module in study_modules():
        out |= {k: v for k, v in dict(getattr(module, "WHY", None) or {}).items() if isinstance(v, str)}
    return out


#: Words that mark a note's sentence as a reason (a fallback when a claim states no ``why``).
_REASON = re.compile(r"\b(why|because|systematic|not numerical|rounded|does not determine|no reading|cannot|"
                     r"dominated|indistinguishable|slip|misprint|instead)\b", re.I)


def why(record: dict, max_words: int = 25) -> str:
    """Why a claim does not fully reproduce, in one or two sentences for the report's table.

    For a published number, how far it is off (:func:`mascore.ledger.deviation_sentence`); then the
    claim's own ``why`` when it states one, or the sentence its paper module gives it (a module-level
    ``WHY`` mapping, claim id -> sentence), or else the first sentence of its note that gives a
    reason, cut at `max_words` words (the ledger holds the rest).

    Parameters
    ----------
    record : dict
        A claim record.
    max_words : int
        Longest reason taken from the note.

    Returns
    -------
    str
        The reason.

    Examples
    --------
    >>> from mascore.ledger import Claim
    >>> from mascore.report import why
    >>> off = Claim("ren2005/b", "Sec. 3", "Another.", 2.0, 3.0, {"rel": 0.01},
    ...             note="Ours is run 0. The gap is systematic: the paper rounds.").to_dict()
    >>> print(why(off).replace("\\xa0", " "))
    50 % off; more than the 3 % of 'approximately'. The gap is systematic: the paper rounds.
    """
    deviation = deviation_sentence(record) if record.get("paper_value") is not None else ""
    stated = record.get("why") or _module_whys().get(record.get("id", ""))
    if stated:
        return ". ".join(t for t in (deviation, stated) if t)
    paragraphs = [" ".join(p.split()) for p in (record.get("note") or "").split("\n\n") if p.strip()]
    stated = [p.split(":", 1)[1].strip() for p in paragraphs if re.match(r"Why\b[^:]*:", p)]
    sentences = [s for p in stated + paragraphs for s in re.split(r"(?<=[.;])\s+(?=[A-Z])", p)]
    reason = next((s for s in sentences if _REASON.search(s)), sentences[0] if sentences else "")
    words = reason.split()
    if len(words) > max_words:
        reason = " ".join(words[:max_words]).rstrip(",;:") + " \u2026"
    reason = reason[:1].upper() + reason[1:]
    return ". ".join(t for t in (deviation, reason) if t)


def errata_list(papers: Sequence[str] | None = None) -> MarkdownText:
    """Per paper, the errata and readings its registry records, each paper in a collapsed dropdown.

    Parameters
    ----------
    papers : sequence of str, optional
        Paper keys (default all, :func:`mascore.registry.paper_keys`).

    Returns
    -------
    MarkdownText
        MyST dropdowns, one per paper.

    Examples
    --------
    >>> from mascore.report import errata_list
    >>> str(errata_list(["ren2005"])).startswith(":::")
    True
    """
    if papers is not None and (isinstance(papers, str) or not isinstance(papers, Sequence)
                               or not all(isinstance(p, str) for p in papers)):
        raise TypeError(f"papers must be a sequence of paper keys (e.g. ['ren2005']) or None; got {papers!r}")
    blocks = []
    for key in paper_keys() if papers is None else papers:
        reg = paper_registry(key)
        if reg.errata:
            items = "\n".join(f"- {e}" for e in reg.errata)
            blocks.append(f":::{{dropdown}} {reg.citation}: {len(reg.errata)} errata and readings\n"
                          f"{items}\n:::")
    return MarkdownText("\n\n".join(blocks))


def _check_records(records: object, keys: tuple[str, ...]) -> None:
    """`records` as :func:`mascore.ledger.load_claims` gives them: a sequence of dicts with `keys`."""
    if isinstance(records, str | bytes | dict) or not isinstance(records, Sequence):
        raise TypeError(f"records must be a sequence of claim records (dicts, mascore.ledger.load_claims); "
                        f"got {type(records).__name__}")
    for i, r in enumerate(records):
        if not isinstance(r, dict):
            raise TypeError(f"records[{i}] must be a claim record (a dict); got {type(r).__name__}")
        missing = [k for k in keys if k not in r]
        if missing:
            raise ValueError(f"records[{i}] lacks the keys {missing} of a claim record")
        if r["verdict"] not in VERDICTS:
            raise ValueError(f"records[{i}]['verdict'] must be one of {VERDICTS}; got {r['verdict']!r}")


#: The comparison's scenarios in the intro's answer: task, the reader's name, and the study that holds it.
_SCENARIOS = (("team", "own state", "scaling"), ("target", "common target", None),
              ("localization", "cooperative localization", None), ("shared", "shared quantity", None))

#: The bounds of the scenarios (ratio 1 by definition): never a recommendation.
_BOUNDS = tuple({reference_method(task): None for task, _, _ in _SCENARIOS})


def best_methods(summary, n_agents: int = 8, *, exclude: Sequence[str] = (),
                 honest: bool = True) -> dict[str, tuple[str, float]]:
    """Per scenario of the comparison, the method closest to the centralized filter and its RMSE ratio.

    On the ring of `n_agents` without drop-outs (the comparison's headline tables), among the
    methods other than the bound (the centralized filter, or the central fusion of the shared
    quantity) and `exclude` (say, the knob settings other than each paper's own); with `honest`,
    a method whose ANEES lies above its chi-square bound (``nees_bound_hi``) is left out: an
    overconfident filter is not recommended, however close it comes.

    Parameters
    ----------
    summary : pandas.DataFrame
        :func:`mascore.compare.summarize` of the sweep.
    n_agents : int
        Team size of the headline tables.
    exclude : sequence of str
        Methods not to consider (e.g. :func:`mascore.compare.knob_variants`).
    honest : bool
        Leave out the overconfident methods (where the summary has the ANEES and its bounds).

    Returns
    -------
    dict
        Scenario name (``"own state"``, ``"common target"``, ``"cooperative localization"``,
        ``"shared quantity"``) -> (method, RMSE ratio to the bound), for the scenarios in `summary`.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.report import best_methods
    >>> s = pd.DataFrame({"task": "target", "study": "scaling", "graph": "ring", "n_agents": 8, "dropout": 0.0,
    ...                   "method": ["centralized", "local", "ci-L5"], "ratio_mean": [1.0, 1.9, 1.2]})
    >>> best_methods(s)
    {'common target': ('ci-L5', 1.2)}
    """
    frame = summary[(summary["n_agents"] == n_agents) & (summary["dropout"] == 0.0) & (summary["graph"] == "ring")
                    & ~summary["method"].isin([*_BOUNDS, *exclude])]
    if honest and {"nees_own_mean", "nees_bound_hi"} <= set(frame.columns):
        frame = frame[~(frame["nees_own_mean"] > frame["nees_bound_hi"])]  # NaN (no covariance) stays
    out = {}
    for task, name, study in _SCENARIOS:
        rows = frame[(frame["task"] == task) & ((frame["study"] == study) if study else True)]
        rows = rows[rows["ratio_mean"].notna()]
        if len(rows):
            best = rows.loc[rows["ratio_mean"].idxmin()]
            out[name] = (str(best["method"]), float(best["ratio_mean"]))
    return out


#: Abbreviations of the methods' names, as the glossary writes them.
_ACRONYMS = {"ci": "CI", "hcmci": "HCMCI", "icf": "ICF", "kf": "KF", "ekf": "EKF"}


def method_words(name: str) -> str:
    """A comparison method's name as prose writes it: ``"hcmci-L5"`` reads ``"HCMCI with 5 consensus steps"``.

    Parameters
    ----------
    name : str
        The method's name in the comparison's tables (``"ci-diffusion"``, ``"hcmci-L1"``, ``"forwarding"``).

    Returns
    -------
    str
        The name with its abbreviations in capitals and its number of consensus steps in words.

    Examples
    --------
    >>> from mascore.report import method_words
    >>> method_words("hcmci-L5"), method_words("hcmci-L1"), method_words("ci-diffusion"), method_words("forwarding")
    ('HCMCI with 5 consensus steps', 'HCMCI with 1 consensus step', 'CI diffusion', 'forwarding')
    """
    words, steps = [], ""
    for part in name.split("-"):
        if re.fullmatch(r"L\d+", part):
            n = int(part[1:])
            steps = f" with {n} consensus step{'s' if n != 1 else ''}"
        else:
            words.append(_ACRONYMS.get(part, part))
    return " ".join(words) + steps


def reading_paths(records: Sequence[dict], best: dict[str, tuple[str, float]] | None = None,
                  apply_examples: Sequence[str] = ()) -> MarkdownText:
    """The intro's four questions, each with its page and a one-line answer computed from the results.

    Parameters
    ----------
    records : sequence of dict
        The papers' claim records (:func:`mascore.ledger.load_claims`).
    best : dict, optional
        :func:`best_methods` of the comparison's sweep; None when the sweep has not been run.
    apply_examples : sequence of str
        Titles of the apply chapter's worked examples.

    Returns
    -------
    MarkdownText
        A Markdown list with links to the pages ({doc} roles from the book's root).

    Examples
    --------
    >>> from mascore.ledger import Claim
    >>> from mascore.report import reading_paths
    >>> ok = Claim("ren2005/a", "Sec. 2", "A number.", 2.0, 2.01, {"rel": 0.01}).to_dict() | {"paper": "ren2005"}
    >>> print(str(reading_paths([ok])).splitlines()[0].split(" ({doc}")[0])
    - **Did it reproduce?** All 1 published claims reproduce or hold
    """
    _check_records(records, ("paper", "verdict"))
    own = [r for r in records if r.get("own_check")]  # checks of our own, which the papers do not state
    records = [r for r in records if not r.get("own_check")]
    good = sum(r["verdict"] in ("reproduces", "holds") for r in records)
    near = sum(r["verdict"] == "approximately" for r in records)
    open_ = sum(bool(r.get("undecided")) for r in records)  # failed because their data cannot decide them
    bad = len(records) - good - near - open_
    if good == len(records):
        verdict = f"All {len(records)} published claims reproduce or hold"
    else:
        undecided = f", {open_} not shown (their intervals cross the edge of their bands)" if open_ else ""
        verdict = (f"{good} of {len(records)} published claims reproduce or hold, {near} approximately{undecided}, "
                   f"{bad} do not reproduce or fail")
    if own:
        verdict += (f"; beside them, {sum(r['verdict'] == 'holds' for r in own)} of {len(own)} checks of our own "
                    "hold")
    if good < len(records):
        verdict += "; the report says which and why"
    lines = [f"- **Did it reproduce?** {verdict} "
             f"({{doc}}`the reproduction report </notebooks/reproduction_report>`)."]
    if best:
        closest = "; ".join(f"{name}: {method_words(m)}, RMSE {ratio:.2f} times the centralized filter's"
                            for name, (m, ratio) in best.items())
        lines.append(f"- **Which method for my team?** It depends on what the team estimates. Closest to the "
                     f"centralized filter on a ring of 8 agents, among the methods whose ANEES is not above its 95 % "
                     f"chi-square bound: {closest}. Larger teams and other graphs can change the answer "
                     f"({{ref}}`the comparison's decision table <decision-table>` and its scenario pages).")
    else:
        lines.append("- **Which method for my team?** The comparison puts every method on the same problems "
                     "({doc}`comparing the methods </notebooks/comparing_methods>`).")
    examples = f": {len(apply_examples)} worked examples ({'; '.join(apply_examples)})" if apply_examples else ""
    lines.append(f"- **How do I use it on my system?** Each method on a system of our own, in a few lines of "
                 f"code, each ending with the theory's check{examples} "
                 f"({{doc}}`apply it to your own system </notebooks/apply_your_system>`).")
    papers = []
    for key in paper_keys():
        reg = paper_registry(key)
        mine = [r for r in records if r["paper"] == key]
        ok = sum(r["verdict"] in ("reproduces", "holds") for r in mine)
        links = ", ".join(f"{{doc}}`{s.name.replace('-', ' ').capitalize()} </notebooks/{s.chapter}>`" for s in reg.studies)
        papers.append(f"{reg.citation} ({links}: {ok} of {len(mine)} claims reproduce or hold)")
    lines.append("- **How does paper X work?** Each paper has its chapter, its derivation and its ledger: "
                 + "; ".join(papers) + ".")
    return MarkdownText("\n".join(lines))
