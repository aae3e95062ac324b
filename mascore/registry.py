"""One registry per paper: its settings, runs, figures, tables and claims.

The layer between the algorithms (the concept modules) and the outputs a
reader sees (``python -m mascore reproduce``, the book's chapters, the tests).
Each paper module ``mascore.papers.<KEY>`` declares once, as ``REGISTRY``, a
:class:`PaperRegistry` made of one or more :class:`Study` objects (one per
chapter of the book). A study holds

* ``settings``: a frozen dataclass with every parameter of the run, the ones
  the paper gives and the ones it leaves out (declare the fields with
  :func:`setting`, so that :func:`show_settings` can say which is which);
* ``run(settings, seed, progress=False) -> result``: everything random or
  expensive, computed once;
* ``figures`` and ``tables``: :class:`FigureSpec` / :class:`TableSpec`, each
  drawn or built from the result alone, with the paper's number and a caption;
* ``claims(result) -> list[Claim]``: the ledger entries, from the result alone.

``reproduce`` writes every figure, table and claim of every study through one
generic writer (:func:`write_study`); a notebook calls the same ``run`` with
the same seed and draws the same figures, so the chapter shows exactly the
published ledger.

Examples
--------
>>> from mascore.registry import paper_registry
>>> reg = paper_registry("ren2005")          # doctest: +SKIP
>>> study = reg.studies[0]                    # doctest: +SKIP
>>> result = study.run(study.settings, seed=1)  # doctest: +SKIP
>>> fig = study.draw("fig1", result)          # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._optional import require
from .ledger import Claim, format_value

if TYPE_CHECKING:  # pragma: no cover
    import matplotlib.figure
    import pandas as pd

__all__ = [
    "COMPARISON_MODULES",
    "STUDY_CONTRACT",
    "FigureSpec",
    "PaperRegistry",
    "SettingsView",
    "documented_settings",
    "Study",
    "TableSpec",
    "all_figures",
    "comparison_registries",
    "ledger_keys",
    "paper_keys",
    "paper_registries",
    "paper_registry",
    "setting",
    "show_settings",
    "study_modules",
    "write_study",
    "allowed_values",
    "check_settings",
    "check_settings_type",
    "caption_values",
    "glue_caption_values",
    "glue_key",
]

#: What every study module of ``mascore.papers`` exports (:func:`study_modules`): the default
#: settings, ``run(settings=SETTINGS, seed=1, progress=False)``, ``claims(result)``, the figure and
#: table specs, and the :class:`Study` made of them. A paper module (its name is the paper's key)
#: also exports ``REGISTRY``, its :class:`PaperRegistry`.
STUDY_CONTRACT = ("SETTINGS", "run", "claims", "FIGURES", "TABLES", "STUDY")

#: Modules outside ``mascore.papers`` that declare a ``REGISTRY`` of their own: the comparisons,
#: whose ledgers follow the papers' (``results/compare/claims.json``).
COMPARISON_MODULES = ("mascore.compare",)


@dataclass(frozen=True)
class FigureSpec:
    """A figure of a study: which paper figure it rebuilds, its caption and how to draw it.

    Parameters
    ----------
    name : str
        File stem in ``results/PAPER/figures/`` (``"fig2"``); unique within the paper.
    number : str
        The paper's figure it rebuilds (``"Fig. 2"``); what of the paper it checks when the
        paper has no such figure (``"Theorems 3.2 and 3.9 (our check)"``); or ``""`` for a
        figure beyond the paper.
    caption : str
        What the figure shows and what to look for (MyST Markdown: ``$math$`` allowed).
    draw : callable
        ``draw(result) -> matplotlib.figure.Figure``: draws from the result alone (everything
        it shows is computed by the study's ``run``), and returns the figure (:meth:`Study.draw`
        refuses anything else).
    values : callable, optional
        ``values(result) -> {name: number}``: the numbers the caption quotes, computed from the
        result. The caption refers to one as ``{{name:.3g}}`` (a format spec after the colon);
        the book shows the value of the chapter's run (MyST-NB ``glue``), so a caption cannot
        quote a stale number.

    Examples
    --------
    >>> from mascore.papers import song2023
    >>> spec = song2023.REGISTRY.study("rendezvous").figure("fig2")
    >>> spec.name, spec.number
    ('fig2', 'Fig. 2')
    """

    name: str
    number: str
    caption: str
    draw: Callable[[Any], matplotlib.figure.Figure]
    values: Callable[[Any], Mapping[str, float]] | None = None

    def __post_init__(self) -> None:
        if self.placeholders() and self.values is None:
            raise ValueError(f"figure {self.name!r}: the caption quotes {self.placeholders()} but no values "
                             "function computes them")

    def placeholders(self) -> list[str]:
        """Names of the computed values the caption quotes (``{{name:fmt}}``), in order.

        Returns
        -------
        list of str
            The names.

        Examples
        --------
        >>> from mascore.papers import ren2005
        >>> ren2005.REGISTRY.study("kalman-consensus").figure("bias").placeholders()
        ['bias_runs', 'fused', 'average']
        """
        return [m.group(1) for m in _CAPTION_VALUE.finditer(self.caption)]

    def caption_with(self, result: Any) -> str:
        """The caption with its computed values filled in from `result`.

        Parameters
        ----------
        result : object
            The output of the study's ``run``.

        Returns
        -------
        str
            The caption, every ``{{name:fmt}}`` replaced by ``format(values(result)[name], fmt)``.

        Raises
        ------
        KeyError
            If the values function does not compute a quoted name.

        Examples
        --------
        >>> from mascore.registry import FigureSpec
        >>> spec = FigureSpec("f", "", "Settles at {{level:.2f}}.", draw=None, values=lambda r: {"level": r})
        >>> spec.caption_with(0.04993)
        'Settles at 0.05.'
        """
        if self.values is None:
            return self.caption
        values = self.values(result)
        return _CAPTION_VALUE.sub(lambda m: format(values[m.group(1)], m.group(2) or ""), self.caption)


#: A computed value quoted by a caption: ``{{name}}`` or ``{{name:.3g}}``.
_CAPTION_VALUE = re.compile(r"\{\{(\w+)(?::([^{}]*))?\}\}")


@dataclass(frozen=True)
class TableSpec:
    """A table of a study (written to ``results/PAPER/tables/NAME.csv``).

    Parameters
    ----------
    name : str
        File stem; unique within the paper.
    number : str
        The paper's table (``"Table 1"``) or ``""`` beyond the paper.
    caption : str
        What the table shows.
    build : callable
        ``build(result) -> pandas.DataFrame``.

    Examples
    --------
    >>> from mascore.papers import bhattacharjee2021
    >>> spec = bhattacharjee2021.REGISTRY.study("set-membership").table("table1")
    >>> spec.name, spec.number
    ('table1', 'Table 1')
    """

    name: str
    number: str
    caption: str
    build: Callable[[Any], pd.DataFrame]


@dataclass(frozen=True)
class Study:
    """One chapter's worth of a paper: settings, one run, and what is computed from it.

    Parameters
    ----------
    name : str
        Short name (``"rendezvous"``); also the anchor of the chapter's ledger
        section, ``{paper}-{name}-ledger``.
    chapter : str
        Notebook stem of the chapter (``"song2023_rendezvous"``).
    settings : frozen dataclass
        The default (paper-faithful) settings.
    run : callable
        ``run(settings, seed, progress=False) -> result``.
    figures : sequence of FigureSpec
        The figures the study rebuilds.
    tables : sequence of TableSpec
        The tables.
    claims : callable
        ``claims(result) -> list[Claim]``.

    Examples
    --------
    >>> from mascore.papers import vlahakis
    >>> study = vlahakis.REGISTRY.study("distributed-observer")
    >>> study.chapter
    'vlahakis_distributed_observer'
    """

    name: str
    chapter: str
    settings: Any
    run: Callable[..., Any]
    figures: tuple[FigureSpec, ...] = ()
    tables: tuple[TableSpec, ...] = ()
    claims: Callable[[Any], list[Claim]] = lambda result: []

    def figure(self, name: str) -> FigureSpec:
        """The figure spec called `name` (``ValueError`` naming the choices otherwise).

        Parameters
        ----------
        name : str
            A figure of the study.

        Returns
        -------
        FigureSpec
            Its spec.

        Examples
        --------
        >>> from mascore.papers import song2023
        >>> song2023.REGISTRY.study("rendezvous").figure("fig2").number
        'Fig. 2'
        """
        for spec in self.figures:
            if spec.name == name:
                return spec
        raise ValueError(f"figure must be one of {[f.name for f in self.figures]}; got {name!r}")

    def table(self, name: str) -> TableSpec:
        """The table spec called `name` (``ValueError`` naming the choices otherwise).

        Parameters
        ----------
        name : str
            A table of the study.

        Returns
        -------
        TableSpec
            Its spec.

        Examples
        --------
        >>> from mascore.papers import bhattacharjee2021
        >>> bhattacharjee2021.REGISTRY.study("set-membership").table("table1").number
        'Table 1'
        """
        for spec in self.tables:
            if spec.name == name:
                return spec
        raise ValueError(f"table must be one of {[t.name for t in self.tables]}; got {name!r}")

    def draw(self, name: str, result: Any) -> matplotlib.figure.Figure:
        """Draw figure `name` from `result` (in the book's style).

        Parameters
        ----------
        name : str
            A figure of the study.
        result : object
            The output of the study's ``run``.

        Returns
        -------
        matplotlib.figure.Figure
            The figure.

        Examples
        --------
        >>> import dataclasses
        >>> import matplotlib.pyplot as plt
        >>> from mascore.papers import ren2005
        >>> study = ren2005.REGISTRY.study("kalman-consensus")
        >>> fewer = dataclasses.replace(study.settings, noise_runs=20, noise_paths=4, bias_runs=50)  # fewer runs
        >>> fig = study.draw("fig1", study.run(fewer, 1))
        >>> len(fig.axes)
        4
        >>> plt.close("all")
        """
        from .plotting import use_style

        use_style()
        fig = self.figure(name).draw(result)
        figure_class = require("matplotlib.figure", "drawing a registered figure").Figure
        if not isinstance(fig, figure_class):
            raise TypeError(f"{self.name}: figure {name!r} must be drawn as a matplotlib Figure; "
                            f"its draw returned {type(fig).__name__}")
        return fig

    def build(self, name: str, result: Any) -> pd.DataFrame:
        """Build table `name` from `result`.

        Parameters
        ----------
        name : str
            A table of the study.
        result : object
            The output of the study's ``run``.

        Returns
        -------
        pandas.DataFrame
            The table.

        Examples
        --------
        >>> import dataclasses
        >>> from mascore.papers import bhattacharjee2021 as bs
        >>> study = bs.REGISTRY.study("set-membership")
        >>> result = study.run(dataclasses.replace(bs.SETTINGS, n_runs=3, t_f=10, figure_method="closed_form"), 1)
        >>> study.build("table1", result).shape[0]
        3
        """
        return self.table(name).build(result)


@dataclass(frozen=True)
class PaperRegistry:
    """Everything the companion reproduces of one paper.

    Parameters
    ----------
    key : str
        The paper's key: the name of its module ``mascore.papers.<key>`` and of its
        results folder (lower-case letters, digits and underscores).
    citation : str
        Short author-year form used in captions (``"Song et al. 2023"``).
    studies : sequence of Study
        One per chapter.
    errata : sequence of str
        Errata and readings we found, one Markdown sentence or two each (the report lists them).
    position : int
        Place of the paper in the book's table of contents (``book/_toc.yml``); the reports,
        ledgers and :func:`paper_keys` list the papers in this order.

    Examples
    --------
    >>> from mascore.papers import song2023
    >>> [s.name for s in song2023.REGISTRY.studies]
    ['rendezvous', 'flocking']
    """

    key: str
    citation: str
    studies: tuple[Study, ...]
    errata: tuple[str, ...] = ()
    position: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.key, str) or not re.fullmatch(r"[a-z][a-z0-9_]*", self.key):
            raise ValueError(f"key must be a module name of lower-case letters, digits and underscores; "
                             f"got {self.key!r}")
        names = [f.name for s in self.studies for f in (*s.figures, *s.tables)]
        if len(set(names)) != len(names):
            raise ValueError(f"{self.key}: figure and table names must be unique; got {names}")

    def study(self, name: str) -> Study:
        """The study called `name` (``ValueError`` naming the choices otherwise).

        Parameters
        ----------
        name : str
            A study of the paper.

        Returns
        -------
        Study
            The study.

        Examples
        --------
        >>> from mascore.papers import song2023
        >>> song2023.REGISTRY.study("flocking").chapter
        'song2023_flocking'
        """
        for s in self.studies:
            if s.name == name:
                return s
        raise ValueError(f"study must be one of {[s.name for s in self.studies]}; got {name!r}")

    def figure_label(self, name: str) -> str:
        """Cross-reference label of figure `name` in the book: ``fig-{key}-{name}``.

        Parameters
        ----------
        name : str
            A figure name.

        Returns
        -------
        str
            The label.

        Examples
        --------
        >>> from mascore.papers import song2023
        >>> song2023.REGISTRY.figure_label("fig2")
        'fig-song2023-fig2'
        """
        return f"fig-{self.key}-{name}"

    def full_caption(self, spec: FigureSpec | TableSpec) -> str:
        """The caption as the book prints it: the paper's number first, then the spec's caption.

        Parameters
        ----------
        spec : FigureSpec or TableSpec
            A figure or table of one of the studies.

        Returns
        -------
        str
            The caption.

        Examples
        --------
        >>> from mascore.papers import song2023
        >>> spec = song2023.REGISTRY.study("rendezvous").figure("fig2")
        >>> song2023.REGISTRY.full_caption(spec).startswith("Song et al. 2023, Fig. 2 (rebuilt).")
        True
        """
        if not spec.number:
            source = "Beyond the paper. "
        elif spec.number.startswith(("Fig", "Table")):
            source = f"{self.citation}, {spec.number} (rebuilt). "
        else:  # e.g. "Theorems 3.2 and 3.9 (our check)": what of the paper the figure is about
            source = f"{self.citation}, {spec.number}. "
        caption = spec.caption
        if isinstance(spec, FigureSpec):  # computed values: glued by the chapter (glue_caption_values)
            caption = _CAPTION_VALUE.sub(
                lambda m: f"{{glue:text}}`{glue_key(spec, m.group(1))}{':' + m.group(2) if m.group(2) else ''}`",
                caption)
        return source + caption


def glue_key(spec: FigureSpec, name: str) -> str:
    """The MyST-NB glue key of value `name` quoted by the caption of `spec`: ``{figure}-{name}``.

    Parameters
    ----------
    spec : FigureSpec
        The figure.
    name : str
        One of ``spec.placeholders()``.

    Returns
    -------
    str
        The key (unique in a chapter: figure names are unique in a paper).

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> glue_key(ren2005.REGISTRY.study("kalman-consensus").figure("bias"), "fused")
    'bias-fused'
    """
    return f"{spec.name}-{name}"


def caption_values(study: Study, result: Any) -> dict[str, float]:
    """Every value the study's captions quote, computed from `result`, by glue key.

    Parameters
    ----------
    study : Study
        The study.
    result : object
        The output of its ``run``.

    Returns
    -------
    dict
        ``{glue_key(spec, name): value}`` over every figure and quoted name.

    Raises
    ------
    KeyError
        If a figure's values function does not compute a name its caption quotes.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> study = ren2005.REGISTRY.study("kalman-consensus")
    >>> values = caption_values(study, ren2005.run(ren2005.SETTINGS, seed=1))
    >>> round(values["bias-fused"], 3)
    6.985
    """
    out = {}
    for spec in study.figures:
        if spec.values is None:
            continue
        values = spec.values(result)
        for name in spec.placeholders():
            if name not in values:
                raise KeyError(f"figure {spec.name!r}: its values function does not compute {name!r}")
            out[glue_key(spec, name)] = float(values[name])
    return out


def glue_caption_values(study: Study, result: Any) -> dict[str, float]:
    """Glue (MyST-NB) every value the study's captions quote, so the chapter's captions show this run's numbers.

    Call it in the chapter's notebook after the run; the captions that ``make sync`` writes into
    the figure cells refer to these keys.

    Parameters
    ----------
    study : Study
        The study.
    result : object
        The output of its ``run``.

    Returns
    -------
    dict
        The glued values, by key (see :func:`caption_values`).

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> from mascore.registry import glue_caption_values
    >>> study = ren2005.REGISTRY.study("kalman-consensus")
    >>> glued = glue_caption_values(study, ren2005.run(ren2005.SETTINGS, seed=1))  # doctest: +SKIP
    """
    glue = require("myst_nb", "gluing caption values in a notebook").glue
    values = caption_values(study, result)
    for key, value in values.items():
        glue(key, value, display=False)
    return values


def study_modules() -> list:
    """Every study module of ``mascore.papers``, in book order (papers by position, then their studies).

    A study module is one that exports ``STUDY`` (and the rest of :data:`STUDY_CONTRACT`);
    nothing is listed by hand: a new module with a study is found here.

    Returns
    -------
    list of module
        The modules, each once.

    Examples
    --------
    >>> from mascore.registry import study_modules
    >>> [m.__name__.rsplit(".", 1)[1] for m in study_modules()][:2]
    ['song2023', 'song2023_flocking']
    """
    import mascore.papers as package

    modules = [importlib.import_module(f"{package.__name__}.{info.name}")
               for info in pkgutil.iter_modules(package.__path__) if not info.name.startswith("_")]
    with_study = {id(m.STUDY): m for m in modules if isinstance(getattr(m, "STUDY", None), Study)}
    ordered = [with_study.pop(id(s)) for reg in paper_registries() for s in reg.studies if id(s) in with_study]
    return ordered + sorted(with_study.values(), key=lambda m: m.__name__)  # a study on no registry: last


def paper_registries() -> tuple[PaperRegistry, ...]:
    """The registries of every paper, discovered in ``mascore.papers``, in book order.

    A paper is a module ``mascore.papers.<key>`` that exports ``REGISTRY``, a
    :class:`PaperRegistry` whose key is the module's name; papers are ordered by
    :attr:`PaperRegistry.position`.

    Returns
    -------
    tuple of PaperRegistry
        One per paper.

    Raises
    ------
    ValueError
        If a registry's key is not its module's name, or two papers share a position.

    Examples
    --------
    >>> from mascore.registry import paper_registries
    >>> [reg.key for reg in paper_registries()]
    ['song2023', 'ren2005', 'bhattacharjee2021', 'vlahakis']
    """
    import mascore.papers as package

    found = []
    for info in pkgutil.iter_modules(package.__path__):
        if info.name.startswith("_"):
            continue
        reg = getattr(importlib.import_module(f"{package.__name__}.{info.name}"), "REGISTRY", None)
        if isinstance(reg, PaperRegistry):
            if reg.key != info.name:
                raise ValueError(f"mascore.papers.{info.name}: REGISTRY.key must be the module's name; got {reg.key!r}")
            found.append(reg)
    positions = [reg.position for reg in found]
    if len(set(positions)) != len(positions):
        raise ValueError(f"papers must have distinct positions; got {dict((r.key, r.position) for r in found)}")
    return tuple(sorted(found, key=lambda reg: reg.position))


def paper_keys() -> tuple[str, ...]:
    """The keys of every paper, in book order (:func:`paper_registries`).

    Returns
    -------
    tuple of str
        The keys; each names a module ``mascore.papers.<key>`` and a folder ``results/<key>``.

    Examples
    --------
    >>> from mascore.registry import paper_keys
    >>> paper_keys()
    ('song2023', 'ren2005', 'bhattacharjee2021', 'vlahakis')
    """
    return tuple(reg.key for reg in paper_registries())


def comparison_registries() -> tuple[PaperRegistry, ...]:
    """The registries of the comparisons (:data:`COMPARISON_MODULES`), whose ledgers follow the papers'.

    Returns
    -------
    tuple of PaperRegistry
        One per comparison.

    Examples
    --------
    >>> from mascore.registry import comparison_registries
    >>> [reg.key for reg in comparison_registries()]
    ['compare']
    """
    return tuple(importlib.import_module(name).REGISTRY for name in COMPARISON_MODULES)


def ledger_keys() -> tuple[str, ...]:
    """Every ledger's key: the papers', in book order, then the comparisons'.

    Returns
    -------
    tuple of str
        The keys; each ledger is ``results/<key>/claims.json`` and its claim ids start with ``<key>/``.

    Examples
    --------
    >>> from mascore.registry import ledger_keys
    >>> ledger_keys()
    ('song2023', 'ren2005', 'bhattacharjee2021', 'vlahakis', 'compare')
    """
    return (*paper_keys(), *(reg.key for reg in comparison_registries()))


def paper_registry(key: str) -> PaperRegistry:
    """The :class:`PaperRegistry` of a paper (``REGISTRY`` of ``mascore.papers.<key>``) or a comparison.

    Parameters
    ----------
    key : str
        One of :func:`ledger_keys`.

    Returns
    -------
    PaperRegistry
        The paper's registry.

    Examples
    --------
    >>> from mascore.registry import paper_registry
    >>> paper_registry("vlahakis").citation
    'Vlahakis and Halikias'
    """
    for reg in (*paper_registries(), *comparison_registries()):
        if reg.key == key:
            return reg
    raise ValueError(f"paper must be one of {', '.join(ledger_keys())}; got key {key!r}")


def write_study(paper: PaperRegistry, study: Study, result: Any, out_dir: str | Path) -> list[Claim]:
    """Write a study's figures (PNG) and tables (CSV) into `out_dir`; return its claims.

    Each claim is tagged with the study's name (``Claim.study``), so the report can
    link it to its chapter.

    Parameters
    ----------
    paper : PaperRegistry
        The paper.
    study : Study
        One of its studies.
    result : object
        The output of ``study.run``.
    out_dir : str or pathlib.Path
        The paper's output folder (``figures/`` and ``tables/`` are created in it).

    Returns
    -------
    list of mascore.ledger.Claim
        The study's claims.

    Examples
    --------
    >>> import dataclasses, tempfile
    >>> from mascore.papers import ren2005
    >>> from mascore.registry import write_study
    >>> study = ren2005.REGISTRY.study("kalman-consensus")
    >>> fewer = dataclasses.replace(study.settings, noise_runs=20, noise_paths=4, bias_runs=50)  # fewer runs
    >>> claims = write_study(ren2005.REGISTRY, study, study.run(fewer, 1), tempfile.mkdtemp())
    >>> {c.study for c in claims}
    {'kalman-consensus'}
    """
    if not isinstance(paper, PaperRegistry):
        raise TypeError(f"paper must be a PaperRegistry (a paper module's REGISTRY); got {type(paper).__name__}")
    if not isinstance(study, Study):
        raise TypeError(f"study must be a Study (one of paper.studies); got {type(study).__name__}")
    if not isinstance(out_dir, str | Path):
        raise TypeError(f"out_dir must be a path (str or pathlib.Path); got {type(out_dir).__name__}")
    plt = require("matplotlib.pyplot", "drawing a registered figure")

    from .plotting import save_figure

    out_dir = Path(out_dir)
    for spec in study.figures:
        save_figure(study.draw(spec.name, result), out_dir / "figures" / f"{spec.name}.png")
        plt.close("all")
    for spec in study.tables:
        (out_dir / "tables").mkdir(parents=True, exist_ok=True)
        spec.build(result).to_csv(out_dir / "tables" / f"{spec.name}.csv", index=False, float_format="%.6g")
    return [dataclasses.replace(c, study=study.name) for c in study.claims(result)]


# ---------------------------------------------------------------- settings


def setting(default: Any, *, source: str = "paper", where: str = "", unit: str = "", note: str = "",
            kind: str | None = None, low: float | None = None, high: float | None = None,
            low_open: bool = False, high_open: bool = False, choices: Sequence[Any] | None = None,
            length: int | None = None, check: Callable[[Any], str | None] | None = None) -> Any:
    """A settings-dataclass field that documents and checks itself.

    The declaration says what the field is (shown by :func:`show_settings` and
    :func:`documented_settings`) and which values it takes: ``check_settings``,
    called by the dataclass's ``__post_init__``, refuses any other value by the
    field's name, so construction and :func:`dataclasses.replace` both fail early.

    Parameters
    ----------
    default : object
        The value (use a tuple, not a list or array, to keep the dataclass frozen and hashable).
    source : {"paper", "chosen", "derived"}
        Given by the paper, chosen by us because the paper leaves it out, or derived from others.
    where : str
        Where the paper gives it (``"Table I"``) or why we chose it.
    unit : str
        Physical unit, ``""`` if dimensionless.
    note : str
        One short phrase on what it is.
    kind : {"real", "integer", "bool", "text", "choice", "reals", "integers", "matrix"}, optional
        What the value is: a finite number, an integer (not a bool), a bool, a string, one of
        `choices`, a tuple of finite numbers or of integers, or a rectangular tuple of tuples
        of finite numbers. Default: inferred from `default` (``"choice"`` when `choices` is given).
    low, high : float, optional
        Bounds of the value (of every entry for tuples and matrices).
    low_open, high_open : bool
        Whether the bound itself is excluded (``low=0, low_open=True`` means ``> 0``).
    choices : sequence, optional
        The allowed values of a ``"choice"``.
    length : int, optional
        Required number of entries of a tuple (``"reals"``, ``"integers"``).
    check : callable, optional
        ``check(value) -> None`` if the value is allowed, else a phrase naming what it must be
        (``"a (n, n) matrix"``); runs after the checks above.

    Returns
    -------
    dataclasses.Field
        The field, its metadata read by :func:`show_settings`, :func:`documented_settings`
        and ``check_settings``.

    Raises
    ------
    ValueError
        If `source` or `kind` is not one of the above.

    Examples
    --------
    >>> from dataclasses import dataclass, fields, replace
    >>> from mascore.registry import check_settings, setting
    >>> @dataclass(frozen=True)
    ... class Demo:
    ...     dt: float = setting(0.1, source="paper", where="Table I", unit="s", note="sampling time",
    ...                         low=0, low_open=True)
    ...     def __post_init__(self):
    ...         check_settings(self)
    >>> fields(Demo)[0].metadata["unit"]
    's'
    >>> replace(Demo(), dt=-0.1)
    Traceback (most recent call last):
    ...
    ValueError: Demo.dt must be a finite number > 0 s; got -0.1
    """
    if source not in ("paper", "chosen", "derived"):
        raise ValueError(f"source must be 'paper', 'chosen' or 'derived'; got {source!r}")
    if kind is None:
        kind = "choice" if choices is not None else _infer_kind(default)
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {', '.join(_KINDS)}; got {kind!r}")
    if kind == "choice" and not choices:
        raise ValueError("a 'choice' setting needs its choices")
    return field(default=default, metadata={
        "source": source, "where": where, "unit": unit, "note": note, "kind": kind, "low": low, "high": high,
        "low_open": bool(low_open), "high_open": bool(high_open),
        "choices": tuple(choices) if choices is not None else None, "length": length, "check": check})


#: What a :func:`setting` can be (its ``kind``).
_KINDS = ("real", "integer", "bool", "text", "choice", "reals", "integers", "matrix")


def _is_int(x: Any) -> bool:
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


def _is_real(x: Any) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def _infer_kind(default: Any) -> str:
    if isinstance(default, (bool, np.bool_)):
        return "bool"
    if _is_int(default):
        return "integer"
    if _is_real(default):
        return "real"
    if isinstance(default, str):
        return "text"
    if isinstance(default, tuple) and default and all(_is_real(x) for x in default):
        return "integers" if all(_is_int(x) for x in default) else "reals"
    if isinstance(default, tuple) and default and all(isinstance(r, tuple) for r in default):
        return "matrix"
    raise ValueError(f"cannot infer the kind of a setting from its default {default!r}; give kind=")


def _fmt_bound(x: float) -> str:
    return format(x, "g") if isinstance(x, float) else str(x)


def _range_text(meta: Mapping[str, Any]) -> str:
    """The bounds of a setting as text: ``"> 0"``, ``"in [0, 1]"``, ``""`` when unbounded."""
    low, high = meta.get("low"), meta.get("high")
    if low is not None and high is not None:
        return (f"in {'(' if meta.get('low_open') else '['}{_fmt_bound(low)}, {_fmt_bound(high)}"
                f"{')' if meta.get('high_open') else ']'}")
    if low is not None:
        return f"{'>' if meta.get('low_open') else '>='} {_fmt_bound(low)}"
    if high is not None:
        return f"{'<' if meta.get('high_open') else '<='} {_fmt_bound(high)}"
    return ""


def allowed_values(meta: Mapping[str, Any]) -> str:
    """What a :func:`setting` accepts, in words (its field's ``metadata``), without the unit.

    Parameters
    ----------
    meta : mapping
        The ``metadata`` of a field declared with :func:`setting`.

    Returns
    -------
    str
        E.g. ``"a finite number > 0"``, ``"an integer in [1, 10]"``, ``"one of 'sdp', 'closed_form'"``.

    Examples
    --------
    >>> import dataclasses
    >>> from mascore.papers import song2023
    >>> from mascore.registry import allowed_values
    >>> field = {f.name: f for f in dataclasses.fields(song2023.SETTINGS)}["dt"]
    >>> allowed_values(field.metadata)
    'a finite number > 0'
    """
    kind, bounds = meta.get("kind"), _range_text(meta)
    length = meta.get("length")
    many = f"a tuple of {length} " if length else "a non-empty tuple of "
    text = {"real": "a finite number", "integer": "an integer", "bool": "True or False", "text": "a string",
            "reals": many + "finite numbers", "integers": many + "integers",
            "matrix": "a rectangular tuple of tuples of finite numbers"}.get(kind, "")
    if kind == "choice":
        return "one of " + ", ".join(repr(c) for c in meta["choices"])
    if bounds:
        text += (" " if kind in ("real", "integer") else ", each ") + bounds
    return text


def _setting_error(settings: Any, f: dataclasses.Field, value: Any, what: str | None = None,
                   error: type[Exception] = ValueError) -> Exception:
    meta = f.metadata
    what = what or allowed_values(meta)
    unit = f" {meta['unit']}" if meta.get("unit") and meta.get("kind") in ("real", "reals", "matrix") else ""
    shown = repr(value)
    if len(shown) > 80:
        shown = shown[:77] + "..."
    return error(f"{type(settings).__name__}.{f.name} must be {what}{unit}; got {shown}")


def _in_range(x: float, meta: Mapping[str, Any]) -> bool:
    low, high = meta.get("low"), meta.get("high")
    if low is not None and (x < low or (meta.get("low_open") and x == low)):
        return False
    return not (high is not None and (x > high or (meta.get("high_open") and x == high)))


def check_settings(settings: Any) -> None:
    """Check every field of a settings dataclass against its :func:`setting` declaration.

    Call it first thing in the dataclass's ``__post_init__``; construction and
    :func:`dataclasses.replace` then refuse a bad value with an error naming the
    class, the field, the allowed values and the unit. A list or array given for a
    tuple field is stored as a tuple (the dataclass stays frozen and hashable).
    Fields not declared with :func:`setting` are not checked.

    Parameters
    ----------
    settings : dataclass instance
        The settings being built.

    Raises
    ------
    TypeError
        If a field has the wrong type (a float for an integer, a string for a number, ...).
    ValueError
        If a field is out of its range, not finite, or not one of its choices.

    Examples
    --------
    >>> import dataclasses
    >>> from mascore.papers import ren2005
    >>> dataclasses.replace(ren2005.SETTINGS, n_steps=0)
    Traceback (most recent call last):
    ...
    ValueError: KalmanConsensusSettings.n_steps must be an integer >= 1; got 0
    """
    if not dataclasses.is_dataclass(settings) or isinstance(settings, type):
        raise TypeError(f"settings must be a dataclass instance; got {type(settings).__name__}")
    for f in dataclasses.fields(settings):
        meta = f.metadata
        kind = meta.get("kind")
        if kind is None:
            continue
        value = getattr(settings, f.name)
        if kind in ("reals", "integers", "matrix") and isinstance(value, (list, np.ndarray)):
            value = _as_tuple(value)
            object.__setattr__(settings, f.name, value)
        _check_field(settings, f, value, kind, meta)
        check = meta.get("check")
        if check is not None:
            problem = check(value)
            if problem:
                raise _setting_error(settings, f, value, problem)


def _as_tuple(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list):
        return tuple(_as_tuple(v) for v in value)
    return value


def _check_field(settings: Any, f: dataclasses.Field, value: Any, kind: str, meta: Mapping[str, Any]) -> None:
    if kind == "bool":
        if not isinstance(value, (bool, np.bool_)):
            raise _setting_error(settings, f, value, error=TypeError)
    elif kind == "text":
        if not isinstance(value, str):
            raise _setting_error(settings, f, value, error=TypeError)
    elif kind == "choice":
        try:
            ok = value in meta["choices"]
        except TypeError:  # an unhashable value
            ok = False
        if not ok:
            raise _setting_error(settings, f, value)
    elif kind in ("real", "integer"):
        if not (_is_int(value) if kind == "integer" else _is_real(value)):
            raise _setting_error(settings, f, value, error=TypeError)
        if not np.isfinite(float(value)) or not _in_range(float(value), meta):
            raise _setting_error(settings, f, value)
    else:
        if not isinstance(value, tuple):
            raise _setting_error(settings, f, value, error=TypeError)
        rows = value if kind == "matrix" else (value,)
        if kind == "matrix" and not (rows and all(isinstance(r, tuple) and r for r in rows)
                                     and len({len(r) for r in rows}) == 1):
            raise _setting_error(settings, f, value, error=TypeError)
        if not rows[0] or (meta.get("length") is not None and len(value) != meta["length"]):
            raise _setting_error(settings, f, value)
        entry = _is_int if kind == "integers" else _is_real
        if not all(entry(x) for r in rows for x in r):
            raise _setting_error(settings, f, value, error=TypeError)
        if not all(np.isfinite(float(x)) and _in_range(float(x), meta) for r in rows for x in r):
            raise _setting_error(settings, f, value)


def check_settings_type(settings: Any, cls: type, name: str = "settings") -> Any:
    """Return `settings` if it is an instance of `cls`, else raise ``TypeError`` naming `name`.

    Parameters
    ----------
    settings : object
        The argument.
    cls : type
        The settings dataclass it must be.
    name : str
        The argument's name.

    Returns
    -------
    object
        `settings`.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> from mascore.registry import check_settings_type
    >>> check_settings_type(ren2005.SETTINGS, ren2005.KalmanConsensusSettings) is ren2005.SETTINGS
    True
    """
    if not isinstance(settings, cls):
        raise TypeError(f"{name} must be a {cls.__name__} (change one with dataclasses.replace); "
                        f"got {type(settings).__name__}")
    return settings


def documented_settings(settings_class: type) -> type:
    """Complete a settings dataclass's docstring from its :func:`setting` fields.

    Appends a numpydoc Parameters section (one entry per field: its default with unit,
    whether the paper gives it or we chose it, the note and the allowed values) and an Examples section,
    so the API reference shows every setting of a paper without a second copy of them.
    Apply it above ``@dataclass``.

    Parameters
    ----------
    settings_class : type
        A dataclass whose fields were declared with :func:`setting`.

    Returns
    -------
    type
        `settings_class`, with its ``__doc__`` completed.

    Raises
    ------
    TypeError
        If `settings_class` is not a dataclass, or defines no ``__post_init__`` (which must call
        ``check_settings``).

    Examples
    --------
    >>> from mascore.papers.ren2005 import KalmanConsensusSettings
    >>> "Omega : " in KalmanConsensusSettings.__doc__
    True
    """
    if not (isinstance(settings_class, type) and dataclasses.is_dataclass(settings_class)):
        raise TypeError(f"documented_settings needs a dataclass; got {settings_class!r}")
    if "__post_init__" not in vars(settings_class):
        raise TypeError(f"{settings_class.__name__} must check its fields: define __post_init__ calling "
                        f"mascore.registry.check_settings(self)")
    lines = [(settings_class.__doc__ or settings_class.__name__).rstrip(), "", "Parameters", "----------"]
    for f in dataclasses.fields(settings_class):
        meta = f.metadata
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
        value = format_value(default, max_items=6) + (f" {meta['unit']}" if meta.get("unit") else "")
        origin = {"paper": "the paper", "chosen": "our choice", "derived": "derived"}.get(meta.get("source"), "")
        if meta.get("where"):
            origin += f", {meta['where']}"
        text = f"{meta.get('note') or f.name} ({origin})." if origin else f"{meta.get('note') or f.name}."
        if meta.get("kind"):
            text += f" Allowed: {allowed_values(meta)}" + (f" {meta['unit']}." if meta.get("unit") and meta.get(
                "kind") in ("real", "reals", "matrix") else ".")
        lines += [f"{f.name} : default {_rst(value)}", f"    {_rst(text)}"]
    first = dataclasses.fields(settings_class)[0].name
    lines += ["", "Examples", "--------", ">>> import dataclasses",
              f">>> from {settings_class.__module__} import {settings_class.__name__}",
              f">>> settings = {settings_class.__name__}()",
              f">>> changed = dataclasses.replace(settings, {first}=settings.{first})   # change any setting by name",
              ">>> changed == settings", "True"]
    settings_class.__doc__ = "\n".join(lines)
    return settings_class


@dataclass(frozen=True)
class SettingsView:
    """A settings dataclass laid out as a Markdown table (Jupyter shows it as such).

    Parameters
    ----------
    settings : dataclass instance
        Settings declared with :func:`setting`.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> from mascore.registry import SettingsView
    >>> str(SettingsView(ren2005.SETTINGS)).splitlines()[0]
    '| setting | value | allowed | from | note |'
    """

    settings: Any

    def _repr_markdown_(self) -> str:
        rows = ["| setting | value | allowed | from | note |", "|---|---|---|---|---|"]
        for f in dataclasses.fields(self.settings):
            meta = f.metadata
            value = format_value(getattr(self.settings, f.name), max_items=12)
            if meta.get("unit"):
                value += f" {meta['unit']}"
            origin = {"paper": "paper", "chosen": "**our choice**", "derived": "derived"}.get(meta.get("source"), "")
            if meta.get("where"):
                origin += f" ({meta['where']})"
            allowed = allowed_values(meta) if meta.get("kind") else ""
            rows.append(f"| `{f.name}` | {_cell(value)} | {_cell(allowed)} | {_cell(origin)} "
                        f"| {_cell(meta.get('note', ''))} |")
        return "\n".join(rows)

    __str__ = _repr_markdown_


def show_settings(settings: Any) -> SettingsView:
    """Display a settings dataclass as a table: value with unit, whether the paper gives it, a note.

    Parameters
    ----------
    settings : dataclass instance
        Settings declared with :func:`setting`.

    Returns
    -------
    SettingsView
        Shown as a Markdown table by Jupyter.

    Raises
    ------
    TypeError
        If `settings` is not a dataclass instance.

    Examples
    --------
    >>> from mascore.papers import song2023
    >>> from mascore.registry import show_settings
    >>> "sampling time" in str(show_settings(song2023.SETTINGS))
    True
    """
    if not dataclasses.is_dataclass(settings):
        raise TypeError(f"settings must be a dataclass instance; got {type(settings).__name__}")
    return SettingsView(settings)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def all_figures(papers: Sequence[str] | None = None) -> list[tuple[PaperRegistry, Study, FigureSpec]]:
    """Every registered figure as ``(paper, study, spec)``, in book order.

    Parameters
    ----------
    papers : sequence of str, optional
        Paper keys (default all, :func:`paper_keys`).

    Returns
    -------
    list of tuple
        ``(PaperRegistry, Study, FigureSpec)`` per figure.

    Examples
    --------
    >>> from mascore.registry import all_figures
    >>> len(all_figures(["ren2005"])) > 0
    True
    """
    if papers is not None and (isinstance(papers, str) or not isinstance(papers, Sequence)
                               or not all(isinstance(p, str) for p in papers)):
        raise TypeError(f"papers must be a sequence of paper keys (e.g. ['ren2005']) or None; got {papers!r}")
    out = []
    for key in paper_keys() if papers is None else papers:
        reg = paper_registry(key)
        out += [(reg, s, f) for s in reg.studies for f in s.figures]
    return out


def _rst(text: str) -> str:
    """MyST text of a setting as reStructuredText: ``$x$`` as :math:`x`, ``|x|`` not a substitution."""
    text = text.replace("|", "\\|")
    return re.sub(r"\$([^$]+)\$", lambda m: ":math:`" + m.group(1).replace("\\|", "|") + "`", text)
