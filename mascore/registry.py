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
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._optional import require
from ._runstore import read_run, run_digest, write_run
from .claims import Claim
from .settings import (
    SettingsView,
    allowed_values,
    check_settings,
    check_settings_type,
    documented_settings,
    setting,
    show_settings,
)

if TYPE_CHECKING:  # pragma: no cover
    import matplotlib.figure
    import pandas as pd

__all__ = [
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
    "render_figure",
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
        >>> fewer = dataclasses.replace(study.settings, noise_runs=20, noise_paths=4, bias_runs=50,
        ...                                             switch_steps=100, t_final=20.0)  # fewer runs, shorter switching demos
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

    def run_key(self, settings: Any, seed: int) -> str:
        """The identity of one run: the study, its settings, the seed and the package's source code.

        Two runs with the same key give the same numbers, byte for byte; a run stored under
        another key (other settings, another seed, or any edited module) is never reused.

        Parameters
        ----------
        settings : frozen dataclass
            The run's settings.
        seed : int
            The run's seed.

        Returns
        -------
        str
            A SHA-256 digest (64 hexadecimal digits).

        Examples
        --------
        >>> from mascore.papers import ren2005
        >>> study = ren2005.REGISTRY.study("kalman-consensus")
        >>> study.run_key(study.settings, 0) == study.run_key(study.settings, 1)
        False
        """
        kind = f"{type(settings).__module__}.{type(settings).__qualname__}"
        return run_digest((self.name, self.chapter, kind, settings, int(seed)))

    def save_run(self, settings: Any, seed: int, result: Any, store: str | Path,
                 pickled: bytes | None = None) -> Path | None:
        """Store a run's result in `store` for :meth:`load_or_run` (``store/runs/NAME.pickle``).

        ``python -m mascore reproduce`` stores every run it makes in the paper's results
        folder, so that the chapters draw the very run the ledger was computed from.

        Parameters
        ----------
        settings : frozen dataclass
            The settings the result was computed with.
        seed : int
            Its seed.
        result : object
            The output of ``self.run(settings, seed)``.
        store : str or pathlib.Path
            The folder (a paper's results folder).
        pickled : bytes, optional
            ``pickle.dumps(result, protocol=4)`` made by the process that computed `result`
            (a Dask worker), written as it is: the file is then the same, byte for byte, as
            a run in this process writes (a result sent between processes keeps its values,
            not which of its strings are one object).

        Returns
        -------
        pathlib.Path or None
            The file written; None if the result cannot be pickled (a study defined inside a
            function, say): nothing is stored and :meth:`load_or_run` computes the run.

        Examples
        --------
        >>> import dataclasses, tempfile
        >>> from mascore.papers import ren2005
        >>> study = ren2005.REGISTRY.study("kalman-consensus")
        >>> fewer = dataclasses.replace(study.settings, noise_runs=20, noise_paths=4, bias_runs=50,
        ...                                             switch_steps=100, t_final=20.0)  # fewer runs, shorter switching demos
        >>> study.save_run(fewer, 1, study.run(fewer, 1), tempfile.mkdtemp()).name
        'kalman-consensus.pickle'
        """
        return write_run(Path(store) / "runs" / f"{self.name}.pickle", self.run_key(settings, seed), result,
                          pickled)

    def load_or_run(self, settings: Any, seed: int, store: str | Path | None = None, progress: bool = False) -> Any:
        """The study's result: read from `store` if this exact run is stored there, else computed.

        A stored run is used only if its :meth:`run_key` is this one (same settings, seed and
        package source); otherwise, or without a store, the run is computed with
        ``self.run(settings, seed)``. Only read stores you wrote yourself (the file is a pickle).

        Parameters
        ----------
        settings : frozen dataclass
            The run's settings.
        seed : int
            The run's seed.
        store : str or pathlib.Path, optional
            A folder that :meth:`save_run` wrote to (a paper's results folder).
        progress : bool
            Show progress bars if the run is computed.

        Returns
        -------
        object
            The result, equal to ``self.run(settings, seed)``.

        Examples
        --------
        >>> import dataclasses, tempfile
        >>> from mascore.papers import ren2005
        >>> study = ren2005.REGISTRY.study("kalman-consensus")
        >>> fewer = dataclasses.replace(study.settings, noise_runs=20, noise_paths=4, bias_runs=50,
        ...                                             switch_steps=100, t_final=20.0)  # fewer runs, shorter switching demos
        >>> folder = tempfile.mkdtemp()
        >>> path = study.save_run(fewer, 1, study.run(fewer, 1), folder)
        >>> study.load_or_run(fewer, 1, folder).settings == fewer  # read, not recomputed
        True
        """
        if store is not None:
            found, result = read_run(Path(store) / "runs" / f"{self.name}.pickle", self.run_key(settings, seed))
            if found:
                return result
        return self.run(settings, seed, progress=progress)

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
    kind : {"paper", "comparison"}
        A paper, or a comparison of the papers' methods (its ledger follows the papers':
        :func:`comparison_registries`).

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
    kind: str = "paper"

    def __post_init__(self) -> None:
        if self.kind not in ("paper", "comparison"):
            raise ValueError(f"kind must be 'paper' or 'comparison'; got {self.kind!r}")
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
    >>> import dataclasses
    >>> from mascore.papers import ren2005
    >>> study = ren2005.REGISTRY.study("kalman-consensus")
    >>> fewer = dataclasses.replace(ren2005.SETTINGS, noise_runs=20, noise_paths=4, bias_runs=50,
    ...                                               switch_steps=100, t_final=20.0)  # fewer runs, shorter switching demos
    >>> values = caption_values(study, ren2005.run(fewer, seed=1))
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
    comparisons = {id(s) for reg in comparison_registries() for s in reg.studies}  # their own chapter
    with_study = {id(m.STUDY): m for m in modules
                  if isinstance(getattr(m, "STUDY", None), Study) and id(m.STUDY) not in comparisons}
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
    found = [reg for reg in _registries() if reg.kind == "paper"]
    positions = [reg.position for reg in found]
    if len(set(positions)) != len(positions):
        raise ValueError(f"papers must have distinct positions; got {dict((r.key, r.position) for r in found)}")
    return tuple(sorted(found, key=lambda reg: reg.position))


def _registries() -> list[PaperRegistry]:
    """Every ``REGISTRY`` of ``mascore.papers`` (papers and comparisons), its key checked against its module."""
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
    return found


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
    """The registries of the comparisons (``kind="comparison"``, in ``mascore.papers``), whose ledgers follow the papers'.

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
    return tuple(sorted((reg for reg in _registries() if reg.kind == "comparison"), key=lambda reg: reg.position))


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


def write_study(paper: PaperRegistry, study: Study, result: Any, out_dir: str | Path,
                figures: Mapping[str, Mapping[str, bytes]] | None = None) -> list[Claim]:
    """Write a study's figures (PNG) and tables (CSV) into `out_dir`; return its claims.

    Beside each figure, ``NAME.layout.json`` lists the legends that cover its data
    (:func:`mascore.plotting.legend_overlaps`) and the panels with more than five unlabelled
    lines (:func:`mascore.plotting.unlabelled_lines`); both empty when none.

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
    figures : mapping of str to mapping, optional
        Figures already drawn from `result` elsewhere (on Dask workers, say): figure name ->
        :func:`render_figure`'s files. The figures not in it are drawn here.

    Returns
    -------
    list of mascore.ledger.Claim
        The study's claims.

    Examples
    --------
    >>> import dataclasses, tempfile
    >>> from mascore.papers import bhattacharjee2021
    >>> from mascore.registry import write_study
    >>> study = bhattacharjee2021.REGISTRY.study("set-membership")
    >>> quick = dataclasses.replace(study.settings, n_runs=3, t_f=10, figure_method="closed_form")  # a quick look
    >>> claims = write_study(bhattacharjee2021.REGISTRY, study, study.run(quick, 1), tempfile.mkdtemp())
    >>> {c.study for c in claims}
    {'set-membership'}
    """
    if not isinstance(paper, PaperRegistry):
        raise TypeError(f"paper must be a PaperRegistry (a paper module's REGISTRY); got {type(paper).__name__}")
    if not isinstance(study, Study):
        raise TypeError(f"study must be a Study (one of paper.studies); got {type(study).__name__}")
    if not isinstance(out_dir, str | Path):
        raise TypeError(f"out_dir must be a path (str or pathlib.Path); got {type(out_dir).__name__}")
    out_dir = Path(out_dir)
    drawn = figures or {}
    for spec in study.figures:
        files = drawn[spec.name] if spec.name in drawn else render_figure(study, spec.name, result)
        for relative, data in files.items():
            path = out_dir / relative
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
    for spec in study.tables:
        (out_dir / "tables").mkdir(parents=True, exist_ok=True)
        spec.build(result).to_csv(out_dir / "tables" / f"{spec.name}.csv", index=False, float_format="%.6g")
    return [dataclasses.replace(c, study=study.name) for c in study.claims(result)]


def render_figure(study: Study, name: str, result: Any) -> dict[str, bytes]:
    """Draw one figure of a study from its result: the files :func:`write_study` writes for it.

    Depends on nothing but its arguments, so the figures of a run can be drawn in any
    process (``mascore reproduce --workers``) and give the same bytes.

    Parameters
    ----------
    study : Study
        The study.
    name : str
        One of its figures.
    result : object
        The output of ``study.run``.

    Returns
    -------
    dict of str to bytes
        ``figures/NAME.png`` (the figure, at the book's style and resolution) and
        ``figures/NAME.layout.json`` (its legends over data and crowded panels), by path
        relative to the paper's folder.

    Examples
    --------
    >>> import dataclasses
    >>> from mascore.papers import ren2005
    >>> from mascore.registry import render_figure
    >>> study = ren2005.REGISTRY.study("kalman-consensus")
    >>> fewer = dataclasses.replace(study.settings, noise_runs=20, noise_paths=4, bias_runs=50,
    ...                                             switch_steps=100, t_final=20.0)  # fewer runs, shorter switching demos
    >>> sorted(render_figure(study, "fig1", study.run(fewer, 1)))
    ['figures/fig1.layout.json', 'figures/fig1.png']
    """
    import io
    import json

    from .plotting import legend_overlaps, unlabelled_lines

    plt = require("matplotlib.pyplot", "drawing a registered figure")
    fig = study.draw(name, result)
    try:
        layout = {"legend_overlaps": legend_overlaps(fig),  # read by the book's tests: no legend over data,
                  "unlabelled_lines": unlabelled_lines(fig)}  # no panel with more than five unlabelled lines
        png = io.BytesIO()
        fig.savefig(png, format="png")
    finally:
        plt.close("all")
    return {f"figures/{name}.png": png.getvalue(),
            f"figures/{name}.layout.json": (json.dumps(layout, indent=1) + "\n").encode()}


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
