"""`reproduce` is all or nothing, its ledger matches its files, and its arguments are checked.

A fake ren2005 registry (cheap, with a run that can fail or wait) stands in for
the real papers, whose own runs are tested in their own files.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from mascore import ledger, reproduce

FAKE = textwrap.dedent('''
    import time
    from dataclasses import dataclass
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd
    from mascore.ledger import Claim
    from mascore.registry import FigureSpec, PaperRegistry, Study, TableSpec

    @dataclass(frozen=True)
    class Settings:
        fail: bool = False
        wait: float = 0.0

    def run(settings, seed, progress=False):
        time.sleep(settings.wait)
        if settings.fail:
            raise KeyboardInterrupt("interrupted by the test")
        return seed

    def draw(seed):
        fig, ax = plt.subplots()
        ax.plot([0, 1], [0, seed])
        ax.set_xlabel("x"); ax.set_ylabel("y")
        return fig

    def registry(**kw):
        study = Study("fake", "ren2005_kalman_consensus", Settings(**kw), run,
                      (FigureSpec("fig1", "Fig. 1", "A line whose slope is the seed.", draw),),
                      (TableSpec("table1", "", "The seed in a table.", lambda s: pd.DataFrame({"seed": [s]})),),
                      lambda s: [Claim("ren2005/seed", "Fig. 1", "The seed.", 1.0, float(s), {"abs": 0.5})])
        return PaperRegistry("ren2005", "Fake 2005", (study,))
''')


@pytest.fixture
def fake(monkeypatch):
    namespace: dict = {}
    exec(FAKE, namespace)  # noqa: S102 - a test double defined above

    def use(**kw):
        import mascore.papers.ren2005 as module

        monkeypatch.setattr(module, "REGISTRY", namespace["registry"](**kw), raising=False)

    return use


def test_reproduce_writes_a_ledger_that_matches_its_files(tmp_path, fake):
    fake()
    reproduce.reproduce_paper("ren2005", tmp_path, seed=1, progress=False)
    doc = ledger.verify_outputs(tmp_path / "ren2005")
    assert doc["seed"] == 1 and set(doc["files"]) == {"figures/fig1.png", "figures/fig1.layout.json", "tables/table1.csv"}
    assert doc["claims"][0]["study"] == "fake"
    assert str(tmp_path) not in json.dumps(doc), "an absolute path in the ledger"
    (tmp_path / "ren2005" / "tables" / "table1.csv").write_text("seed\n7\n")
    with pytest.raises(ValueError, match="does not match its claims.json"):
        ledger.load_claims(tmp_path)


def test_two_identical_runs_give_identical_ledgers_and_files(tmp_path, fake):
    fake()
    texts = []
    for out in (tmp_path / "a", tmp_path / "b"):
        reproduce.reproduce_paper("ren2005", out, seed=3, progress=False)
        texts.append((out / "ren2005" / "claims.json").read_bytes())
    assert texts[0] == texts[1]


def test_a_failed_run_leaves_the_previous_output_untouched(tmp_path, fake):
    fake()
    reproduce.reproduce_paper("ren2005", tmp_path, seed=1, progress=False)
    before = {p: p.read_bytes() for p in (tmp_path / "ren2005").rglob("*") if p.is_file()}
    fake(fail=True)
    with pytest.raises(KeyboardInterrupt):
        reproduce.reproduce_paper("ren2005", tmp_path, seed=2, progress=False)
    after = {p: p.read_bytes() for p in (tmp_path / "ren2005").rglob("*") if p.is_file()}
    assert after == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ren2005"], "a partial directory was left"


def test_sigint_during_a_run_keeps_the_previous_output(tmp_path):
    script = FAKE + textwrap.dedent(f'''
        import signal
        signal.signal(signal.SIGINT, signal.default_int_handler)  # a background job inherits SIGINT ignored
        import mascore.papers.ren2005 as module
        from mascore.reproduce import reproduce_paper
        module.REGISTRY = registry()
        reproduce_paper("ren2005", {str(tmp_path)!r}, seed=1, progress=False)
        module.REGISTRY = registry(wait=60.0)
        print("started", flush=True)
        reproduce_paper("ren2005", {str(tmp_path)!r}, seed=2, progress=False)
    ''')
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "started"
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=30) != 0
    assert ledger.verify_outputs(tmp_path / "ren2005")["seed"] == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ren2005"]


@pytest.mark.parametrize("args,message", [
    (["reproduce", "ren2005", "--seed", "-1"], "--seed: expected a non-negative integer"),
    (["reproduce", "ren2005", "--seed", "one"], "--seed: expected a non-negative integer"),
    (["reproduce", "nosuchpaper"], "invalid choice"),
])
def test_cli_rejects_bad_arguments_by_name(args, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        reproduce.main(args)
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


def test_cli_rejects_a_file_as_out(tmp_path, capsys):
    target = tmp_path / "results.txt"
    target.write_text("")
    with pytest.raises(SystemExit):
        reproduce.main(["reproduce", "ren2005", "--out", str(target)])
    assert "--out: expected a directory" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == [target]


def test_cli_prints_its_version(capsys):
    with pytest.raises(SystemExit):
        reproduce.main(["--version"])
    assert capsys.readouterr().out.startswith("mascore ")


def test_reproduce_paper_checks_its_arguments(tmp_path):
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        reproduce.reproduce_paper("ren2005", tmp_path, seed=-1)
    with pytest.raises(ValueError, match="paper must be one of"):
        reproduce.reproduce_paper("nosuchpaper", tmp_path)
