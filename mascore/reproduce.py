"""``python -m mascore reproduce PAPER|all``: rebuild a paper's figures, tables and ledger.

Each paper module ``mascore.papers.<PAPER>`` declares its registry ``REGISTRY``
(:class:`mascore.registry.PaperRegistry`); for every study this module calls
``study.run(study.settings, seed)`` and writes, through one generic writer
(:func:`mascore.registry.write_study`), ``out_dir/figures/*.png``,
``out_dir/tables/*.csv`` and ``out_dir/claims.json``.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import shlex
import sys
import time
from pathlib import Path

from ._progress import progress_bar
from .ledger import PAPERS, Claim, write_claims
from .registry import write_study

__all__ = ["DEFAULT_SEED", "available_papers", "main", "reproduce_paper", "results_dir"]

#: Seed used when the caller gives none.
DEFAULT_SEED = 1


def results_dir() -> Path:
    """The project's ``results/`` folder, found from the current directory.

    Uses ``$MASCORE_RESULTS`` if set, else ``results/`` beside the nearest
    ``pyproject.toml`` above the working directory (so notebooks executed from
    ``notebooks/`` or the book find it), else ``./results``.
    """
    import os

    if os.environ.get("MASCORE_RESULTS"):
        return Path(os.environ["MASCORE_RESULTS"])
    here = Path.cwd().resolve()
    for folder in (here, *here.parents):
        if (folder / "pyproject.toml").exists():
            return folder / "results"
    return here / "results"


def available_papers() -> list[str]:
    """Paper keys whose scenario module is present, in book order."""
    return [p for p in PAPERS if importlib.util.find_spec(f"mascore.papers.{p}") is not None]


def reproduce_paper(
    paper: str, out: str | Path = "results", seed: int = DEFAULT_SEED, created_by: str | None = None
) -> list[Claim]:
    """Run one paper's reproduction and write its ledger.

    Parameters
    ----------
    paper : str
        One of :data:`mascore.ledger.PAPERS`.
    out : path
        Results root; files go to ``out/PAPER/``.
    seed : int
        Seed of every random draw in the run.
    created_by : str, optional
        Command line recorded in ``claims.json``.
    """
    if paper not in PAPERS:
        raise ValueError(f"unknown paper {paper!r}; expected one of {', '.join(PAPERS)} or 'all'")
    if paper not in available_papers():
        raise RuntimeError(f"paper {paper!r} has no scenario module (mascore/papers/{paper}.py) yet")
    module = importlib.import_module(f"mascore.papers.{paper}")
    out_dir = Path(out) / paper
    (out_dir / "figures").mkdir(parents=True, exist_ok=True)
    (out_dir / "tables").mkdir(parents=True, exist_ok=True)
    if hasattr(module, "REGISTRY"):
        claims = []
        for study in module.REGISTRY.studies:
            result = study.run(study.settings, seed, progress=True)
            claims += write_study(module.REGISTRY, study, result, out_dir)
    else:  # transitional: modules not yet on the registry
        claims = module.reproduce(out_dir, seed)
    write_claims(
        claims, out_dir / "claims.json", paper, seed,
        created_by or f"python -m mascore reproduce {paper} --out {out} --seed {seed}",
    )
    return claims


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the process exit code."""
    parser = argparse.ArgumentParser(prog="mascore", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rep = sub.add_parser("reproduce", help="rebuild a paper's figures, tables and claims.json")
    rep.add_argument("paper", choices=[*PAPERS, "all"])
    rep.add_argument("--out", default="results", help="results directory (default: results/)")
    rep.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"random seed (default: {DEFAULT_SEED})")
    args = parser.parse_args(argv)

    papers = available_papers() if args.paper == "all" else [args.paper]
    command = "python -m mascore " + shlex.join(sys.argv[1:] if argv is None else argv)
    failed = False
    for paper in progress_bar(papers, enabled=len(papers) > 1, desc="papers", unit="paper"):
        start = time.perf_counter()
        try:
            claims = reproduce_paper(paper, args.out, args.seed, created_by=command)
        except Exception as exc:  # report and go on with the other papers
            print(f"mascore: reproducing {paper} failed: {type(exc).__name__}: {exc}", file=sys.stderr)
            failed = True
            continue
        counts: dict[str, int] = {}
        for c in claims:
            counts[c.verdict] = counts.get(c.verdict, 0) + 1
        summary = ", ".join(f"{n} {v}" for v, n in sorted(counts.items()))
        print(f"{paper}: {len(claims)} claims ({summary}) in {time.perf_counter() - start:.1f} s "
              f"-> {Path(args.out) / paper}")
    return 1 if failed else 0
