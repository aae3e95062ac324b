"""Every study module keeps one contract, and the papers are found, not listed.

A study module of :mod:`mascore.papers` (and the comparison, :mod:`mascore.compare`) exports
``SETTINGS``, ``run(settings=SETTINGS, seed, progress=False)``, ``claims(result)``, ``FIGURES``,
``TABLES`` and ``STUDY`` (:data:`mascore.registry.STUDY_CONTRACT`); a paper module also
exports ``REGISTRY``. Nothing lists the papers by hand: a new module is a new paper.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import sys
import textwrap

import matplotlib
import pytest

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402

import mascore.papers  # noqa: E402
from mascore import registry, reproduce  # noqa: E402
from mascore.registry import (  # noqa: E402
    STUDY_CONTRACT,
    FigureSpec,
    PaperRegistry,
    Study,
    TableSpec,
    comparison_registries,
    ledger_keys,
    paper_keys,
    paper_registries,
    study_modules,
)

MODULES = [*study_modules(), *(importlib.import_module(f"mascore.papers.{reg.key}") for reg in comparison_registries())]


@pytest.mark.parametrize("module", MODULES, ids=[m.__name__ for m in MODULES])
def test_study_module_exports_the_contract(module):
    missing = [name for name in STUDY_CONTRACT if not hasattr(module, name)]
    assert not missing, f"{module.__name__} lacks {missing}"
    assert set(STUDY_CONTRACT) <= set(module.__all__), f"{module.__name__}: the contract is not in __all__"
    study = module.STUDY
    assert isinstance(study, Study)
    assert study.settings is module.SETTINGS and study.run is module.run and study.claims is module.claims
    assert study.figures == tuple(module.FIGURES) and study.tables == tuple(module.TABLES)
    assert all(isinstance(f, FigureSpec) for f in module.FIGURES)
    assert all(isinstance(t, TableSpec) for t in module.TABLES)
    settings = module.SETTINGS
    assert dataclasses.is_dataclass(settings) and not isinstance(settings, type)
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(settings, dataclasses.fields(settings)[0].name, None)
    params = inspect.signature(module.run).parameters
    assert list(params)[:3] == ["settings", "seed", "progress"], f"{module.__name__}.run{inspect.signature(module.run)}"
    assert params["settings"].default is settings and params["progress"].default is False
    assert list(inspect.signature(module.claims).parameters) == ["result"]


@pytest.mark.parametrize("module", study_modules(), ids=[m.__name__ for m in study_modules()])
def test_paper_study_runs_with_the_published_seed_by_default(module):
    assert inspect.signature(module.run).parameters["seed"].default == reproduce.DEFAULT_SEED


def test_every_study_is_on_a_registry_and_every_registry_is_its_module():
    registered = [s for reg in paper_registries() for s in reg.studies]
    for module in study_modules():
        assert any(s is module.STUDY for s in registered), f"{module.__name__}.STUDY is on no paper's REGISTRY"
    for reg in paper_registries():
        assert reg.key in sys.modules[f"mascore.papers.{reg.key}"].__name__
    positions = [reg.position for reg in paper_registries()]
    assert positions == sorted(set(positions)), positions
    assert ledger_keys() == (*paper_keys(), *(reg.key for reg in comparison_registries()))


def test_every_registered_figure_was_drawn_by_reproduce(published):
    """`reproduce` drew every figure of every study through Study.draw, which accepts only a Figure."""
    for reg in paper_registries():
        folder, claims = published(reg.key)
        for study in reg.studies:
            for spec in study.figures:
                assert (folder / "figures" / f"{spec.name}.png").stat().st_size > 1000, f"{reg.key}/{spec.name}"
            for spec in study.tables:
                assert (folder / "tables" / f"{spec.name}.csv").exists(), f"{reg.key}/{spec.name}"
        assert {c.study for c in claims} == {s.name for s in reg.studies}


def test_study_draw_refuses_what_is_not_a_figure():
    def axes_only(result):
        return plt.subplots()[1]

    study = Study("demo", "demo", None, lambda settings, seed, progress=False: seed,
                  (FigureSpec("fig1", "Fig. 1", "An axes instead of a figure.", axes_only),))
    with pytest.raises(TypeError, match="fig1.*matplotlib Figure.*Axes"):
        study.draw("fig1", 1)
    plt.close("all")


NEW_PAPER = textwrap.dedent('''
    from dataclasses import dataclass

    import matplotlib.pyplot as plt

    from mascore.ledger import Claim
    from mascore.registry import FigureSpec, PaperRegistry, Study

    @dataclass(frozen=True)
    class Settings:
        gain: float = 2.0

    SETTINGS = Settings()

    def run(settings=SETTINGS, seed=1, progress=False):
        return settings.gain * seed

    def claims(result):
        return [Claim("newpaper2099/gain", "Sec. 1", "The gain.", 2.0, result, {"abs": 0.1})]

    def _draw(result):
        fig, ax = plt.subplots()
        ax.plot([0, 1], [0, result])
        return fig

    FIGURES = (FigureSpec("fig1", "Fig. 1", "A line whose slope is the gain times the seed.", _draw),)
    TABLES = ()
    STUDY = Study("demo", "newpaper2099_demo", SETTINGS, run, FIGURES, TABLES, claims)
    REGISTRY = PaperRegistry("newpaper2099", "New et al. 2099", (STUDY,), position=99)
''')


def test_a_new_paper_is_one_new_module(tmp_path, monkeypatch):
    """A module with a REGISTRY beside the papers is found, listed last (its position) and reproduced."""
    (tmp_path / "newpaper2099.py").write_text(NEW_PAPER)
    monkeypatch.setattr(mascore.papers, "__path__", [*mascore.papers.__path__, str(tmp_path)])
    monkeypatch.delitem(sys.modules, "mascore.papers.newpaper2099", raising=False)
    try:
        assert paper_keys()[-1] == "newpaper2099" and "newpaper2099" in ledger_keys()
        assert study_modules()[-1].__name__ == "mascore.papers.newpaper2099"
        assert registry.paper_registry("newpaper2099").citation == "New et al. 2099"
        claims = reproduce.reproduce_paper("newpaper2099", tmp_path / "results", seed=1, progress=False)
        assert [c.verdict for c in claims] == ["reproduces"]
        assert (tmp_path / "results" / "newpaper2099" / "figures" / "fig1.png").exists()
    finally:
        sys.modules.pop("mascore.papers.newpaper2099", None)
        vars(mascore.papers).pop("newpaper2099", None)
        monkeypatch.undo()
        plt.close("all")
    assert "newpaper2099" not in paper_keys()


def test_a_registry_whose_key_is_not_its_module_is_refused(tmp_path, monkeypatch):
    (tmp_path / "otherkey2099.py").write_text(NEW_PAPER)
    monkeypatch.setattr(mascore.papers, "__path__", [*mascore.papers.__path__, str(tmp_path)])
    try:
        with pytest.raises(ValueError, match="REGISTRY.key must be the module's name"):
            paper_keys()
    finally:
        sys.modules.pop("mascore.papers.otherkey2099", None)
        vars(mascore.papers).pop("otherkey2099", None)


def test_paper_registry_refuses_a_bad_key():
    with pytest.raises(ValueError, match="key must be"):
        PaperRegistry("Not A Key", "x", ())


def test_a_caption_quoting_a_value_needs_its_values_function():
    """A caption that quotes ``{{name}}`` without a function computing it is refused when declared."""
    from mascore.registry import FigureSpec

    with pytest.raises(ValueError, match="no values function"):
        FigureSpec("f", "", "Settles at {{level:.2f}}.", draw=lambda r: None)
    spec = FigureSpec("f", "", "From {{a:.1f}} to {{b}}.", draw=lambda r: None, values=lambda r: {"a": r, "b": 2})
    assert spec.caption_with(0.26) == "From 0.3 to 2."
    missing = FigureSpec("f", "", "From {{a}}.", draw=lambda r: None, values=lambda r: {})
    with pytest.raises(KeyError):
        missing.caption_with(1.0)
