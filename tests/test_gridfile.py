"""A sweep of your own from a TOML grid file (mascore compare --grid FILE.toml)."""

from __future__ import annotations

import pandas as pd
import pytest

from mascore.compare import run_cell
from mascore.compare.gridfile import read_grid
from mascore.reproduce import main
from mascore.sweep import cell_id

GRID = """
runs = 3
blocks = [0, 1]

[[study]]
name = "mine"
task = "target"
method = ["centralized", "ci-L1"]
n_agents = 6
"""


def test_a_grid_file_runs_its_cells_and_equals_the_cells_run_one_by_one(tmp_path, capsys):
    path = tmp_path / "my_grid.toml"
    path.write_text(GRID)
    grid = read_grid(path)
    assert [(c["method"], c["block"]) for c in grid.cells] == [("centralized", 0), ("centralized", 1),
                                                               ("ci-L1", 0), ("ci-L1", 1)]
    assert main(["compare", "--grid", str(path), "--out", str(tmp_path), "--workers", "0"]) == 0
    assert "4 cells, 12 runs" in capsys.readouterr().out
    table = pd.read_csv(tmp_path / "compare" / "table-my_grid-0.csv")
    rows = pd.DataFrame([{**r, **c, "cell": cell_id(c)} for c in grid.cells for r in run_cell(c, 0, grid.settings)])
    for column in ("rmse_own", "nees_own"):
        assert table.sort_values(["cell", "run"])[column].tolist() == rows.sort_values(["cell", "run"])[column].tolist()
    summary = pd.read_csv(tmp_path / "compare" / "summary-my_grid-0.csv")
    assert summary.loc[summary["method"] == "centralized", "ratio_mean"].tolist() == pytest.approx([1.0])


@pytest.mark.parametrize("text, message", [
    ("runs = 3\n", "no \\[\\[study\\]\\]"),
    ("runs = 3\n[[study]]\ntask = 'target'\nmethod = 'ci-L9'\nn_agents = 6\n", "method"),
    ("runs = 3\n[[study]]\ntask = 'target'\nmethod = 'ci-L1'\nn_agents = 6\ngraf = 'ring'\n", "unknown axes"),
    ("runs = 3\n[[study]]\ntask = 'target'\nmethod = 'ci-L1'\n", "missing \\['n_agents'\\]"),
    ("runs = 1\n[[study]]\ntask = 'target'\nmethod = 'ci-L1'\nn_agents = 6\n", "runs"),
    ("runs = [\n", "not a TOML file"),
    # a team beyond the method's limit (its spec's max_agents) or beyond memory: refused before the first cell runs
    ("runs = 3\n[[study]]\ntask = 'team'\nmethod = 'song-eb'\nn_agents = [4, 200]\n", "song-eb runs teams of at most 32"),
    ("runs = 3\n[[study]]\ntask = 'target'\nmethod = 'ci-L1'\nn_agents = [4, 1000000]\n", "n_agents asks for too much"),
    # a misspelt task is named with the file and the study
    ("runs = 3\n[[study]]\nname = 'mine'\ntask = 'targte'\nmethod = 'ci-L1'\nn_agents = 6\n",
     "bad.toml: study 'mine'\\['task'\\] must be one of"),
    # a study named as a link study runs over those links: a method without a model of them is refused up front
    ("runs = 3\n[[study]]\nname = 'send-on-delta-0.5'\ntask = 'target'\nmethod = 'ci-L5'\nn_agents = 8\n",
     "study 'send-on-delta-0.5': send_delta: method must be one of"),
    ("runs = 3\n[[study]]\nname = 'latency'\ntask = 'localization'\nmethod = 'ci-L1'\nn_agents = 8\n"
     "graph = 'switching'\n", "not modelled on the switching localization task"),
])
def test_a_bad_grid_file_is_refused_by_name_before_anything_runs(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises((ValueError, TypeError), match=message):
        read_grid(path)


@pytest.mark.parametrize("task, methods", [("target", ["centralized", "ci-L1"]),
                                           ("shared", ["central-fusion", "ren-kc"])])
def test_a_study_without_the_reference_of_its_ratios_gets_it_first(tmp_path, task, methods):
    """Every ratio is to the centralized filter's error on the same runs: a study that leaves it out would
    summarize into NaN ratios, so the reference is added (and named once where the study names it)."""
    path = tmp_path / "ref.toml"
    path.write_text(f"runs = 3\n[[study]]\ntask = '{task}'\nmethod = '{methods[1]}'\nn_agents = 6\n")
    assert [c["method"] for c in read_grid(path).cells] == methods
    path.write_text(f"runs = 3\n[[study]]\ntask = '{task}'\nmethod = {methods[::-1]}\nn_agents = 6\n")
    assert [c["method"] for c in read_grid(path).cells] == methods[::-1]


def test_the_command_line_refuses_a_grid_that_is_neither_named_nor_a_file(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["compare", "--grid", "mine"])
    assert main(["compare", "--grid", str(tmp_path / "absent.toml"), "--out", str(tmp_path)]) == 2
    assert "existing .toml file" in capsys.readouterr().err


AXES_GRID = """
runs = 2
blocks = [0]

[[study]]
name = "axes"
task = "team"
method = ["centralized", "local"]
n_agents = 4
q_scale = [0.5, 2.0]
sensing = ["full", "position"]
"""


def test_every_axis_of_the_file_has_its_own_summary_row(tmp_path, capsys):
    path = tmp_path / "axes.toml"
    path.write_text(AXES_GRID)
    assert main(["compare", "--grid", str(path), "--out", str(tmp_path), "--workers", "0"]) == 0
    printed = capsys.readouterr().out
    assert "q_scale" in printed and "sensing" in printed
    summary = pd.read_csv(tmp_path / "compare" / "summary-axes-0.csv")
    assert len(summary) == 8 and set(summary["n"]) == {2}           # 2 methods x 2 q_scale x 2 sensing, 2 runs each
    central = summary[summary["method"] == "centralized"]
    assert central["ratio_lo"].tolist() == central["ratio_hi"].tolist() == [1.0] * 4  # the bound against itself


@pytest.mark.filterwarnings("ignore::DeprecationWarning", "ignore::ResourceWarning")
def test_a_grid_file_gives_the_same_tables_on_two_local_dask_workers_and_serially(tmp_path):
    pytest.importorskip("distributed")
    path = tmp_path / "tiny.toml"
    path.write_text(GRID.replace("runs = 3", "runs = 2"))
    for workers in ("0", "2"):
        assert main(["compare", "--grid", str(path), "--out", str(tmp_path / workers), "--workers", workers]) == 0
    for name in ("table-tiny-0.csv", "summary-tiny-0.csv"):
        serial, parallel = (pd.read_csv(tmp_path / w / "compare" / name) for w in ("0", "2"))
        keys = ["cell", "run"] if name.startswith("table") else ["study", "method"]
        serial, parallel = (t.drop(columns=["cpu_s", "cpu_us"], errors="ignore").sort_values(keys, kind="stable")
                            .reset_index(drop=True) for t in (serial, parallel))
        pd.testing.assert_frame_equal(serial, parallel, check_exact=True)


def test_the_full_grid_writes_its_claims_beside_the_quick_ledger(tmp_path, monkeypatch, capsys):
    """``compare --grid full`` must not replace ``claims.json``, the quick grid's ledger that the book reads."""
    import dataclasses
    import json
    import types

    import mascore.compare
    from mascore.ledger import Claim
    from mascore.papers import compare as study_module

    def run(settings, seed, **kwargs):  # the sweep itself is not under test: one cell, one claim named by its grid
        return types.SimpleNamespace(table=pd.DataFrame({"cell": ["c0"]}), summary=pd.DataFrame(), links=None,
                                     grid=settings.grid)

    def claims(result):
        return [Claim(f"compare/{result.grid}", "here", "A claim of one grid.", 1.0, 1.0, {"rel": 0.05})]

    fake = types.SimpleNamespace(settings=study_module.STUDY.settings, run=run, claims=claims)
    monkeypatch.setattr(study_module, "STUDY", fake)
    monkeypatch.setattr(mascore.compare, "headline", lambda summary, task: pd.DataFrame())
    folder = tmp_path / "compare"
    folder.mkdir()
    ids = {}
    for grid in ("quick", "full"):
        assert main(["compare", "--grid", grid, "--out", str(tmp_path), "--workers", "0"]) == 0
        name = "claims.json" if grid == "quick" else f"claims-{grid}.json"
        assert str(folder / name) in capsys.readouterr().out
        ids[grid] = [c["id"] for c in json.loads((folder / name).read_text())["claims"]]
    assert ids == {"quick": ["compare/quick"], "full": ["compare/full"]}
    assert dataclasses.asdict(fake.settings)["grid"] == "quick"  # the study's own grid is the quick one
