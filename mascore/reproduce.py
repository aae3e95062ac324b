"""``python -m mascore reproduce PAPER|all``: rebuild a paper's figures, tables and ledger.

Each paper module ``mascore.papers.<PAPER>`` declares its registry ``REGISTRY``
(:class:`mascore.registry.PaperRegistry`); for every study this module calls
``study.run(study.settings, seed)`` and writes, through one generic writer
(:func:`mascore.registry.write_study`), ``out_dir/figures/*.png``,
``out_dir/tables/*.csv`` and ``out_dir/claims.json``.

A paper's directory is replaced all at once: everything is written into a
temporary directory beside it, which takes the place of the old one in a
rename only when the whole paper succeeded. On a failure or an interrupt the
previous complete output stays as it was. ``claims.json`` records the SHA-256
of every figure and table it belongs with, so a directory whose files do not
match its ledger is detected (:func:`mascore.ledger.verify_outputs`).
"""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ._progress import progress_bar
from .ledger import Claim, output_hashes, write_claims
from .registry import paper_keys, paper_registry, write_study

__all__ = ["DEFAULT_SEED", "apply_settings", "available_papers", "changed_claims", "main", "reproduce_paper",
           "project_dir", "reproduce_papers", "results_dir", "settings_folder"]

#: Seed used when the caller gives none.
DEFAULT_SEED = 1


def results_dir() -> Path:
    """The project's ``results/`` folder, found from the current directory.

    Uses ``$MASCORE_RESULTS`` if set, else ``results/`` beside the nearest
    ``pyproject.toml`` above the working directory (so notebooks executed from
    ``notebooks/`` or the book find it), else ``./results``.

    Returns
    -------
    pathlib.Path
        The folder (it may not exist yet).

    Examples
    --------
    >>> import os
    >>> from mascore.reproduce import results_dir
    >>> os.environ["MASCORE_RESULTS"] = "/tmp/my-results"
    >>> str(results_dir())
    '/tmp/my-results'
    >>> del os.environ["MASCORE_RESULTS"]
    """
    import os

    if os.environ.get("MASCORE_RESULTS"):
        return Path(os.environ["MASCORE_RESULTS"])
    return project_dir() / "results"


def project_dir() -> Path:
    """The checkout the working directory is in: the nearest folder above it with a ``pyproject.toml``.

    The notebooks read the data committed beside the package from there (``benchmarks/data``); outside a
    checkout, the working directory itself.

    Returns
    -------
    pathlib.Path
        The folder.

    Examples
    --------
    >>> from mascore.reproduce import project_dir
    >>> (project_dir() / "pyproject.toml").exists()
    True
    """
    here = Path.cwd().resolve()
    return next((folder for folder in (here, *here.parents) if (folder / "pyproject.toml").exists()), here)


def available_papers() -> list[str]:
    """The keys of every paper, in book order (discovered: :func:`mascore.registry.paper_keys`).

    Returns
    -------
    list of str
        The keys.

    Examples
    --------
    >>> from mascore.reproduce import available_papers
    >>> available_papers()
    ['song2023', 'ren2005', 'bhattacharjee2021', 'vlahakis']
    """
    return list(paper_keys())


def reproduce_paper(
    paper: str, out: str | Path = "results", seed: int = DEFAULT_SEED, created_by: str | None = None,
    progress: bool = True, overrides: dict[str, str] | None = None, workers: int = 0,
) -> list[Claim]:
    """Run one paper's reproduction and write its figures, tables and ledger, all or nothing.

    Parameters
    ----------
    paper : str
        One of :func:`mascore.registry.paper_keys`.
    out : str or pathlib.Path
        Results root; files go to ``out/PAPER/``, which is replaced as a whole.
    seed : int
        Seed of every random draw in the run (non-negative).
    created_by : str, optional
        Command line recorded in ``claims.json`` (default: the equivalent
        ``mascore reproduce`` command, without paths).
    progress : bool
        Show progress bars of the long runs.
    overrides : dict of str to str, optional
        Settings to change, ``{name: value}`` as typed on the command line
        (:func:`apply_settings`); the results then go to ``out/PAPER-set-NAME=VALUE.../``,
        beside the default ones, which stay as they are.
    workers : int
        0 (default): everything in this process. K >= 1: the paper's studies run, and their
        figures are drawn, on a local Dask cluster of K single-threaded worker processes
        (:func:`reproduce_papers`); the files are the same, byte for byte.

    Returns
    -------
    list of Claim
        The paper's claims, as written to ``claims.json``.

    Raises
    ------
    ValueError
        Unknown `paper`, negative or non-integer `seed`, or `out` is a file.

    Examples
    --------
    ``make reproduce`` (and ``make test``, first) calls it for every paper:

    >>> import tempfile
    >>> from mascore.reproduce import reproduce_paper
    >>> claims = reproduce_paper("ren2005", out=tempfile.mkdtemp(), progress=False)  # doctest: +SKIP
    >>> sorted({c.verdict for c in claims})  # doctest: +SKIP
    ['holds']
    >>> reproduce_paper("ren2006", out=tempfile.mkdtemp())
    Traceback (most recent call last):
    ...
    ValueError: paper must be one of song2023, ren2005, bhattacharjee2021, vlahakis or 'all'; got 'ren2006'
    """
    if paper not in paper_keys():
        raise ValueError(f"paper must be one of {', '.join(paper_keys())} or 'all'; got {paper!r}")
    ((_, outcome),) = reproduce_papers([paper], out, seed, created_by, progress, overrides, workers)
    if isinstance(outcome, BaseException):
        raise outcome
    return outcome


def reproduce_papers(
    papers: list[str], out: str | Path = "results", seed: int = DEFAULT_SEED, created_by: str | None = None,
    progress: bool = True, overrides: dict[str, str] | None = None, workers: int = 0,
) -> Iterator[tuple[str, list[Claim] | Exception]]:
    """Reproduce several papers, serially or on a local Dask cluster; each paper's outcome as it is written.

    The independent parts of the papers' studies are what the workers share: every
    study's run, then every figure drawn from it (a figure waits only for its own run).
    The tables, claims and files are written in this process, paper by paper in the
    order given, through the same writer as a serial run: the files are the same, byte
    for byte, with any number of workers (the workers compute with one BLAS thread, as
    this process does under ``OMP_NUM_THREADS=1``). Each paper's folder is replaced all
    at once (:func:`reproduce_paper`); a paper that fails leaves its old folder and does
    not stop the others.

    Parameters
    ----------
    papers : list of str
        Paper keys (:func:`mascore.registry.paper_keys`), each once.
    out : str or pathlib.Path
        Results root; paper P goes to ``out/P/`` (or its :func:`settings_folder`).
    seed : int
        Seed of every random draw (non-negative).
    created_by : str, optional
        Command line recorded in each ``claims.json`` (default: ``mascore reproduce P --seed S``).
    progress : bool
        Show the progress bars of the long runs (serial only: the workers run without).
    overrides : dict of str to str, optional
        Settings to change (:func:`apply_settings`; one paper only).
    workers : int
        0: in this process. K >= 1: on K local worker processes
        (:func:`mascore.sweep.dask_client`; a script that calls this needs
        ``if __name__ == "__main__":``).

    Yields
    ------
    tuple of (str, list of Claim or Exception)
        Each paper and its claims, or the error that stopped it, in the order of `papers`.

    Raises
    ------
    ValueError
        An unknown or repeated paper, `overrides` with more than one paper, a bad `seed`,
        `workers` or `out` (before any work).

    Examples
    --------
    >>> import tempfile
    >>> from mascore.reproduce import reproduce_papers
    >>> for paper, claims in reproduce_papers(["ren2005", "vlahakis"], tempfile.mkdtemp(),
    ...                                       workers=2):  # doctest: +SKIP
    ...     print(paper, len(claims))
    ren2005 9
    vlahakis 12
    """
    papers = list(papers)
    unknown = [p for p in papers if p not in paper_keys()]
    if unknown or len(set(papers)) != len(papers):
        raise ValueError(f"papers must be distinct keys of {', '.join(paper_keys())}; got {papers!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer; got {seed!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise ValueError(f"workers must be a non-negative integer (0: in this process); got {workers!r}")
    if overrides and len(papers) != 1:
        raise ValueError(f"overrides apply to one paper's settings; got {len(papers)} papers")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"out must be a directory; {str(out)!r} is a file")
    settings = {p: apply_settings(p, overrides or {}) for p in papers}
    out.mkdir(parents=True, exist_ok=True)
    if workers == 0:
        for paper in papers:
            yield paper, _write_paper(paper, out, seed, created_by, settings[paper], overrides,
                                      lambda study, s: (study.run(s, seed, progress=progress), None, None))
        return
    from .sweep import dask_client

    with dask_client(workers) as client:
        parts = _submit_parts(client, papers, settings, seed)

        def gathered(study, _settings):
            run, figures = parts.pop((study.chapter, study.name))  # the futures go once gathered
            result, pickled = _unpickled(run.result())
            return result, pickled, {name: future.result() for name, future in figures.items()}

        for paper in papers:
            yield paper, _write_paper(paper, out, seed, created_by, settings[paper], overrides, gathered)


def _submit_parts(client: Any, papers: list[str], settings: dict, seed: int) -> dict:
    """Submit every study's run and, after it, each of its figures: (chapter, study) -> (run, {figure: future})."""
    parts = {}
    for paper in papers:
        for study in paper_registry(paper).studies:
            run = client.submit(_pickled_run, study, settings[paper][study.name], seed, pure=False,
                                key=f"run-{paper}-{study.name}")
            parts[study.chapter, study.name] = (run, {
                spec.name: client.submit(_figure_of_run, study, spec.name, run, pure=False,
                                         key=f"figure-{paper}-{study.name}-{spec.name}")
                for spec in study.figures})
    return parts


def _pickled_run(study: Any, settings: Any, seed: int) -> tuple[bytes | None, Any]:
    """A study's run on a worker, pickled there as :meth:`Study.save_run` pickles it: ``(bytes, None)``,
    or ``(None, result)`` when it cannot be pickled."""
    import pickle

    result = study.run(settings, seed, progress=False)
    try:
        return pickle.dumps(result, protocol=4), None
    except (pickle.PicklingError, AttributeError, TypeError):  # as save_run: such a run is not stored
        return None, result


def _unpickled(run: tuple[bytes | None, Any]) -> tuple[Any, bytes | None]:
    """The result of :func:`_pickled_run` and its pickle (None if it has none)."""
    import pickle

    pickled, result = run
    return (result, None) if pickled is None else (pickle.loads(pickled), pickled)


def _figure_of_run(study: Any, name: str, run: tuple[bytes | None, Any]) -> dict[str, bytes]:
    """One figure drawn on a worker from a run of :func:`_pickled_run`."""
    from .registry import render_figure

    return render_figure(study, name, _unpickled(run)[0])


def _write_paper(paper: str, out: Path, seed: int, created_by: str | None, settings: dict,
                 overrides: dict[str, str] | None, compute: Callable) -> list[Claim] | Exception:
    """Write one paper from ``compute(study, settings) -> (result, its pickle, figures drawn)`` (None: made here),
    all or nothing."""
    registry = paper_registry(paper)
    final = out / settings_folder(paper, overrides or {})
    staging = Path(tempfile.mkdtemp(prefix=f".{paper}-incomplete-", dir=out))
    try:
        claims: list[Claim] = []
        for study in registry.studies:
            result, pickled, figures = compute(study, settings[study.name])
            claims += write_study(registry, study, result, staging, figures)
            study.save_run(settings[study.name], seed, result, staging, pickled)  # the chapters draw this run
        write_claims(claims, staging / "claims.json", paper, seed,
                     created_by or f"mascore reproduce {paper} --seed {seed}", files=output_hashes(staging))
        _replace_directory(final, staging)
    except Exception as exc:  # reported by the caller; the old folder stays as it was
        shutil.rmtree(staging, ignore_errors=True)
        return exc
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return claims


def apply_settings(paper: str, overrides: dict[str, str]) -> dict[str, object]:
    """Each study's settings of `paper` with `overrides` applied, checked by the settings' own constraints.

    A name is a field of one or more of the paper's settings dataclasses (``n_runs``), or
    ``STUDY.name`` to change one study only. A value is read as a Python literal (``0.2``,
    ``20``, ``(0.5, 1.5)``, ``'ring'``), else kept as text; the settings are rebuilt with
    :func:`dataclasses.replace` (all of a study's changes at once, so settings that must agree,
    such as ``n_agents`` and ``xi0``, change together), and a value outside the field's declared
    range is refused with the field's name, range and unit.

    Parameters
    ----------
    paper : str
        A paper's key.
    overrides : dict of str to str
        ``{name: value}`` as typed after ``--set``.

    Returns
    -------
    dict of str to settings
        Study name -> its settings (the defaults where nothing was changed).

    Raises
    ------
    ValueError, TypeError
        An unknown name (the message lists the paper's settings) or a value the setting refuses.

    Examples
    --------
    >>> from mascore.reproduce import apply_settings
    >>> apply_settings("ren2005", {"n_steps": "20"})["kalman-consensus"].n_steps
    20
    >>> apply_settings("ren2005", {"n_steps": "0"})
    Traceback (most recent call last):
    ...
    ValueError: KalmanConsensusSettings.n_steps must be an integer >= 1; got 0
    """
    import ast

    registry = paper_registry(paper)
    settings = {study.name: study.settings for study in registry.studies}
    changes: dict[str, dict] = {s: {} for s in settings}  # applied at once: n_agents and xi0 change together
    for name, text in overrides.items():
        study_name, _, field = name.rpartition(".")
        targets = [s for s in settings if (not study_name or s == study_name)
                   and field in {f.name for f in dataclasses.fields(settings[s])}]
        if not targets:
            known = sorted({f"{s}.{f.name}" for s in settings for f in dataclasses.fields(settings[s])})
            raise ValueError(f"--set {name}: {paper} has no setting of that name; its settings are "
                             f"{', '.join(known)} (STUDY.name, or the name alone when only one study has it)")
        try:
            value = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            value = text
        for s in targets:
            changes[s][field] = value
    return {s: dataclasses.replace(v, **changes[s]) if changes[s] else v for s, v in settings.items()}


def settings_folder(paper: str, overrides: dict[str, str]) -> str:
    """The folder name of a run at changed settings: ``PAPER`` alone for the defaults.

    Parameters
    ----------
    paper : str
        A paper's key.
    overrides : dict of str to str
        ``{name: value}`` as typed after ``--set``.

    Returns
    -------
    str
        ``PAPER-set-name=value+...`` (characters other than letters, digits, ``.``, ``=``, ``-``
        and ``_`` replaced by ``_``), so that the default ledger is never overwritten.

    Examples
    --------
    >>> from mascore.reproduce import settings_folder
    >>> settings_folder("ren2005", {"n_steps": "20"})
    'ren2005-set-n_steps=20'
    """
    import re

    if not overrides:
        return paper
    tag = "+".join(f"{k}={v}" for k, v in sorted(overrides.items()))
    return f"{paper}-set-" + re.sub(r"[^A-Za-z0-9.=_-]", "_", tag)


def changed_claims(default: list[dict], changed: list[dict]) -> list[str]:
    """The claims whose verdict differs between the default run and a run at other settings.

    Parameters
    ----------
    default, changed : list of dict
        Claim records (``claims.json``'s ``claims``) of the two runs.

    Returns
    -------
    list of str
        One line per claim whose verdict changed (``id: before -> after``), or that one run has
        and the other has not.

    Examples
    --------
    >>> from mascore.reproduce import changed_claims
    >>> changed_claims([{"id": "p/a", "verdict": "holds"}], [{"id": "p/a", "verdict": "fails"}])
    ['p/a: holds -> fails']
    """
    before = {c["id"]: c["verdict"] for c in default}
    after = {c["id"]: c["verdict"] for c in changed}
    lines = [f"{i}: {before.get(i, 'absent')} -> {after.get(i, 'absent')}"
             for i in sorted(set(before) | set(after)) if before.get(i) != after.get(i)]
    return lines


def _replace_directory(final: Path, staging: Path) -> None:
    """Put `staging` in the place of `final` (renames only; the old one is removed last)."""
    if not final.exists():
        staging.rename(final)
        return
    old = Path(tempfile.mkdtemp(prefix=f".{final.name}-old-", dir=final.parent))
    old.rmdir()
    final.rename(old)
    staging.rename(final)
    shutil.rmtree(old, ignore_errors=True)


def _non_negative_argument(what: str) -> Callable[[str], int]:
    """An argparse ``type`` that reads a non-negative integer; `what` ends its error message."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = -1
        if value < 0:
            raise argparse.ArgumentTypeError(f"expected a non-negative integer{what}, got {text!r}")
        return value
    return parse


_seed_argument = _non_negative_argument(" seed")
_workers_argument = _non_negative_argument(" (0: in this process)")


def _override_argument(text: str) -> tuple[str, str]:
    name, eq, value = text.partition("=")
    if not eq or not name.strip() or not value.strip():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE (e.g. n_runs=20), got {text!r}")
    return name.strip(), value.strip()


def _reproduce_at(args: argparse.Namespace) -> int:
    """``reproduce PAPER --set ...``: the run at other settings, its ledger beside the default, the changed claims."""
    import json

    overrides = dict(args.overrides)
    command = (f"mascore reproduce {args.paper} --seed {args.seed} --set "
               + " ".join(f"{k}={v}" for k, v in args.overrides))
    try:
        apply_settings(args.paper, overrides)  # refused before any work
    except (ValueError, TypeError) as exc:
        print(f"mascore: {exc}", file=sys.stderr)
        return 2
    start = time.perf_counter()
    claims = reproduce_paper(args.paper, args.out, args.seed, created_by=command, overrides=overrides,
                             workers=args.workers)
    folder = args.out / settings_folder(args.paper, overrides)
    print(f"{args.paper} at {', '.join(f'{k}={v}' for k, v in args.overrides)}: {len(claims)} claims in "
          f"{time.perf_counter() - start:.1f} s on {_where(args.workers)} -> {folder}")
    default = args.out / args.paper / "claims.json"
    if not default.exists():
        print(f"no default ledger at {default} to compare with (run `mascore reproduce {args.paper} --seed "
              f"{args.seed} --out {args.out}` first)")
        return 0
    lines = changed_claims(json.loads(default.read_text())["claims"], [c.to_dict() for c in claims])
    print(f"{len(lines)} claim(s) changed verdict against {default}" + (":" if lines else ""))
    for line in lines:
        print(f"  {line}")
    return 0


def _where(workers: int) -> str:
    """Where the work ran, for the command's summary line."""
    return f"{workers} local worker{'s' if workers > 1 else ''}" if workers else "this process"


def _out_argument(text: str) -> Path:
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"expected a directory, but {text!r} is a file")
    return path


def _compare_file(args: argparse.Namespace, workers: int, start: float) -> int:
    """``mascore compare --grid FILE.toml``: a sweep of the user's own cells, its table and summary."""
    import functools

    from .compare import run_cell, summarize
    from .compare.gridfile import AXES, read_grid
    from .sweep import run_sweep

    try:
        grid = read_grid(args.grid)
    except (ValueError, TypeError) as exc:
        print(f"mascore: {exc}", file=sys.stderr)
        return 2
    folder = args.out / "compare"
    table = run_sweep(list(grid.cells), functools.partial(run_cell, base_seed=args.seed, settings=grid.settings),
                      folder / f"table-{grid.name}-{args.seed}.csv", workers=workers, scheduler=args.scheduler,
                      progress=True)
    by = ["study", *AXES]  # every axis a study may set: no two cells of a file share a summary row
    table = table.assign(sensing=table["sensing"].fillna("-")) if "sensing" in table else table
    summary = summarize(table, by=[c for c in by if c in table.columns], settings=grid.settings)
    summary.to_csv(folder / f"summary-{grid.name}-{args.seed}.csv", index=False)
    columns = [c for c in (*by, "n", "ratio_mean", "ratio_lo", "ratio_hi", "nees_own_mean", "nees_bound_lo",
                           "nees_bound_hi") if c in summary.columns]
    print(summary[columns].to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    where = args.scheduler or _where(workers)
    print(f"compare: {len(grid.cells)} cells, {len(table)} runs in {time.perf_counter() - start:.1f} s on {where} "
          f"-> {folder / f'summary-{grid.name}-{args.seed}.csv'}")
    return 0


class _PaperChoices:
    """The choices of ``reproduce PAPER``: the discovered papers and ``all``, looked up only when needed
    (``mascore compare`` and ``--version`` do not import the papers)."""

    def __contains__(self, value: object) -> bool:
        return value == "all" or value in paper_keys()

    def __iter__(self):
        return iter([*paper_keys(), "all"])


def _grid_argument(value: str) -> str:
    """``--grid``: ``quick``, ``full`` or a grid file (:mod:`mascore.compare.gridfile`)."""
    if value in ("quick", "full") or value.endswith(".toml"):
        return value
    raise argparse.ArgumentTypeError(f"must be 'quick', 'full' or a .toml grid file; got {value!r}")


def _compare(args: argparse.Namespace) -> int:
    """``mascore compare``: the sweep, then its summary, headline tables and claims under ``out/compare``.

    The quick grid's claims are ``claims.json`` (the ledger the book and the report read); the full grid's are
    ``claims-full.json`` beside it, so that running the full grid leaves the quick ledger as it is.
    """
    import os

    from .compare import headline
    from .papers.compare import STUDY

    workers = (os.cpu_count() or 1) if args.workers is None else args.workers
    if workers < 0:
        print(f"mascore: --workers must be >= 0; got {workers}", file=sys.stderr)
        return 2
    start = time.perf_counter()
    if args.grid not in ("quick", "full"):
        return _compare_file(args, workers, start)
    study = STUDY
    result = study.run(dataclasses.replace(study.settings, grid=args.grid), args.seed, progress=True, out=args.out,
                       workers=workers, scheduler=args.scheduler)
    table, summary = result.table, result.summary
    elapsed = time.perf_counter() - start
    folder = args.out / "compare"
    summary.to_csv(folder / f"summary-{args.grid}-{args.seed}.csv", index=False)
    if getattr(result, "links", None) is not None:  # the lossy, late and event-triggered links, summarized apart
        result.links.to_csv(folder / f"links-{args.grid}-{args.seed}.csv", index=False)
    claims = study.claims(result)
    # the study's own grid writes the ledger the book and the report read; another grid writes beside it
    ledger = folder / ("claims.json" if args.grid == study.settings.grid else f"claims-{args.grid}.json")
    write_claims(claims, ledger, "compare", args.seed,
                 created_by=f"mascore compare --grid {args.grid} --seed {args.seed}")
    where = args.scheduler or _where(workers)
    for task in ("team", "position", "target", "localization", "shared"):
        print(headline(summary, task).to_string())
    held = sum(c.verdict == "holds" for c in claims)
    print(f"compare: {len(table['cell'].unique())} cells, {len(table)} runs in {elapsed:.1f} s on {where}; "
          f"{held} of {len(claims)} claims hold -> {ledger}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point: ``python -m mascore reproduce PAPER|all`` and ``python -m mascore compare``.

    ``reproduce PAPER|all [--out DIR] [--seed S] [--workers K] [--set NAME=VALUE ...]`` rebuilds the papers;
    ``compare [--grid quick|full|FILE.toml] [--out DIR] [--workers K] [--scheduler ADDRESS] [--seed S]``
    runs the cross-method sweep (:mod:`mascore.compare`).

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The process exit code: 0 when every paper was reproduced, 1 otherwise.

    Examples
    --------
    >>> from mascore.reproduce import main
    >>> try:
    ...     main(["--version"])
    ... except SystemExit as exit:
    ...     print(exit.code)
    mascore 0.1.0
    0
    """
    from . import __version__

    parser = argparse.ArgumentParser(prog="mascore", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"mascore {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    rep = sub.add_parser("reproduce", help="rebuild a paper's figures, tables and claims.json")
    rep.add_argument("paper", choices=_PaperChoices(), metavar="PAPER",
                     help="a paper's key (a module of mascore.papers; a wrong key lists them) or 'all'")
    rep.add_argument("--out", type=_out_argument, default=Path("results"),
                     help="results directory (default: results/)")
    rep.add_argument("--seed", type=_seed_argument, default=DEFAULT_SEED,
                     help=f"random seed, a non-negative integer (default: {DEFAULT_SEED})")
    rep.add_argument("--workers", type=_workers_argument, default=0,
                     help="local Dask worker processes that run the studies and draw the figures (default: 0, "
                          "in this process); the files are the same")
    rep.add_argument("--set", dest="overrides", metavar="NAME=VALUE", nargs="+", type=_override_argument,
                     default=[], help="change a setting (one paper only); results go beside the default ones")
    cmp = sub.add_parser("compare", help="run the cross-method comparison sweep (Dask) and write its claims")
    cmp.add_argument("--grid", default="quick", type=_grid_argument,
                     help="quick, full, or a .toml file of your own cells (default: quick)")
    cmp.add_argument("--out", type=_out_argument, default=Path("results"),
                     help="results directory (default: results/); the sweep resumes from its table there")
    cmp.add_argument("--workers", type=int, default=None,
                     help="local Dask worker processes (default: one per core; 0 runs in this process)")
    cmp.add_argument("--scheduler", default=None, help="address of a running Dask scheduler, e.g. tcp://HOST:8786")
    cmp.add_argument("--seed", type=_seed_argument, default=0, help="the sweep's base seed (default: 0)")
    args = parser.parse_args(argv)
    if args.command == "compare":
        return _compare(args)

    if args.overrides:
        if args.paper == "all":
            print("mascore: --set applies to one paper's settings; name the paper", file=sys.stderr)
            return 2
        return _reproduce_at(args)
    papers = available_papers() if args.paper == "all" else [args.paper]
    failed = False
    start = time.perf_counter()
    outcomes = reproduce_papers(papers, args.out, args.seed, created_by=f"mascore reproduce {args.paper} --seed "
                                f"{args.seed}", workers=args.workers)
    for paper, outcome in progress_bar(outcomes, enabled=len(papers) > 1, total=len(papers), desc="papers",
                                       unit="paper"):
        if isinstance(outcome, Exception):  # report and go on with the other papers
            print(f"mascore: reproducing {paper} failed, {args.out / paper} left as it was: "
                  f"{type(outcome).__name__}: {outcome}", file=sys.stderr)
            failed = True
            continue
        counts: dict[str, int] = {}
        for c in outcome:
            counts[c.verdict] = counts.get(c.verdict, 0) + 1
        summary = ", ".join(f"{n} {v}" for v, n in sorted(counts.items()))
        print(f"{paper}: {len(outcome)} claims ({summary}) {'in' if args.workers == 0 else 'after'} "
              f"{time.perf_counter() - start:.1f} s on {_where(args.workers)} -> {args.out / paper}")
        start = start if args.workers else time.perf_counter()
    return 1 if failed else 0
