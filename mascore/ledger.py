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
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ._optional import require

__all__ = [
    "APPROX_FACTOR",
    "VERDICTS",
    "Claim",
    "ClaimsView",
    "claims_table",
    "format_number",
    "format_value",
    "ledger_summary",
    "load_claims",
    "output_hashes",
    "show_claims",
    "verify_outputs",
    "write_claims",
]

#: The default band of "approximately": this many tolerances.
APPROX_FACTOR = 3.0

#: Significant digits of the paper's values in a ledger: enough to keep every printed digit.
PAPER_DIGITS = 6

#: Allowed verdicts.
VERDICTS = ("reproduces", "approximately", "does-not-reproduce", "holds", "fails")

#: A claim id: the ledger's key (a paper, :func:`mascore.registry.ledger_keys`), a slash, a short name.
_CLAIM_ID = re.compile(r"[a-z][a-z0-9_]*/\S+")

_RECORD_KEYS = ("id", "where", "statement", "paper_value", "value", "tolerance", "verdict", "note")
_OPTIONAL_KEYS = ("unit", "labels", "rule", "band_reason", "study")


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
        word by several claims is shown once by :func:`show_claims`.
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
    holds : bool, optional
        The decided condition of a qualitative claim (use :meth:`qualitative`).

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
    holds: bool | None = None
    verdict: str = field(default="", init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not _CLAIM_ID.fullmatch(self.id):
            raise ValueError(f"claim id must look like 'PAPER/short-name' with PAPER a ledger's key; got {self.id!r}")
        for name in ("where", "statement", "note", "unit", "rule", "band_reason", "study"):
            if not isinstance(getattr(self, name), str):
                raise TypeError(f"{self.id}: {name} must be a string; got {type(getattr(self, name)).__name__}")
        if self.tolerance is not None and not isinstance(self.tolerance, dict):
            raise TypeError(f"{self.id}: tolerance must be a dict ({{'abs': t}} or {{'rel': t}}) or None; "
                            f"got {type(self.tolerance).__name__}")
        if self.holds is not None and not isinstance(self.holds, bool | np.bool_):
            raise TypeError(f"{self.id}: holds must be True, False or None; got {type(self.holds).__name__}")
        object.__setattr__(self, "value", _jsonable(self.value))
        object.__setattr__(self, "paper_value", _jsonable(self.paper_value))
        if self.labels is not None:
            if isinstance(self.labels, str | bytes) or not isinstance(self.labels, list | tuple | np.ndarray):
                raise TypeError(f"{self.id}: labels must be a sequence of strings (one per value); "
                                f"got {type(self.labels).__name__} {self.labels!r}")
            object.__setattr__(self, "labels", tuple(str(x) for x in self.labels))
        if self.paper_value is None:
            if self.holds is None or self.tolerance is not None:
                raise ValueError(f"{self.id}: qualitative claims must be built with Claim.qualitative")
            object.__setattr__(self, "holds", bool(self.holds))
            object.__setattr__(self, "verdict", "holds" if self.holds else "fails")
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
        cls, id: str, where: str, statement: str, value: Any, holds: bool | np.bool_, note: str = "",
        *, rule: str = "", unit: str = "",
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
        holds : bool
            The condition evaluated on `value` by the caller's code.
        note : str
            Why, what reading we chose.
        rule : str
            The condition in words or symbols (``"max_ratio <= 1"``).
        unit : str
            Unit of `value`.

        Returns
        -------
        Claim
            With verdict ``"holds"`` or ``"fails"``.

        Examples
        --------
        >>> from mascore.ledger import Claim
        >>> Claim.qualitative("ren2005/demo", "Thm. 3.2", "They agree.", {"spread": 1e-9}, True,
        ...                   rule="spread < 1e-6").verdict
        'holds'
        """
        return cls(id, where, statement, None, value, None, note, unit=unit, rule=rule, holds=bool(holds))

    @property
    def deviation(self) -> float | None:
        """Largest deviation from the paper (relative or absolute, as the tolerance), or None."""
        if self.paper_value is None:
            return None
        kind = "rel" if "rel" in self.tolerance else "abs"
        return _worst_deviation(self.paper_value, self.value, kind)

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
        return cls(**keys)


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


_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def format_number(x: float, digits: int = 4) -> str:
    """One number as the book prints it: `digits` significant digits, no ``e`` notation.

    Numbers from 1e-3 to below 1e6 are written out (``0.07681``, ``2.462``, ``136.4``,
    ``12,346``); smaller and larger ones as ``2.776 × 10⁻¹⁷``. Integers are written
    exactly. Trailing zeros are dropped.

    Parameters
    ----------
    x : float
        The number.
    digits : int
        Significant digits.

    Returns
    -------
    str
        The number as printed.

    Examples
    --------
    >>> format_number(0.076812345), format_number(2.7755575615628914e-17), format_number(5.0)
    ('0.07681', '2.776 × 10⁻¹⁷', '5')
    """
    if isinstance(digits, bool) or not isinstance(digits, int | np.integer):
        raise TypeError(f"digits must be an integer >= 1 (significant digits); got {type(digits).__name__} {digits!r}")
    if digits < 1:
        raise ValueError(f"digits must be an integer >= 1 (significant digits); got {digits}")
    digits = int(digits)
    if isinstance(x, bool | np.bool_):
        return str(bool(x))
    if isinstance(x, int | np.integer):
        return f"{int(x):,}" if abs(int(x)) >= 10_000 else str(int(x))
    if isinstance(x, str | bytes) or not hasattr(x, "__float__"):
        raise TypeError(f"x must be a real number; got {type(x).__name__} {x!r}")
    x = float(x)
    if not math.isfinite(x):
        return str(x)
    if x == 0.0:
        return "0"
    exponent = math.floor(math.log10(abs(x)))
    if -3 <= exponent < 6:
        decimals = max(digits - 1 - exponent, 0)
        text = f"{x:,.{decimals}f}"
        if "." in text:
            text = text.rstrip("0").rstrip(".")
        return "0" if text in ("-0", "") else text
    mantissa = f"{x / 10.0**exponent:.{digits - 1}f}".rstrip("0").rstrip(".")
    if mantissa in ("10", "-10"):  # rounding carried into the next decade
        mantissa, exponent = mantissa[:-1], exponent + 1
    return f"{mantissa} \u00d7 10{str(exponent).translate(_SUPERSCRIPT)}"


def format_value(value: Any, digits: int = 4, max_items: int = 4, unit: str = "",
                 labels: Sequence[str] | None = None) -> str:
    """A short human-readable form of a claim value.

    Numbers through :func:`format_number` (with `unit` appended), lists labelled by
    `labels` when given and cut after `max_items` entries (marked with an ellipsis),
    dicts as ``label = value`` pairs (underscores in labels read as spaces), ``None``
    as a dash. Any value is shown, by design: NaN and infinities print as ``nan`` and
    ``inf``, a string as itself (this is a display helper; :class:`Claim` refuses them).

    Parameters
    ----------
    value : object
        A number, list, dict or None.
    digits : int
        Significant digits of each number.
    max_items : int
        Entries shown of a list.
    unit : str
        Appended to numbers.
    labels : sequence of str, optional
        Names of a list's entries.

    Returns
    -------
    str
        The value as printed.

    Examples
    --------
    >>> from mascore.ledger import format_value
    >>> format_value([1.5, 2.25], labels=["mean", "rms"], unit="m")
    'mean: 1.5; rms: 2.25 (m)'
    """
    for name, count in (("digits", digits), ("max_items", max_items)):
        if isinstance(count, bool) or not isinstance(count, int | np.integer):
            raise TypeError(f"{name} must be an integer >= 1; got {type(count).__name__} {count!r}")
        if count < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {count}")
    if not isinstance(unit, str):
        raise TypeError(f"unit must be a string; got {type(unit).__name__}")
    suffix = f"\u00a0{unit}" if unit else ""
    if value is None:
        return "\u2014"
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if isinstance(value, int | float | np.integer | np.floating):
        return format_number(value, digits) + suffix
    if isinstance(value, str):
        return value
    if isinstance(value, dict):
        def item(v: Any) -> str:
            text = format_value(v, digits, max_items)
            return "(" + text + ")" if isinstance(v, dict) else text

        items = [f"{_label(k)} = {item(v)}" for k, v in list(value.items())[:2 * max_items]]
        more = len(value) > 2 * max_items
        return "; ".join(items) + ("; \u2026" if more else "") + (f" ({unit})" if unit else "")
    if isinstance(value, list | tuple | np.ndarray):
        value = list(value)
        if labels is not None and len(labels) == len(value):
            pairs = [f"{lab}: {format_value(v, digits, max_items)}" for lab, v in zip(labels, value)]
            return "; ".join(pairs) + (f" ({unit})" if unit else "")
        items = [format_value(v, digits, max_items) for v in value[:max_items]]
        return "[" + ", ".join(items) + (", \u2026" if len(value) > max_items else "") + "]" + suffix
    return str(value)


def _label(key: Any) -> str:
    return str(key).replace("_", " ")


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
            claim = f"{_cell(r.get('statement', ''))} *({_cell(r.get('where', ''))})*"
            if r.get("rule"):
                claim += f"<br>*Decided by:* {_cell(r['rule'])}"
            lines.append(
                f"| {n} | {claim} | {_cell(format_value(r.get('paper_value'), PAPER_DIGITS, unit=unit, labels=labels))} "
                f"| {_cell(format_value(r.get('value'), unit=unit, labels=labels))} | {_cell(_verdict_text(r))} |"
            )
        return "\n".join(lines + _notes_markdown(self.records))

    __str__ = _repr_markdown_


def _verdict_text(record: dict) -> str:
    verdict = f"**{record['verdict']}**"
    tol = record.get("tolerance")
    if not tol:
        return verdict
    kind = "rel" if "rel" in tol else "abs"
    fmt = (lambda v: format_number(100 * v, 3) + " %") if kind == "rel" else format_number
    dev = _worst_deviation(record["paper_value"], record["value"], kind)
    return (f"{verdict}<br>off by {fmt(dev)}; reproduces within {fmt(tol[kind])}, "
            f"approximately within {fmt(tol[f'approx_{kind}'])}")


def _notes_markdown(records: Sequence[dict]) -> list[str]:
    """Notes by claim number; a paragraph shared by several claims is printed once."""
    owners: dict[str, list[int]] = {}
    for n, r in enumerate(records, 1):
        paragraphs = [p.strip() for p in (r.get("note") or "").split("\n\n") if p.strip()]
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


def _worst_deviation(paper_value: Any, value: Any, kind: str) -> float:
    paper = np.atleast_1d(np.asarray(paper_value, dtype=float))
    ours = np.atleast_1d(np.asarray(value, dtype=float))
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
    worst = _worst_deviation(paper, ours, kind)
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
    numbers = [r for r in records if r.get("paper_value") is not None]
    statements = [r for r in records if r.get("paper_value") is None]

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
    if numbers:
        sentences.append(
            f"Of the {len(numbers)} published number{'s' if len(numbers) != 1 else ''} checked here, "
            + counted(numbers, (("reproduces", "reproduces", "reproduce"),
                                ("approximately", "reproduces approximately", "reproduce approximately"),
                                ("does-not-reproduce", "does not", "do not"))) + ".")
    if statements:
        n = len(statements)
        lead = "Of the" if numbers else "The paper prints no number we check; of its"
        sentences.append(f"{lead} {n} statement{'s' if n != 1 else ''} without a number, "
                         + counted(statements, (("holds", "holds", "hold"), ("fails", "fails", "fail"))) + ".")
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
        lines.append(f"- {r['statement']} ({r['where']}){values} {verdict}.{reason}")
    return "\n".join(lines)
