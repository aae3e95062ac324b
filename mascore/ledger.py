"""The reproduction ledger: claims, computed verdicts and the claims.json file.

A :class:`Claim` records what a paper publishes, what mascore computes and a
verdict that is *computed* from the two (never typed in). The format is the
one of ``shared/REPRODUCTION.md``.

Verdict rules
-------------
Quantitative claims (``paper_value`` is a number or a list of numbers) carry a
tolerance ``{"abs": a}`` or ``{"rel": r}``. With ``d`` the largest deviation
over the entries:

* ``reproduces`` if ``d <= tol``;
* ``approximately`` if ``d <= APPROX_FACTOR * tol``;
* ``does-not-reproduce`` otherwise.

Qualitative claims (``paper_value`` is ``None``) are built with
:meth:`Claim.qualitative` from a boolean condition evaluated on measured
numbers; their verdict is ``holds`` or ``fails``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "APPROX_FACTOR",
    "PAPERS",
    "VERDICTS",
    "Claim",
    "ClaimsView",
    "claims_table",
    "format_value",
    "load_claims",
    "show_claims",
    "write_claims",
]

#: A deviation within this many tolerances is "approximately".
APPROX_FACTOR = 10.0

#: Allowed verdicts.
VERDICTS = ("reproduces", "approximately", "does-not-reproduce", "holds", "fails")

#: Paper keys, in book order.
PAPERS = ("song2023", "ren2005", "bhattacharjee2021", "vlahakis")


@dataclass(frozen=True)
class Claim:
    """One published number or statement, our value and the verdict.

    Build quantitative claims with the constructor and qualitative ones with
    :meth:`qualitative`; the verdict is computed in both cases.

    Parameters
    ----------
    id : str
        ``PAPER/short-name``, stable across versions.
    where : str
        Where the paper states it (``"Table 1, row 2"``, ``"Fig. 5"``).
    statement : str
        One sentence in our words.
    paper_value : float or list of float
        The published value(s).
    value : float or list of float
        Our value(s), same shape as `paper_value`.
    tolerance : dict
        ``{"abs": a}`` or ``{"rel": r}``.
    note : str
        Why it differs, what reading we chose, what setting the paper left out.
    """

    id: str
    where: str
    statement: str
    paper_value: Any
    value: Any
    tolerance: dict | None
    note: str = ""
    verdict: str = field(default="", init=False)

    def __post_init__(self) -> None:
        if "/" not in self.id or self.id.split("/")[0] not in PAPERS:
            raise ValueError(f"claim id must look like 'PAPER/short-name' with PAPER in {PAPERS}; got {self.id!r}")
        object.__setattr__(self, "value", _jsonable(self.value))
        object.__setattr__(self, "paper_value", _jsonable(self.paper_value))
        if self.paper_value is None:
            if self.verdict not in ("holds", "fails"):
                raise ValueError(f"{self.id}: qualitative claims must be built with Claim.qualitative")
            return
        object.__setattr__(self, "verdict", _quantitative_verdict(self))

    @classmethod
    def qualitative(
        cls, id: str, where: str, statement: str, value: Any, holds: bool | np.bool_, note: str = ""
    ) -> "Claim":
        """A claim without a published number, decided by a measured condition.

        Parameters
        ----------
        value : number, list or dict
            The measured quantity (or quantities) that decides the claim.
        holds : bool
            The condition evaluated on `value` by the caller's code.
        """
        claim = object.__new__(cls)
        for name, val in dict(
            id=id, where=where, statement=statement, paper_value=None, value=value,
            tolerance=None, note=note, verdict="holds" if bool(holds) else "fails",
        ).items():
            object.__setattr__(claim, name, val)
        claim.__post_init__()
        return claim

    def to_dict(self) -> dict:
        """The JSON record of REPRODUCTION.md."""
        keys = ("id", "where", "statement", "paper_value", "value", "tolerance", "verdict", "note")
        record = asdict(self)
        return {k: record[k] for k in keys}


def write_claims(
    claims: Sequence[Claim], path: str | Path, paper: str, seed: int, created_by: str
) -> Path:
    """Write ``claims.json`` for one paper; returns the path written."""
    from . import __version__

    if paper not in PAPERS:
        raise ValueError(f"paper must be one of {PAPERS}; got {paper!r}")
    ids = [c.id for c in claims]
    if len(set(ids)) != len(ids):
        raise ValueError(f"duplicate claim ids: {sorted({i for i in ids if ids.count(i) > 1})}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "paper": paper,
        "seed": int(seed),
        "mascore_version": __version__,
        "created_by": created_by,
        "claims": [c.to_dict() for c in claims],
    }
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    return path


def load_claims(results_dir: str | Path, papers: Iterable[str] = PAPERS) -> list[dict]:
    """Read every ``results_dir/PAPER/claims.json`` that exists.

    Returns
    -------
    list of dict
        The claim records, each with an added ``paper`` key.
    """
    records = []
    for paper in papers:
        path = Path(results_dir) / paper / "claims.json"
        if path.exists():
            doc = json.loads(path.read_text())
            records += [{"paper": paper, **c} for c in doc["claims"]]
    return records


def claims_table(records: Sequence[dict]):
    """A pandas DataFrame of claim records (full values, for analysis; see :func:`show_claims` to read)."""
    import pandas as pd

    columns = ["id", "where", "paper_value", "value", "tolerance", "verdict", "note"]
    return pd.DataFrame([{k: r.get(k) for k in columns} for r in records], columns=columns)


def format_value(value: Any, digits: int = 4, max_items: int = 4) -> str:
    """A short human-readable form of a claim value: numbers to `digits` significant digits,
    lists and dicts cut after `max_items` entries (marked with an ellipsis), ``None`` as a dash."""
    if value is None:
        return "\u2014"
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if isinstance(value, int | float | np.integer | np.floating):
        return f"{float(value):.{digits}g}" if isinstance(value, float | np.floating) else str(value)
    if isinstance(value, dict):
        def item(v: Any) -> str:
            text = format_value(v, digits, max_items)
            return "{" + text + "}" if isinstance(v, dict) else text

        items = [f"{k}: {item(v)}" for k, v in list(value.items())[:max_items]]
        return "; ".join(items) + ("; \u2026" if len(value) > max_items else "")
    if isinstance(value, list | tuple | np.ndarray):
        items = [format_value(v, digits, max_items) for v in list(value)[:max_items]]
        return "[" + ", ".join(items) + (", \u2026" if len(value) > max_items else "") + "]"
    return str(value)


@dataclass(frozen=True)
class ClaimsView:
    """Claims laid out for reading in a notebook: a compact table, then each claim's note.

    Jupyter shows it as Markdown (``_repr_markdown_``); ``str()`` gives the same text.
    """

    records: tuple[dict, ...]

    def _repr_markdown_(self) -> str:
        def cell(text: str) -> str:
            return text.replace("|", "\\|").replace("\n", " ")

        def name(r: dict) -> str:  # the paper is named once, above the table
            return r["id"].split("/", 1)[-1]

        lines = ["| verdict | claim | where | paper | ours |", "|---|---|---|---|---|"]
        for r in self.records:
            lines.append(
                f"| **{r['verdict']}** | {name(r)} | {cell(str(r.get('where', '')))} "
                f"| {cell(format_value(r.get('paper_value')))} | {cell(format_value(r.get('value'), max_items=3))} |"
            )
        notes = [f"- `{name(r)}`: {r['note']}" for r in self.records if r.get("note")]
        return "\n".join(lines + (["", "Notes:", "", *notes] if notes else []))

    __str__ = _repr_markdown_


def show_claims(claims: Iterable[Claim | dict]) -> ClaimsView:
    """Claims (objects or ``claims.json`` records) as a :class:`ClaimsView` for display."""
    return ClaimsView(tuple(c.to_dict() if isinstance(c, Claim) else dict(c) for c in claims))


def _quantitative_verdict(claim: Claim) -> str:
    tol = claim.tolerance
    if not isinstance(tol, dict) or len(tol) != 1 or next(iter(tol)) not in ("abs", "rel"):
        raise ValueError(f"{claim.id}: tolerance must be {{'abs': a}} or {{'rel': r}}; got {tol!r}")
    kind, size = next(iter(tol.items()))
    paper = np.atleast_1d(np.asarray(claim.paper_value, dtype=float))
    ours = np.atleast_1d(np.asarray(claim.value, dtype=float))
    if paper.shape != ours.shape:
        raise ValueError(f"{claim.id}: value shape {ours.shape} differs from paper_value shape {paper.shape}")
    if not np.all(np.isfinite(ours)):
        return "does-not-reproduce"
    dev = np.abs(ours - paper)
    if kind == "rel":
        dev = dev / np.maximum(np.abs(paper), np.finfo(float).tiny)
    worst = float(dev.max())
    if worst <= size:
        return "reproduces"
    if worst <= APPROX_FACTOR * size:
        return "approximately"
    return "does-not-reproduce"


def _jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays (possibly nested) to plain JSON types."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"claim values must be finite; got {v}")
        return v
    return value
