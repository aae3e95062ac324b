"""A claim of a paper, our value, and the verdict computed from the two (never typed in).

A :class:`Claim` records what a paper publishes, what mascore computes and a
verdict computed by the rules of :mod:`mascore.ledger` (which writes and reads the
claims of a study as its ``claims.json``).
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ._validation import float_array, require_finite

__all__ = ["APPROX_FACTOR", "PAPER_DIGITS", "VERDICTS", "Claim", "worst_deviation"]


#: The default band of "approximately": this many tolerances.
APPROX_FACTOR = 3.0

#: Significant digits of the paper's values in a ledger: enough to keep every printed digit.
PAPER_DIGITS = 6

#: Allowed verdicts.
VERDICTS = ("reproduces", "approximately", "does-not-reproduce", "holds", "fails")

#: A claim id: the ledger's key (a paper, :func:`mascore.registry.ledger_keys`), a slash, a short name.
_CLAIM_ID = re.compile(r"[a-z][a-z0-9_]*/\S+")

_RECORD_KEYS = ("id", "where", "statement", "paper_value", "value", "tolerance", "verdict", "note")
_OPTIONAL_KEYS = ("unit", "labels", "rule", "band_reason", "study", "why", "written_from", "decided_on", "post_hoc",
                  "own_check", "undecided")


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
    paper_value : float or list of float, or None
        The published value(s); ``None`` for a qualitative claim.
    value : float, list of float or dict
        Our value(s), same shape as `paper_value`; for a qualitative claim the
        measured quantities that decide it (a dict labels them).
    tolerance : dict or None
        ``{"abs": t}`` or ``{"rel": t}``, optionally with the band of
        "approximately" (``"approx_abs"`` / ``"approx_rel"``, default 3t).
    note : str
        Why it differs, what reading we chose, what setting the paper left out.
        Paragraphs are separated by a blank line; a paragraph shared word for
        word by several claims is shown once by :func:`mascore.ledger.show_claims`.
    unit : str
        Unit of the values (``"m"``, ``"s"``), ``""`` if dimensionless.
    labels : sequence of str, optional
        One label per entry of a list-valued claim (``["row 1", "row 2"]``).
    rule : str
        The condition that decides a qualitative claim, in words or symbols.
    band_reason : str
        Required when the band of "approximately" is wider than 3t: why.
    study : str
        The study (book chapter) that computed the claim; set by the writer.
    why : str
        For a claim that does not fully reproduce: one sentence, in a reader's words, of why
        (the reproduction report shows it; the `note` gives the evidence).
    written_from : str
        For a claim written from data: the data it was written from (``"seed blocks 0-1"``).
    decided_on : str
        The data its verdict is computed on (held-out seed blocks, or why not).
    post_hoc : str
        For a claim changed after its data were seen: what was changed, and from what.
    own_check : str
        For a check of our own that the paper does not state (a reference bound, a filter's
        consistency, an explanation of a printed number, a result beyond the paper's setting): what it
        adds. The report counts these apart from the paper's claims.
    holds : bool, optional
        The decided condition of a qualitative claim (use :meth:`qualitative`).
    undecided : bool
        A qualitative claim whose data cannot decide it (an interval across the edge of its
        band; use :meth:`qualitative` with ``holds=None``). Its verdict is ``"fails"``: the
        claim is not shown by the data. The record keeps ``"undecided": true`` to say why.

    Examples
    --------
    >>> Claim("ren2005/x", "Fig. 1", "A number.", 1.0, 1.04, {"rel": 0.05}).verdict
    'reproduces'
    >>> Claim("ren2005/x", "Fig. 1", "A number.", 1.0, 1.1, {"rel": 0.05}).verdict
    'approximately'
    """

    id: str
    where: str
    statement: str
    paper_value: Any
    value: Any
    tolerance: dict | None
    note: str = ""
    unit: str = ""
    labels: tuple[str, ...] | None = None
    rule: str = ""
    band_reason: str = ""
    study: str = ""
    why: str = ""
    written_from: str = ""
    decided_on: str = ""
    post_hoc: str = ""
    own_check: str = ""
    holds: bool | None = None
    undecided: bool = False
    verdict: str = field(default="", init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not _CLAIM_ID.fullmatch(self.id):
            raise ValueError(f"claim id must look like 'PAPER/short-name' with PAPER a ledger's key; got {self.id!r}")
        for name in ("where", "statement", "note", "unit", "rule", "band_reason", "study", "why", "written_from",
                     "decided_on", "post_hoc", "own_check"):
            if not isinstance(getattr(self, name), str):
                raise TypeError(f"{self.id}: {name} must be a string; got {type(getattr(self, name)).__name__}")
        if self.tolerance is not None and not isinstance(self.tolerance, dict):
            raise TypeError(f"{self.id}: tolerance must be a dict ({{'abs': t}} or {{'rel': t}}) or None; "
                            f"got {type(self.tolerance).__name__}")
        if self.holds is not None and not isinstance(self.holds, bool | np.bool_):
            raise TypeError(f"{self.id}: holds must be True, False or None; got {type(self.holds).__name__}")
        object.__setattr__(self, "value", _jsonable(self.value, "value"))
        object.__setattr__(self, "paper_value", _jsonable(self.paper_value, "paper_value"))
        if self.labels is not None:
            if isinstance(self.labels, str | bytes) or not isinstance(self.labels, list | tuple | np.ndarray):
                raise TypeError(f"{self.id}: labels must be a sequence of strings (one per value); "
                                f"got {type(self.labels).__name__} {self.labels!r}")
            object.__setattr__(self, "labels", tuple(str(x) for x in self.labels))
        if self.paper_value is None:
            if self.holds is None or self.tolerance is not None:
                raise ValueError(f"{self.id}: qualitative claims must be built with Claim.qualitative")
            object.__setattr__(self, "holds", bool(self.holds))
            object.__setattr__(self, "undecided", bool(self.undecided))
            verdict = "holds" if self.holds and not self.undecided else "fails"  # undecided: not shown
            object.__setattr__(self, "verdict", verdict)
            return
        if not _all_numbers(self.paper_value):
            raise TypeError(f"{self.id}: paper_value must be a number or a list of numbers; got {self.paper_value!r}")
        if not _all_numbers(self.value):
            raise TypeError(f"{self.id}: value must be a number or a list of numbers, as paper_value; "
                            f"got {self.value!r}")
        object.__setattr__(self, "tolerance", _normalized_tolerance(self))
        object.__setattr__(self, "verdict", _quantitative_verdict(self))

    @classmethod
    def qualitative(
        cls, id: str, where: str, statement: str, value: Any, holds: bool | np.bool_ | None, note: str = "",
        *, rule: str = "", unit: str = "", why: str = "", written_from: str = "", decided_on: str = "",
        post_hoc: str = "", own_check: str = "",
    ) -> Claim:
        """A claim without a published number, decided by a measured condition.

        Parameters
        ----------
        id : str
            ``PAPER/short-name``.
        where : str
            Where the paper states it.
        statement : str
            One sentence in our words.
        value : number, list or dict
            The measured quantity (or quantities) that decides the claim.
        holds : bool or None
            The condition evaluated on `value` by the caller's code; None when the data
            cannot decide it (e.g. an interval that straddles the rule's band).
        note : str
            Why, what reading we chose.
        rule : str
            The condition in words or symbols (``"max_ratio <= 1"``).
        unit : str
            Unit of `value`.
        why : str
            When it fails: one sentence of why, for the reproduction report.
        written_from, decided_on, post_hoc : str
            The data the claim was written from, the data that decide it, and what was changed
            after the data were seen (see the class).
        own_check : str
            For a check of our own that the paper does not state: what it adds (see the class).

        Returns
        -------
        Claim
            With verdict ``"holds"`` or ``"fails"`` (also when undecided).

        Examples
        --------
        >>> from mascore.ledger import Claim
        >>> Claim.qualitative("ren2005/demo", "Thm. 3.2", "They agree.", {"spread": 1e-9}, True,
        ...                   rule="spread < 1e-6").verdict
        'holds'
        """
        return cls(id, where, statement, None, value, None, note, unit=unit, rule=rule, why=why,
                   written_from=written_from, decided_on=decided_on, post_hoc=post_hoc, own_check=own_check,
                   holds=bool(holds) if holds is not None else False, undecided=holds is None)

    @property
    def deviation(self) -> float | None:
        """Largest deviation from the paper (relative or absolute, as the tolerance), or None."""
        if self.paper_value is None:
            return None
        kind = "rel" if "rel" in self.tolerance else "abs"
        return worst_deviation(self.paper_value, self.value, kind)

    def to_dict(self) -> dict:
        """The JSON record of REPRODUCTION.md (optional keys only when set).

        Returns
        -------
        dict
            ``id``, ``where``, ``statement``, ``paper_value``, ``value``, ``tolerance``,
            ``verdict``, ``note`` and the optional keys that are set.

        Examples
        --------
        >>> from mascore.ledger import Claim
        >>> c = Claim("ren2005/demo", "Sec. 2", "A demo number.", paper_value=2.0, value=2.01, tolerance={"rel": 0.01})
        >>> c.to_dict()["verdict"]
        'reproduces'
        """
        record = asdict(self)
        out = {k: record[k] for k in _RECORD_KEYS}
        out |= {k: (list(record[k]) if k == "labels" else record[k]) for k in _OPTIONAL_KEYS if record[k]}
        return out

    @classmethod
    def from_dict(cls, record: dict) -> Claim:
        """Rebuild a claim from its JSON record, recomputing the verdict.

        Parameters
        ----------
        record : dict
            A record of ``claims.json`` (:meth:`to_dict`).

        Returns
        -------
        Claim
            The claim, its verdict computed again from the numbers.

        Examples
        --------
        >>> from mascore.ledger import Claim
        >>> c = Claim("ren2005/demo", "Sec. 2", "A demo number.", paper_value=2.0, value=2.01, tolerance={"rel": 0.01})
        >>> Claim.from_dict(c.to_dict()) == c
        True
        """
        keys = {k: record[k] for k in (*_RECORD_KEYS, *_OPTIONAL_KEYS) if k in record and k != "verdict"}
        if keys.get("paper_value") is None:
            keys["holds"] = record["verdict"] == "holds"
            keys["undecided"] = bool(record.get("undecided", False))
        return cls(**keys)


def _normalized_tolerance(claim: Claim) -> dict:
    tol = claim.tolerance
    kinds = [k for k in ("abs", "rel") if isinstance(tol, dict) and k in tol]
    if len(kinds) != 1 or set(tol) - {kinds[0], f"approx_{kinds[0]}"}:
        raise ValueError(f"{claim.id}: tolerance must be {{'abs': t}} or {{'rel': t}}, optionally with "
                         f"'approx_abs' / 'approx_rel'; got {tol!r}")
    kind = kinds[0]
    for key, bound in tol.items():
        if isinstance(bound, bool) or not isinstance(bound, int | float | np.integer | np.floating):
            raise TypeError(f"{claim.id}: tolerance[{key!r}] must be a finite number >= 0; got {bound!r}")
        if not math.isfinite(float(bound)):
            raise ValueError(f"{claim.id}: tolerance[{key!r}] must be a finite number >= 0; got {bound!r}")
    t = float(tol[kind])
    a = float(tol.get(f"approx_{kind}", round(APPROX_FACTOR * t, 12)))
    if not (t >= 0 and a >= t):
        raise ValueError(f"{claim.id}: tolerance needs 0 <= {kind} <= approx_{kind}; got {tol!r}")
    if a > APPROX_FACTOR * t * (1 + 1e-12) and not claim.band_reason:
        raise ValueError(f"{claim.id}: a band of 'approximately' wider than {APPROX_FACTOR:g} tolerances "
                         f"({a:g} > {APPROX_FACTOR:g} x {t:g}) needs a band_reason")
    return {kind: t, f"approx_{kind}": a}


def worst_deviation(paper_value: Any, value: Any, kind: str) -> float:
    """Largest deviation of `value` from `paper_value` over their entries: absolute, or relative (``kind="rel"``).

    Parameters
    ----------
    paper_value, value : float or array_like
        The paper's number(s) and ours, of one shape.
    kind : {"abs", "rel"}
        Absolute deviation, or relative to ``|paper_value|``.

    Returns
    -------
    float
        The largest deviation.

    Examples
    --------
    >>> from mascore.claims import worst_deviation
    >>> worst_deviation([1.0, 2.0], [1.1, 2.0], "abs")
    0.10000000000000009
    """
    paper, ours = (np.atleast_1d(require_finite(float_array(v, name), name))
                   for v, name in ((paper_value, "paper_value"), (value, "value")))
    dev = np.abs(ours - paper)
    if kind == "rel":
        dev = dev / np.maximum(np.abs(paper), np.finfo(float).tiny)
    return float(dev.max())


def _quantitative_verdict(claim: Claim) -> str:
    kind = "rel" if "rel" in claim.tolerance else "abs"
    paper = np.atleast_1d(np.asarray(claim.paper_value, dtype=float))
    ours = np.atleast_1d(np.asarray(claim.value, dtype=float))
    if paper.shape != ours.shape:
        raise ValueError(f"{claim.id}: value shape {ours.shape} differs from paper_value shape {paper.shape}")
    if claim.labels is not None and len(claim.labels) != paper.size:
        raise ValueError(f"{claim.id}: {len(claim.labels)} labels for {paper.size} values")
    if not np.all(np.isfinite(ours)):
        return "does-not-reproduce"
    worst = worst_deviation(paper, ours, kind)
    if worst <= claim.tolerance[kind]:
        return "reproduces"
    if worst <= claim.tolerance[f"approx_{kind}"]:
        return "approximately"
    return "does-not-reproduce"


def _all_numbers(value: Any) -> bool:
    """A number or a (nested) list of numbers, as :func:`_jsonable` leaves them (no bools, no strings)."""
    if isinstance(value, list):
        return bool(value) and all(_all_numbers(v) for v in value)
    return isinstance(value, int | float) and not isinstance(value, bool)


def _jsonable(value: Any, name: str = "value") -> Any:
    """Convert numpy scalars/arrays (possibly nested) to plain JSON types; a NaN or inf is refused naming `name`."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v, name) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v, name) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist(), name)
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{name}: claim values must be finite; got {v}")
        return v
    return value
