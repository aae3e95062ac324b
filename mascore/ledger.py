"""The reproduction ledger: claims, computed verdicts and the claims.json file.

A :class:`Claim` records what a paper publishes, what mascore computes and a
verdict that is *computed* from the two (never typed in). The format is the
one of ``shared/REPRODUCTION.md``.

Verdict rules
-------------
Quantitative claims (``paper_value`` is a number or a list of numbers) carry a
tolerance ``{"abs": t}`` or ``{"rel": t}`` and a band for "approximately",
``{"abs": t, "approx_abs": a}`` or ``{"rel": t, "approx_rel": a}``; the band
defaults to ``APPROX_FACTOR * t`` = 3t and may be wider only with a stated
``band_reason``. With ``d`` the largest deviation over the entries:

* ``reproduces`` if ``d <= t``;
* ``approximately`` if ``t < d <= a``;
* ``does-not-reproduce`` otherwise.

Qualitative claims (``paper_value`` is ``None``) are built with
:meth:`Claim.qualitative` from a boolean condition evaluated on measured
numbers (the ``rule``); their verdict is ``holds`` or ``fails``.

Every number the book prints in a ledger goes through :func:`format_number`.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._optional import require
from .claims import APPROX_FACTOR, PAPER_DIGITS, VERDICTS, Claim, worst_deviation
from .formatting import format_number, format_value, math_text

__all__ = [
    "APPROX_FACTOR",
    "VERDICTS",
    "Claim",
    "ClaimsView",
    "claims_table",
    "deviation_sentence",
    "format_number",
    "format_value",
    "ledger_summary",
    "load_claims",
    "output_hashes",
    "show_claims",
    "verdict_words",
    "verify_outputs",
    "write_claims",
]

def write_claims(
    claims: Sequence[Claim], path: str | Path, paper: str, seed: int, created_by: str,
    files: dict[str, str] | None = None,
) -> Path:
    """Write ``claims.json`` for one paper; returns the path written.

    Parameters
    ----------
    claims : sequence of Claim
        The paper's claims.
    path : str or pathlib.Path
        Where to write.
    paper : str
        The ledger's key, one of :func:`mascore.registry.ledger_keys`.
    seed : int
        The seed of the run.
    created_by : str
        The command that produced it.
    files : dict of str to str, optional
        The paper directory's figures and tables (relative paths) and their SHA-256
        (:func:`output_hashes`); :func:`verify_outputs` checks them later.

    Returns
    -------
    pathlib.Path
        The path written.

    Examples
    --------
    >>> import json, pathlib, tempfile
    >>> from mascore.ledger import Claim, verify_outputs, write_claims
    >>> c = Claim("ren2005/demo", "Sec. 2", "A demo number.", paper_value=2.0, value=2.01, tolerance={"rel": 0.01})
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> path = write_claims([c], d / "claims.json", "ren2005", 1, "demo", files={})
    >>> verify_outputs(d)["claims"][0]["verdict"]
    'reproduces'
    """
    from . import __version__
    from .registry import ledger_keys

    if paper not in ledger_keys():
        raise ValueError(f"paper must be one of {ledger_keys()}; got {paper!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be the run's non-negative integer seed; got {seed!r}")
    if not isinstance(created_by, str):
        raise TypeError(f"created_by must be the command (a string); got {type(created_by).__name__}")
    if isinstance(claims, str | bytes) or not isinstance(claims, Iterable):
        raise TypeError(f"claims must be a sequence of Claim; got {type(claims).__name__}")
    claims = list(claims)
    if not all(isinstance(c, Claim) for c in claims):
        raise TypeError(f"claims must be a sequence of Claim; got {sorted({type(c).__name__ for c in claims})}")
    ids = [c.id for c in claims]
    foreign = [i for i in ids if not i.startswith(f"{paper}/")]
    if foreign:
        raise ValueError(f"the claims of the {paper} ledger must have ids '{paper}/...'; got {foreign}")
    if len(set(ids)) != len(ids):
        raise ValueError(f"duplicate claim ids: {sorted({i for i in ids if ids.count(i) > 1})}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "paper": paper,
        "seed": int(seed),
        "mascore_version": __version__,
        "created_by": created_by,
        "files": dict(sorted((files or {}).items())),
        "claims": [c.to_dict() for c in claims],
    }
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    return path


def output_hashes(paper_dir: str | Path) -> dict[str, str]:
    """SHA-256 of every file under ``paper_dir/figures`` and ``paper_dir/tables``, by relative path.

    Parameters
    ----------
    paper_dir : str or pathlib.Path
        A paper's results folder.

    Returns
    -------
    dict of str to str
        Relative path -> hex digest.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from mascore.ledger import output_hashes
    >>> d = pathlib.Path(tempfile.mkdtemp()); (d / "tables").mkdir(); _ = (d / "tables" / "t.csv").write_text("a")
    >>> list(output_hashes(d))
    ['tables/t.csv']
    """
    import hashlib

    paper_dir = Path(paper_dir)
    return {p.relative_to(paper_dir).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for sub in ("figures", "tables") for p in sorted((paper_dir / sub).glob("*")) if p.is_file()}


def verify_outputs(paper_dir: str | Path) -> dict:
    """Read ``paper_dir/claims.json`` and check that the figures and tables beside it are its own.

    Parameters
    ----------
    paper_dir : str or pathlib.Path
        A paper's results folder.

    Returns
    -------
    dict
        The ledger document.

    Raises
    ------
    ValueError
        A figure or table is missing, extra or changed since the ledger was written
        (for example a run interrupted by hand or files copied in from another seed).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from mascore.ledger import Claim, verify_outputs, write_claims
    >>> c = Claim("ren2005/demo", "Sec. 2", "A demo number.", paper_value=2.0, value=2.01, tolerance={"rel": 0.01})
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = write_claims([c], d / "claims.json", "ren2005", 1, "demo", files={})
    >>> (d / "figures").mkdir(); _ = (d / "figures" / "stray.png").write_bytes(b"x")
    >>> try:
    ...     verify_outputs(d)
    ... except ValueError as exc:
    ...     print("refused")
    refused
    """
    paper_dir = Path(paper_dir)
    doc = json.loads((paper_dir / "claims.json").read_text())
    if "files" not in doc:
        raise ValueError(f"{paper_dir}/claims.json lists no file hashes (written by an older mascore): "
                         "rerun `python -m mascore reproduce`")
    found = output_hashes(paper_dir)
    if found != doc["files"]:
        missing = sorted(set(doc["files"]) - set(found))
        extra = sorted(set(found) - set(doc["files"]))
        changed = sorted(k for k in set(found) & set(doc["files"]) if found[k] != doc["files"][k])
        raise ValueError(f"{paper_dir} does not match its claims.json (seed {doc.get('seed')}): missing {missing}, "
                         f"not in the ledger {extra}, changed {changed}; rerun `python -m mascore reproduce "
                         f"{doc.get('paper')}`")
    return doc


def load_claims(results_dir: str | Path, papers: Iterable[str] | None = None, verify: bool = True) -> list[dict]:
    """Read every ``results_dir/PAPER/claims.json`` that exists.

    Parameters
    ----------
    results_dir : str or pathlib.Path
        The results folder (``results/``).
    papers : iterable of str, optional
        Paper keys to read (default every paper, :func:`mascore.registry.paper_keys`).
    verify : bool
        Check first that each paper's figures and tables match its ledger
        (:func:`verify_outputs`; ``ValueError`` otherwise).

    Returns
    -------
    list of dict
        The claim records, each with an added ``paper`` key.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from mascore.ledger import Claim, load_claims, write_claims
    >>> c = Claim("ren2005/demo", "Sec. 2", "A demo number.", paper_value=2.0, value=2.01, tolerance={"rel": 0.01})
    >>> root = pathlib.Path(tempfile.mkdtemp())
    >>> _ = write_claims([c], root / "ren2005" / "claims.json", "ren2005", 1, "demo", files={})
    >>> [r["paper"] for r in load_claims(root)]
    ['ren2005']
    """
    if papers is None:
        from .registry import paper_keys

        papers = paper_keys()
    records = []
    for paper in papers:
        path = Path(results_dir) / paper / "claims.json"
        if path.exists():
            doc = verify_outputs(path.parent) if verify else json.loads(path.read_text())
            records += [{"paper": paper, **c} for c in doc["claims"]]
    return records


def claims_table(records: Sequence[dict]):
    """A pandas DataFrame of claim records (full values, for analysis; see :func:`show_claims` to read).

    Parameters
    ----------
    records : sequence of dict
        Claim records.

    Returns
    -------
    pandas.DataFrame
        One row per claim.

    Examples
    --------
    >>> from mascore.ledger import Claim, claims_table
    >>> c = Claim("ren2005/demo", "Sec. 2", "A demo number.", paper_value=2.0, value=2.01, tolerance={"rel": 0.01})
    >>> claims_table([c.to_dict()]).loc[0, "verdict"]
    'reproduces'
    """
    pd = require("pandas", "this table")

    columns = ["id", "where", "paper_value", "value", "tolerance", "verdict", "note"]
    return pd.DataFrame([{k: r.get(k) for k in columns} for r in records], columns=columns)


@dataclass(frozen=True)
class ClaimsView:
    """Claims laid out for reading: a numbered table, then the notes (shared paragraphs once).

    Jupyter shows it as Markdown (``_repr_markdown_``); ``str()`` gives the same text.

    Parameters
    ----------
    records : tuple of dict
        Claim records (:meth:`Claim.to_dict`).

    Examples
    --------
    >>> from mascore.ledger import Claim, show_claims
    >>> c = Claim("ren2005/demo", "Sec. 2", "A demo number.", paper_value=2.0, value=2.01, tolerance={"rel": 0.01})
    >>> str(show_claims([c])).splitlines()[0].startswith("|")
    True
    """

    records: tuple[dict, ...]

    def _repr_markdown_(self) -> str:
        lines = ["| # | claim (where the paper says it) | paper | ours | verdict |", "|---|---|---|---|---|"]
        for n, r in enumerate(self.records, 1):
            unit, labels = r.get("unit", ""), r.get("labels")
            claim = f"{_cell(math_text(r.get('statement', '')))} *({_cell(r.get('where', ''))})*"
            if r.get("rule"):
                claim += f"<br>*Decided by:* {_cell(math_text(r['rule']))}"
            lines.append(
                f"| {n} | {claim} "
                f"| {_cell(math_text(format_value(r.get('paper_value'), PAPER_DIGITS, unit=unit, labels=labels)))} "
                f"| {_cell(math_text(format_value(r.get('value'), unit=unit, labels=labels, max_items=VALUE_ITEMS)))} "
                f"| {_cell(_verdict_text(r))} |"
            )
        return "\n".join(lines + _notes_markdown(self.records))

    __str__ = _repr_markdown_


def verdict_words(verdict: str) -> str:
    """A verdict as the book prints it: ``"does-not-reproduce"`` reads ``"does not reproduce"``.

    Parameters
    ----------
    verdict : str
        One of :data:`VERDICTS`.

    Returns
    -------
    str
        The verdict in plain words.

    Examples
    --------
    >>> from mascore.ledger import verdict_words
    >>> verdict_words("does-not-reproduce"), verdict_words("holds")
    ('does not reproduce', 'holds')
    """
    if verdict not in VERDICTS:
        raise ValueError(f"verdict must be one of {VERDICTS}; got {verdict!r}")
    return verdict.replace("-", " ")


def deviation_sentence(record: dict) -> str:
    """How far a quantitative claim is off, against its tolerance, in one sentence ("" for a qualitative claim).

    The sentence agrees with the verdict (a non-breaking space before ``%``):
    ``"0.74 % off; tolerance 5 %"`` when it reproduces,
    ``"9.9 % off; tolerance 5 %, approximately within 15 %"`` when approximately reproduced,
    ``"40 % off; more than the 15 % of 'approximately'"`` when it does not reproduce.
    A vector's deviation is that of its worst entry (``"worst entry 20.75 off; ..."``).

    Parameters
    ----------
    record : dict
        A claim record (:meth:`Claim.to_dict`) with ``paper_value``, ``value``, ``tolerance``, ``verdict``.

    Returns
    -------
    str
        The sentence.

    Examples
    --------
    >>> from mascore.ledger import Claim, deviation_sentence
    >>> record = Claim("ren2005/x", "Fig. 1", "A number.", 1.0, 1.099, {"rel": 0.05}).to_dict()
    >>> print(deviation_sentence(record).replace("\\xa0", " "))
    9.9 % off; tolerance 5 %, approximately within 15 %
    """
    tol = record.get("tolerance")
    if not tol:
        return ""
    kind = "rel" if "rel" in tol else "abs"
    unit = f"\u00a0{record['unit']}" if record.get("unit") else ""
    fmt = (lambda v: format_number(100 * v, 3) + "\u00a0%") if kind == "rel" else (lambda v: format_number(v) + unit)
    several = np.size(record["paper_value"]) > 1  # a vector: the deviation is that of its worst entry
    off = f"{'worst entry ' if several else ''}{fmt(worst_deviation(record['paper_value'], record['value'], kind))} off"
    band = fmt(tol[f"approx_{kind}"])
    if record["verdict"] == "reproduces":
        return f"{off}; tolerance {fmt(tol[kind])}"
    if record["verdict"] == "approximately":
        return f"{off}; tolerance {fmt(tol[kind])}, approximately within {band}"
    return f"{off}; more than the {band} of 'approximately'"


#: Entries of a claim's value shown in the ledger (a mapping shows twice as many): the comparison's claims
#: decide on up to nine methods at once.
VALUE_ITEMS = 5


def _verdict_text(record: dict) -> str:
    verdict = f"**{verdict_words(record['verdict'])}**"
    sentence = deviation_sentence(record)
    marks = [m for m in (sentence, _provenance_mark(record)) if m]
    return "<br>".join([verdict, *marks])


def _provenance_mark(record: dict) -> str:
    """What a claim's record says of its provenance: a check of our own, or data it was decided on that were not
    held out from its writing."""
    marks = ["*changed after the data were seen*"] if record.get("post_hoc") else []
    if record.get("own_check"):
        marks.append("*a check of our own, not the paper's*")
    written, decided = record.get("written_from") or "", record.get("decided_on") or ""
    if written and decided.startswith(written):
        marks.append("*decided on the blocks it was written from*")
    elif written and written.split()[-1] in decided:
        marks.append("*partly decided on the blocks it was written from*")
    return "; ".join(marks)


def _notes_markdown(records: Sequence[dict]) -> list[str]:
    """Notes by claim number; a paragraph shared by several claims is printed once."""
    owners: dict[str, list[int]] = {}
    for n, r in enumerate(records, 1):
        paragraphs = [math_text(p.strip()) for p in (r.get("note") or "").split("\n\n") if p.strip()]
        if r.get("band_reason"):
            paragraphs.append(f"Band of 'approximately' wider than 3 tolerances: {r['band_reason']}")
        for p in paragraphs:
            owners.setdefault(p, []).append(n)
    if not owners:
        return []
    lines = ["", "**Notes**", ""]
    for paragraph, claims in owners.items():
        who = f"Claim {claims[0]}" if len(claims) == 1 else "Claims " + ", ".join(map(str, claims))
        lines.append(f"- *{who}.* {' '.join(paragraph.split())}")
    return lines


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def show_claims(claims: Iterable[Claim | dict]) -> ClaimsView:
    """Claims (objects or ``claims.json`` records) as a :class:`ClaimsView` for display.

    Parameters
    ----------
    claims : iterable of Claim or dict
        The claims.

    Returns
    -------
    ClaimsView
        Shown as a numbered Markdown table by Jupyter.

    Examples
    --------
    >>> from mascore.ledger import Claim, show_claims
    >>> c = Claim("ren2005/demo", "Sec. 2", "A demo number.", paper_value=2.0, value=2.01, tolerance={"rel": 0.01})
    >>> "reproduces" in str(show_claims([c]))
    True
    """
    return ClaimsView(tuple(c.to_dict() if isinstance(c, Claim) else dict(c) for c in claims))


def ledger_summary(claims: Iterable[Claim | dict], why: Mapping[str, str] | None = None) -> str:
    """What a chapter's ledger says, for the top of the chapter: the verdicts counted, then each claim
    that is not fully reproduced, with the paper's value, ours and why.

    Parameters
    ----------
    claims : iterable of Claim or dict
        The chapter's claims (objects or ``claims.json`` records).
    why : mapping of str to str, optional
        Claim id -> one sentence, in a reader's words, of why it is not reproduced (the claim's
        note gives the evidence). A claim without one is listed without a reason.

    Returns
    -------
    str
        Markdown: one paragraph, then a list when some claim is not reproduced.

    Examples
    --------
    >>> from mascore.ledger import Claim, ledger_summary
    >>> a = Claim("ren2005/a", "Fig. 1", "A number.", 2.0, 2.01, {"rel": 0.05})
    >>> b = Claim("ren2005/b", "Table 1", "Another number.", 1.0, 1.5, {"rel": 0.05})
    >>> text = ledger_summary([a, b], why={"ren2005/b": "The paper leaves a setting out."})
    >>> print(text.splitlines()[0])
    Of the 2 published numbers checked here, 1 reproduces and 1 does not.
    >>> print(text.splitlines()[-1])
    - Another number. (Table 1) Paper 1, ours 1.5: does not reproduce. The paper leaves a setting out.
    """
    records = [c.to_dict() if isinstance(c, Claim) else dict(c) for c in claims]
    why = dict(why or {})
    own = [r for r in records if r.get("own_check")]  # checks of our own, counted apart from the paper's claims
    numbers = [r for r in records if r.get("paper_value") is not None and not r.get("own_check")]
    statements = [r for r in records if r.get("paper_value") is None and not r.get("own_check")]

    def counted(rs: list[dict], verdicts: tuple[tuple[str, str, str], ...]) -> str:
        parts = []
        for verdict, one, many in verdicts:
            n = sum(r["verdict"] == verdict for r in rs)
            if n:
                parts.append(f"{n} {one if n == 1 else many}")
        if len(parts) == 1 and len(rs) > 1:  # one verdict for all
            return parts[0].replace(f"{len(rs)} ", "all ", 1).replace("all do not", "none reproduces", 1) \
                .replace("all fail", "none holds", 1)
        return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]

    sentences = []
    if len(numbers) == 1:  # "the one published number checked here reproduces", not "of the 1, 1 reproduces"
        verdict = {"approximately": "reproduces approximately"}.get(numbers[0]["verdict"],
                                                                    verdict_words(numbers[0]["verdict"]))
        sentences.append(f"The one published number checked here {verdict}.")
    elif numbers:
        sentences.append(
            f"Of the {len(numbers)} published numbers checked here, "
            + counted(numbers, (("reproduces", "reproduces", "reproduce"),
                                ("approximately", "reproduces approximately", "reproduce approximately"),
                                ("does-not-reproduce", "does not", "do not"))) + ".")
    if len(statements) == 1:
        lead = "Its" if numbers else "The paper prints no number we check; its"
        sentences.append(f"{lead} one statement without a number {statements[0]['verdict']}.")
    elif statements:
        n = len(statements)
        lead = "Of the" if numbers else "The paper prints no number we check; of its"
        sentences.append(f"{lead} {n} statements without a number, "
                         + counted(statements, (("holds", "holds", "hold"), ("fails", "fails", "fail"))) + ".")
    if own:
        sentences.append(f"Beside {'them' if numbers or statements else 'the paper'}, "
                         + ("one check of our own, which " + verdict_words(own[0]["verdict"]) if len(own) == 1 else
                            f"{len(own)} checks of our own: "
                            + counted(own, (("reproduces", "reproduces", "reproduce"), ("holds", "holds", "hold"),
                                            ("approximately", "approximately", "approximately"),
                                            ("does-not-reproduce", "does not", "do not"),
                                            ("fails", "fails", "fail"))))
                         + ".")
    lines = [" ".join(sentences)]
    missed = [r for r in records if r["verdict"] not in ("reproduces", "holds")]
    if missed:
        lines += ["", "Not fully reproduced, and why:", ""]
    for n, r in enumerate(missed):
        unit, labels = r.get("unit", ""), r.get("labels")
        values = ""
        if r.get("paper_value") is not None:
            values = (f" Paper {format_value(r['paper_value'], PAPER_DIGITS, unit=unit, labels=labels)}, "
                      f"ours {format_value(r['value'], unit=unit, labels=labels)}:")
        reason = why.get(r["id"], "")
        if n + 1 < len(missed) and why.get(missed[n + 1]["id"]) == reason:
            reason = ""  # a reason shared by the next claims is given once, after the last of them
        reason = f" {reason}" if reason else ""
        verdict = {"approximately": "reproduces approximately"}.get(r["verdict"], r["verdict"].replace("-", " "))
        lines.append(f"- {math_text(r['statement'])} ({r['where']}){values} {verdict}.{reason}")
    return "\n".join(lines)
