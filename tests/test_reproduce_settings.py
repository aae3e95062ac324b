"""``mascore reproduce PAPER --set name=value``: checked settings, a ledger beside the default, the changed claims."""

from __future__ import annotations

import json
import shutil

import pytest

from mascore import reproduce


def test_a_setting_outside_its_range_or_unknown_is_refused_before_any_work(tmp_path, capsys):
    assert reproduce.main(["reproduce", "ren2005", "--out", str(tmp_path), "--set", "n_steps=0"]) == 2
    assert "KalmanConsensusSettings.n_steps must be an integer >= 1; got 0" in capsys.readouterr().err
    assert reproduce.main(["reproduce", "ren2005", "--out", str(tmp_path), "--set", "n_step=3"]) == 2
    assert "kalman-consensus.n_steps" in capsys.readouterr().err  # the message lists the paper's settings
    assert reproduce.main(["reproduce", "all", "--out", str(tmp_path), "--set", "n_steps=3"]) == 2
    assert not any(tmp_path.iterdir())
    with pytest.raises(SystemExit):
        reproduce.main(["reproduce", "ren2005", "--set", "n_steps"])


def test_values_are_read_as_literals_and_scoped_by_study():
    s = reproduce.apply_settings("song2023", {"rendezvous.dt": "0.05"})
    assert s["rendezvous"].dt == 0.05 and s["flocking"].dt == reproduce.apply_settings("song2023", {})["flocking"].dt
    assert reproduce.settings_folder("song2023", {"rendezvous.dt": "0.05"}) == "song2023-set-rendezvous.dt=0.05"
    assert reproduce.settings_folder("song2023", {}) == "song2023"


def test_changed_claims_lists_verdicts_that_moved():
    a = [{"id": "p/x", "verdict": "holds"}, {"id": "p/y", "verdict": "reproduces"}]
    b = [{"id": "p/x", "verdict": "holds"}, {"id": "p/y", "verdict": "does-not-reproduce"}, {"id": "p/z",
                                                                                             "verdict": "holds"}]
    assert reproduce.changed_claims(a, b) == ["p/y: reproduces -> does-not-reproduce", "p/z: absent -> holds"]


def test_settings_that_must_agree_change_together_and_the_error_says_how():
    with pytest.raises(ValueError, match=r"change the two together, e.g. --set n_agents=6 xi0="):
        reproduce.apply_settings("ren2005", {"n_agents": "6"})
    s = reproduce.apply_settings("ren2005", {"n_agents": "6", "xi0": "(1.0, 2.0, 3.0, 4.0, 5.0, 6.0)",
                                             "confident_agent": "6"})["kalman-consensus"]
    assert (s.n_agents, s.xi0, s.confident_agent) == (6, (1.0, 2.0, 3.0, 4.0, 5.0, 6.0), 6)
    with pytest.raises(ValueError, match=r"set it too, e.g. --set confident_agent=6"):
        reproduce.apply_settings("ren2005", {"n_agents": "6", "xi0": "(1.0, 2.0, 3.0, 4.0, 5.0, 6.0)"})


FEW = ["n_runs=3", "t_f=10", "figure_method=closed_form"]  # the cheapest run of a study with six figures


def test_a_run_at_other_settings_writes_beside_the_default_names_the_changed_claims_and_equals_a_dask_run(
        tmp_path, capsys):
    """``--set``: the run's ledger goes beside the default one (left untouched) and the command lists the verdicts
    that moved; with ``--workers 1`` the run and each figure are Dask tasks in a worker process, their results sent
    back here, and every file is the same (a second worker would add a copy of the run between workers, and the
    start of one more process)."""
    pytest.importorskip("distributed")
    default = reproduce.results_dir() / "bhattacharjee2021" / "claims.json"
    if not default.exists():
        pytest.skip("no default bhattacharjee2021 ledger in results/ (run `mascore reproduce bhattacharjee2021`)")
    shutil.copytree(default.parent, tmp_path / "0" / "bhattacharjee2021")
    before = default.read_bytes()
    for workers in ("0", "1"):
        assert reproduce.main(["reproduce", "bhattacharjee2021", "--out", str(tmp_path / workers), "--workers",
                               workers, "--set", *FEW]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "0" / "bhattacharjee2021" / "claims.json").read_bytes() == before  # not overwritten
    folder = "bhattacharjee2021-set-" + "_".join(sorted(FEW))  # sorted by name, "+" read as "_"
    ledger = json.loads((tmp_path / "0" / folder / "claims.json").read_text())
    assert ledger["created_by"] == f"mascore reproduce bhattacharjee2021 --seed 1 --set {' '.join(FEW)}"
    moved = reproduce.changed_claims(json.loads(before)["claims"], ledger["claims"])
    assert moved  # three runs of 10 s are too few: some verdicts change, and the command says which
    assert f"{len(moved)} claim(s) changed verdict" in out and all(line in out for line in moved)
    # the folder without a default ledger: the hint names the command that writes it there, with this run's seed
    assert f"(run `mascore reproduce bhattacharjee2021 --seed 1 --out {tmp_path / '1'}` first)" in out
    serial = sorted(p.relative_to(tmp_path / "0") for p in (tmp_path / "0" / folder).rglob("*") if p.is_file())
    parallel = sorted(p.relative_to(tmp_path / "1") for p in (tmp_path / "1").rglob("*") if p.is_file())
    assert serial == parallel and any(p.name == "claims.json" for p in serial)
    assert sum(p.suffix == ".png" for p in serial) == 6 and any(p.suffix == ".pickle" for p in serial)
    for path in serial:  # the ledger, the figures it hashes, the tables and the stored run, byte for byte
        assert (tmp_path / "0" / path).read_bytes() == (tmp_path / "1" / path).read_bytes(), path


def test_workers_are_checked(tmp_path):
    """A bad count of workers is refused before any work. (A script without a main guard that asks for workers is
    told so in one line: tests/test_bad_input_own_team.py runs reproduce_paper and run_sweep in one such script.)"""
    with pytest.raises(SystemExit):
        reproduce.main(["reproduce", "ren2005", "--workers", "-1"])
    with pytest.raises(ValueError, match=r"workers must be a non-negative integer"):
        next(reproduce.reproduce_papers(["ren2005"], tmp_path, workers=1.5))
    assert not any(tmp_path.iterdir())
