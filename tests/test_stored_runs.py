"""Stored runs: a result is read back only under its own key (settings, seed, source and inputs), and the
comparison's chapters read the sweep's stored result instead of summarizing it again."""

import dataclasses
import subprocess
import sys

import pytest

from mascore._runstore import read_run, run_digest, write_run
from mascore.compare import grid
from mascore.compare.benchmark import SETTINGS


def test_a_run_is_read_back_under_its_key_only(tmp_path):
    path = tmp_path / "runs" / "study.pickle"
    assert read_run(path, "k") == (False, None)  # nothing stored
    assert write_run(path, "k", {"x": [1.0, 2.0]}) == path
    assert read_run(path, "k") == (True, {"x": [1.0, 2.0]})
    assert read_run(path, "other") == (False, None)
    assert [p.name for p in path.parent.iterdir()] == ["study.pickle"]  # no scratch file left behind


def test_the_key_covers_identity_and_input_bytes(tmp_path):
    table = tmp_path / "table.csv"
    table.write_text("a,b\n1,2\n")
    key = run_digest(("compare", 0), [table])
    assert key == run_digest(("compare", 0), [table])
    assert key != run_digest(("compare", 1), [table])
    table.write_text("a,b\n1,3\n")
    assert key != run_digest(("compare", 0), [table])


def test_run_reads_its_stored_result_and_a_changed_table_gives_another_key(tmp_path):
    settings = dataclasses.replace(SETTINGS, grid="quick")
    assert grid._stored_run_key(settings, 0, tmp_path) is None  # no table: nothing can match
    table = tmp_path / "compare" / "table-quick-0.csv"
    table.parent.mkdir(parents=True)
    table.write_text("cell,study\nc0,scaling\n")
    key = grid._stored_run_key(settings, 0, tmp_path)
    stored = grid.CompareResult(settings, 0, "table", "summary", {}, {"LMI Phi": 0.0})
    write_run(grid._stored_run_path(settings, 0, tmp_path), key, stored)
    result = grid.run(settings, 0, out=tmp_path)  # read back: the sweep is not run (its cells are not in the table)
    assert (result.table, result.summary, result.phi) == ("table", "summary", {"LMI Phi": 0.0})
    assert grid._stored_run_key(settings, 1, tmp_path) is None  # another seed: another table
    table.write_text("cell,study\nc0,scaling\nc1,scaling\n")
    assert grid._stored_run_key(settings, 0, tmp_path) not in (None, key)


@pytest.mark.parametrize("module", ["mascore.observers", "mascore._solver", "mascore.compare.grid"])
def test_importing_does_not_import_cvxpy(module):
    code = f"import sys, {module}; print('cvxpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
