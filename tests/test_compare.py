"""The comparison benchmark (mascore.compare) and the sweep engine (mascore.sweep).

Sweeps give the same table serially, on a local Dask cluster and on a scheduler with two
workers started here; an interrupted sweep resumes; the ledger claims recompute from the
table; every method's metrics agree with an independent computation on a tiny case.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import re
import socket
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.linalg as sla

from mascore import _team_kernels, compare, consensus, graphs, sweep
from mascore.compare import verdicts
from mascore.ledger import VERDICTS
from mascore.reproduce import results_dir

ROOT = Path(__file__).resolve().parents[1]
CPU = "cpu_s"  # the only column that depends on the machine and the moment


def _small_cells() -> list[dict]:
    """A slice of the quick grid: every team method at N = 4, a drop-out cell, the shared task, fusion cells."""
    cells = [c for c in compare.grid_cells("quick") if c["block"] == 0 and c["n_agents"] in (4, 8)
             and (c["study"] in ("scaling", "shared") or c["dropout"] == 0.3)]
    fusion = [c for c in compare.grid_cells("quick") if c["block"] == 0 and c["task"] in ("target", "localization")
              and c["n_agents"] == 8 and c["graph"] == "ring" and c["method"] in ("centralized", "hcmci-L1",
                                                                                  "ci-diffusion")]
    return [c for c in cells if c["n_agents"] == 4 or c["study"] != "scaling"] + fusion


#: The sweep-engine tests compare tables, not numbers: a few runs of a few steps per cell suffice (every step
#: draws from every stream and, on the switching graph, has a new graph; the steps past 30 add no new code path).
FEW_RUNS = dataclasses.replace(compare.SETTINGS, runs=4, n_steps=30, steady_from=15)
_cell_task = functools.partial(compare.run_cell, settings=FEW_RUNS)  # picklable: Dask workers run it
_cells_task = functools.partial(compare.run_cells, settings=FEW_RUNS)  # the same cells, a cell_group at a time


def _without_cpu(table: pd.DataFrame) -> pd.DataFrame:
    return table.drop(columns=[CPU]).reset_index(drop=True)


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial") / "table.csv"
    return sweep.run_sweep(_small_cells(), _cell_task, out, progress=False), out


def test_grid_cells_cover_the_studies_with_100_seeds():
    from mascore.compare.scenario import BUILT_IN

    cells = [c for c in compare.grid_cells("quick") if c["task"] in BUILT_IN]  # a scenario's module adds its own
    studies = {c["study"] for c in cells}
    assert studies - set(compare.LINK_STUDIES) == {"scaling", "graph", "dropout", "noise", "wrong-q", "shared", "target",
                                                   "localization", "position", "switching"}
    assert studies & set(compare.LINK_STUDIES) == {"loss", "loss-direction", "latency", "send-on-delta-0.5",
                                                   "send-on-delta-1", "lossy-send-on-delta-0.5",
                                                   "late-send-on-delta-0.5"}
    blocks = {c["block"] for c in cells}
    assert len(blocks) * compare.SETTINGS.runs >= 100
    assert {c["method"] for c in cells if c["task"] == "team"} == set(compare.ALL_TEAM_METHODS)
    assert {c["method"] for c in cells if c["task"] == "target"} == set(compare.target_methods(knobs=True))
    assert {c["method"] for c in cells if c.get("sensing") == "position"} == set(compare.POSITION_METHODS)
    assert all(c.get("sensing", "full") == "full" for c in cells if c["study"] != "position")  # old cells: no key
    knobs = set(compare.FUSION_KNOB_METHODS) | set(compare.REN_Q) - set(compare.SHARED_METHODS)
    headline = [c for c in cells if c["method"] not in knobs and (c["task"] in ("shared", "target", "localization")
                or (c["study"] in ("scaling", "position") and c["n_agents"] == 8))]
    for c in headline:  # 200 seeds behind every headline number
        assert len({d["block"] for d in headline if d["method"] == c["method"] and d["task"] == c["task"]}) == 4
    assert len({sweep.cell_id(c) for c in cells}) == len(cells)


def test_cell_seed_depends_only_on_the_seed_axes():
    a = {"task": "team", "method": "local", "n_agents": 4, "noise": "gaussian", "block": 0, "dropout": 0.0}
    same = {**a, "method": "song-eb", "dropout": 0.3}
    other = {**a, "block": 1}
    draw = lambda c: np.random.default_rng(sweep.cell_seed(c, compare.SEED_AXES)).random(3)  # noqa: E731
    np.testing.assert_array_equal(draw(a), draw(same))
    assert not np.allclose(draw(a), draw(other))
    assert not np.allclose(draw(a), np.random.default_rng(sweep.cell_seed(a, compare.SEED_AXES, 1)).random(3))


def test_same_seed_same_numbers_byte_for_byte():
    one = compare.simulate_team("song-eb", 4, 3, runs=5, dropout=0.1)
    two = compare.simulate_team("song-eb", 4, 3, runs=5, dropout=0.1)
    for key in one:
        if key != CPU:
            assert one[key].tobytes() == two[key].tobytes(), key


def _cells_task_on_a_plain_worker(cells):
    """`_cells_task`, on a worker started as sweep.dask_client starts it, or an AssertionError that run_sweep passes
    on: the C library's allocator defaults (Dask's nanny would set MALLOC_TRIM_THRESHOLD_=65536), one BLAS thread,
    and, with no dashboard, no stack sample of its task every 10 ms nor an event-loop tick every 20 ms."""
    import dask

    found = (os.environ.get("MALLOC_TRIM_THRESHOLD_", "unset"), os.environ.get("OMP_NUM_THREADS"),
             dask.config.get("distributed.worker.profile.enabled"), dask.config.get("distributed.admin.tick.interval"))
    assert found == ("unset", "1", False, "1s"), f"a worker with (trim, BLAS threads, profiler, tick) = {found}"
    return _cells_task(cells)


def test_local_cluster_gives_the_serial_table_on_plain_workers(serial, tmp_path, monkeypatch):
    """sweep.dask_client's local cluster (one worker: two workers giving the serial table is the scheduler test's)."""
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)  # not inherited from this process
    table, _ = serial  # one cell at a time; here the cells of a cell_group run together, on a local worker
    parallel = sweep.run_sweep(_small_cells(), _cells_task_on_a_plain_worker, tmp_path / "t.csv", workers=1,
                               progress=False, group=compare.cell_group)
    pd.testing.assert_frame_equal(_without_cpu(parallel), _without_cpu(table), check_exact=True)


def test_cells_run_together_give_the_rows_of_each_cell_alone_and_resume_by_cell(tmp_path):
    cells = [c for c in compare.grid_cells("quick") if c["task"] in ("target", "localization") and c["n_agents"] == 8
             and c["graph"] in ("ring", "switching") and c["method"] in ("ci-diffusion", "hcmci-L1")
             and c["block"] in (0, 1)]
    cells += [c for c in _small_cells() if c["task"] == "shared"][:2]  # cells of no group: alone
    assert {len({c["block"] for c in cells if compare.cell_group(c) == key}) for key in
            {compare.cell_group(c) for c in cells} - {None}} == {2}
    alone = sweep.run_sweep(cells, _cell_task, tmp_path / "alone.csv", progress=False)
    together = sweep.run_sweep(cells, _cells_task, tmp_path / "together.csv", progress=False,
                               group=compare.cell_group)  # both blocks of a group in one call
    pd.testing.assert_frame_equal(_without_cpu(together), _without_cpu(alone), check_exact=True)
    out = tmp_path / "resumed.csv"
    first = sweep.run_sweep([c for c in cells if c["block"] == 0], _cells_task, out, progress=False,
                            group=compare.cell_group)
    resumed = sweep.run_sweep(cells, _cells_task, out, progress=False, group=compare.cell_group)  # block 1 alone
    pd.testing.assert_frame_equal(_without_cpu(resumed), _without_cpu(alone), check_exact=True)
    kept = resumed.set_index(["cell", "run"]).loc[first.set_index(["cell", "run"]).index, CPU]
    np.testing.assert_array_equal(kept.to_numpy(), first[CPU].to_numpy())  # block 0 was not run again
    with pytest.raises(ValueError, match="cell_group"):
        compare.run_cells([cells[0], {**cells[0], "n_agents": 16}])


def test_team_blocks_run_together_give_each_block_alone():
    # simulate_team on a sequence of seeds steps the blocks as one batch, each block drawn from its own seed's
    # streams: every method of the scaling study (N = 4), per-run covariances (drop-outs), position sensing and the
    # switching graph
    cells = [c for c in compare.grid_cells("quick") if c["task"] == "team" and c["block"] in (0, 1) and (
        (c["study"] == "scaling" and c["n_agents"] == 4)
        or (c["study"] == "dropout" and c["dropout"] == 0.3 and c["method"] in ("song-eb", "song-mb"))
        or (c["study"] == "position" and c["method"] == "set-membership" and c["noise"] == "uniform")
        or (c["study"] == "switching" and c["method"] == "song-eb"))]
    groups: dict = {}
    for c in cells:
        groups.setdefault(compare.cell_group(c), []).append(c)
    assert {len(g) for g in groups.values()} == {2} and len(groups) >= 12
    for group in groups.values():
        together = compare.run_cells(group, settings=FEW_RUNS)
        for cell, rows in zip(group, together):
            alone = compare.run_cell(cell, settings=FEW_RUNS)
            pd.testing.assert_frame_equal(_without_cpu(pd.DataFrame(rows)), _without_cpu(pd.DataFrame(alone)),
                                          check_exact=True, obj=str(cell))
    with pytest.raises(ValueError, match="seed"):
        compare.simulate_team("local", 4, [], runs=2)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_scheduler_and_two_workers_give_the_serial_table(serial, tmp_path):
    table, _ = serial
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    procs = [subprocess.Popen([*dask, "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(2):
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--nworkers", "1",
                 "--no-dashboard", "--host", "127.0.0.1"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=60)
        remote = sweep.run_sweep(_small_cells(), _cell_task, tmp_path / "t.csv", scheduler=address,
                                 progress=False)
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            p.wait(timeout=30)
    pd.testing.assert_frame_equal(_without_cpu(remote), _without_cpu(table), check_exact=True)


def _failing_task(cell):
    if cell["method"] == "vlahakis":
        raise KeyboardInterrupt("interrupted")
    return _cell_task(cell)


def test_an_interrupted_sweep_resumes(serial, tmp_path):
    table, _ = serial
    out = tmp_path / "t.csv"
    with pytest.raises(KeyboardInterrupt):
        sweep.run_sweep(_small_cells(), _failing_task, out, progress=False)
    partial = pd.read_csv(out)
    assert 0 < partial["cell"].nunique() < len(_small_cells())
    kept = partial.set_index(["cell", "run"])[CPU]
    resumed = sweep.run_sweep(_small_cells(), _cell_task, out, progress=False)
    pd.testing.assert_frame_equal(_without_cpu(resumed), _without_cpu(table), check_exact=True)
    again = resumed.set_index(["cell", "run"]).loc[kept.index, CPU]
    np.testing.assert_array_equal(again.to_numpy(), kept.to_numpy())  # the finished cells were not rerun


def test_run_sweep_refuses_bad_arguments(tmp_path):
    cells = sweep.Grid({"scale": [1.0], "block": [0]}).cells()
    with pytest.raises(ValueError, match="workers"):
        sweep.run_sweep(cells, sweep.demo_task, tmp_path / "t.csv", workers=-1)
    with pytest.raises(ValueError, match="scheduler"):
        sweep.run_sweep(cells, sweep.demo_task, tmp_path / "t.csv", scheduler="localhost")
    with pytest.raises(TypeError, match="task"):
        sweep.run_sweep(cells, "demo", tmp_path / "t.csv")
    with pytest.raises(ValueError, match="axis"):
        sweep.Grid({"scale": []})
    with pytest.raises(KeyError, match="block"):
        sweep.cell_seed({"scale": 1.0}, ["block"])


@pytest.mark.parametrize("kwargs, match", [
    ({"method": "kalman"}, "method"), ({"noise": "cauchy"}, "noise"), ({"dropout": 1.0}, "dropout"),
    ({"q_scale": 0.0}, "q_scale"), ({"n_agents": 2}, "n_agents"), ({"runs": 0}, "runs"),
])
def test_simulate_team_refuses_bad_arguments(kwargs, match):
    args = {"method": "local", "n_agents": 4, "seed": 0, **kwargs}
    with pytest.raises(ValueError, match=match):
        compare.simulate_team(args.pop("method"), args.pop("n_agents"), args.pop("seed"), **args)


# ---------------------------------------------------------------------------- independent checks


def test_local_filter_matches_the_dare_and_its_rmse_matches_its_covariance():
    """The local Kalman filter's covariance reaches the DARE's; its RMSE and NEES agree with it."""
    s = compare.SETTINGS
    team = compare.team_setup(4, "gaussian", 1.0, s)
    est = compare.make_estimator("local", team, np.zeros((1, 4, 4)))
    for _ in range(300):
        est.update(np.zeros((1, 4, 4, 4)), np.ones((1, 4, 4), bool))
        est.predict(np.zeros((1, 4, 2)))
    prior = sla.solve_discrete_are(team.A.T, np.eye(4), team.Q, team.R)
    np.testing.assert_allclose(est.P, prior, rtol=1e-8)
    posterior = prior - prior @ np.linalg.solve(prior + team.R, prior)
    m = compare.simulate_team("local", 8, 11, runs=100)
    predicted = np.sqrt(np.trace(posterior[:2, :2]))
    assert abs(m["rmse_own"].mean() / predicted - 1) < 0.03
    assert abs(m["nees_own"].mean() - 1) < 0.05


def test_centralized_covariance_matches_the_team_dare():
    """Steady-state own covariance of the centralized filter = DARE of the team with every measurement."""
    s = compare.SETTINGS
    N = 4
    team = compare.team_setup(N, "gaussian", 1.0, s)
    est = compare.make_estimator("centralized", team, np.zeros((1, N, 4)))
    S = (team.adjacency > 0) | np.eye(N, dtype=bool)
    for _ in range(300):
        est.update(np.zeros((1, N, N, 4)), S[None])
        est.predict(np.zeros((1, N, 2)))
    A = np.kron(np.eye(N), team.A)
    H = np.vstack([np.kron(np.eye(N)[j], np.eye(4)) for i in range(N) for j in range(N) if S[i, j]])
    R = np.kron(np.eye(H.shape[0] // 4), team.R)
    prior = sla.solve_discrete_are(A.T, H.T, np.kron(np.eye(N), team.Q), R)
    own = est.own_cov[0]
    prior_own = np.stack([prior[4 * i:4 * i + 4, 4 * i:4 * i + 4] for i in range(N)])
    est.update(np.zeros((1, N, N, 4)), S[None])  # back to the posterior for comparison
    post = prior - prior @ H.T @ np.linalg.solve(H @ prior @ H.T + R, H @ prior)
    post_own = np.stack([post[4 * i:4 * i + 4, 4 * i:4 * i + 4] for i in range(N)])
    np.testing.assert_allclose(own, prior_own, rtol=1e-7)
    np.testing.assert_allclose(est.own_cov[0], post_own, rtol=1e-7)


def test_set_membership_contains_the_truth_under_bounded_noise():
    m = compare.simulate_team("set-membership", 4, 5, noise="uniform", runs=20)
    assert m["containment"].min() == 1.0


def test_centralized_lower_bounds_and_cooperation_ordering():
    c = compare.simulate_team("centralized", 6, 2, runs=40)
    for method in ("local", "song-mb", "song-eb", "vlahakis", "vlahakis-phi1", "set-membership"):
        other = compare.simulate_team(method, 6, 2, runs=40)
        assert np.mean(other["rmse_own"] / c["rmse_own"]) > 1.0, method


def test_shared_task_central_fusion_and_ren_kc():
    best = compare.simulate_shared("central-fusion", 5, 1, runs=400)
    ren = compare.simulate_shared("ren-kc", 5, 1, runs=400)
    none = compare.simulate_shared("no-fusion", 5, 1, runs=400)
    assert abs(best["nees_own"].mean() - 1) < 0.1  # the fused covariance is honest
    assert abs(none["nees_own"].mean() - 1) < 0.1
    assert best["rmse_own"].mean() <= ren["rmse_own"].mean() <= 1.05 * best["rmse_own"].mean()
    # the same priors through the package's central fusion, independently
    xi, P = consensus.central_fusion(np.array([[0.0, 1.0], [2.0, 0.0]]), np.array([np.eye(2), 3 * np.eye(2)]))
    np.testing.assert_allclose(xi, [0.5, 0.75])


def test_floats_per_step_counts_messages():
    assert compare.floats_per_step("centralized", 8) == 24.0
    assert compare.floats_per_step("song-eb", 64) == 0.0
    assert compare.floats_per_step("forwarding", 8, degree=2) == 12.0  # 4 per neighbour + the broadcast estimate
    with pytest.raises(ValueError, match="method"):
        compare.floats_per_step("unknown", 8)


def test_summary_ratio_is_one_for_the_bound(serial):
    table, _ = serial
    s = compare.summarize(table)
    bound = s[s["method"].isin(["centralized", "central-fusion"])]
    np.testing.assert_allclose(bound["ratio_mean"], 1.0)
    assert (s.groupby(["study", "method", "n_agents", "noise", "dropout", "q_scale"])["n"].max()
            == FEW_RUNS.runs).all()


def test_claims_recompute_from_the_table():
    """The ledger written by `mascore compare` is what the table's summary gives.

    The ledger is the one `make test` wrote before pytest (``mascore compare --grid quick --out results``);
    it is read, not written again here, while the comparison's notebooks may be reading it.
    """
    out = results_dir()
    if not all((out / "compare" / name).exists() for name in ("table-quick-0.csv", "claims.json")):
        pytest.skip("the quick sweep has not been run (make reproduce)")
    written = json.loads((out / "compare" / "claims.json").read_text())["claims"]
    table = pd.read_csv(out / "compare" / "table-quick-0.csv")
    again = [c.to_dict() for c in compare.compare_claims(table)]
    assert [c["id"] for c in written] == [c["id"] for c in again]
    for w, a in zip(written, again):
        assert w["verdict"] == a["verdict"], w["id"]
        assert w["written_from"] == "seed blocks 0-1" and w["decided_on"], w["id"]
        assert json.dumps(w["value"], sort_keys=True) == json.dumps(a["value"], sort_keys=True)


def test_every_claim_is_decided_on_a_table_of_the_full_grids_cells():
    """The claims name every coordinate the full grid varies: on a table with the full grid's cells (its larger
    teams, four seed blocks, the set-membership filter on the switching target), each claim finds one summary row
    where it asks for one and gets a verdict. The per-run numbers are synthetic (which metrics a method reports is
    taken from the quick table `make test` wrote): only the selections are under test, not the verdicts."""
    table = results_dir() / "compare" / "table-quick-0.csv"
    if not table.exists():
        pytest.skip("the quick sweep has not been run (make reproduce)")
    quick = pd.read_csv(table, keep_default_na=False, na_values=[""], low_memory=False)
    metrics = ["containment", "cpu_s", "floats", "nees_own", "rmse_far", "rmse_own", "rmse_view", "set_size", "spread"]
    reports = quick.groupby("method")[metrics].apply(lambda d: d.notna().any())
    rng = np.random.default_rng(0)
    rows = [{**cell, "cell": sweep.cell_id(cell), "run": run,
             **{m: 1.0 + 0.1 * rng.standard_normal() if reports.loc[cell["method"], m] else np.nan for m in metrics}}
            for cell in compare.grid_cells("full") for run in range(4)]
    full = pd.DataFrame(rows)
    assert set(full.columns) == set(quick.columns)
    phi = {"Phi = -0.1": 1.0, "Phi = 0": 1.0, "Phi = 0.31": 1.0, "Phi = 1": 1.0, "LMI Phi": 0.3, "LMI bound": 1.0}
    claims = compare.compare_claims(full, phi=phi)
    assert len(claims) == len(verdicts.CLAIMS) + len(verdicts.LINK_CLAIMS) and all(c.verdict for c in claims)



def test_the_recorded_full_grid_has_a_verdict_for_every_claim_of_the_quick_ledger():
    """The claims page lists the claims whose verdicts differ between the quick grid and the committed record of
    the full grid's last run: the record has one valid verdict for each claim the quick ledger decides (same ids),
    and it comes from the same run as the committed timing snapshot (same number of cells)."""
    ledger = results_dir() / "compare" / "claims.json"
    if not ledger.exists():
        pytest.skip("the quick sweep has not been run (make reproduce)")
    data = ROOT / "benchmarks" / "data"
    record = json.loads((data / "compare_full_claims.json").read_text())
    timing = json.loads((data / "compare_full.json").read_text())
    assert record["cells"] == timing["cells"] and record["created_by"].startswith("mascore compare --grid full")
    quick = json.loads(ledger.read_text())["claims"]
    assert [c["id"] for c in record["claims"]] == [c["id"] for c in quick]
    assert all(c["verdict"] in VERDICTS and (c["verdict"] == "fails" or not c["undecided"]) for c in record["claims"])
    assert all(c["why"] for c in record["claims"] if c["verdict"] == "fails")
    # its summary, which the sections "From 8 to 64 agents" draw: one row per cell of the current full grid on
    # ideal links (the link studies have their own tables), each from 4 seed blocks of the grid's runs
    summary = pd.read_csv(data / "compare_full_summary.csv")
    keys = ["study", "task", "method", "graph", "n_agents", "noise", "dropout", "q_scale"]
    cells = [c for c in compare.grid_cells("full") if c["study"] not in compare.LINK_STUDIES]
    assert sorted(summary[keys].itertuples(index=False, name=None)) == sorted({tuple(c[k] for k in keys) for c in cells})
    assert (summary.loc[summary["task"].isin(["target", "localization"]), "n"] == 200).all()

def test_vlahakis_rmse_matches_its_error_covariance():
    """The discretized observer's own-position RMSE = the steady error covariance from a Lyapunov equation.

    Per axis and agent the error is ``e = [e_p, e_v]``; the correction subtracts
    ``G [(e_p,i + nu_ii) + Phi sum_j a_ij (e_p,i - e_p,j + nu_ii - nu_ij)]`` with ``G = dt L``, and the
    prediction is ``e <- A e + w`` (each agent knows the input it applied).
    """
    s = compare.SETTINGS
    N = 5
    L, Phi = compare._vlahakis_gains(graphs.ring_graph(N), s.q_vel, s.r, s.dt)
    G = s.dt * L                                          # (2, 1)
    C = np.array([[1.0, 0.0]])
    A = np.array([[1.0, s.dt], [0.0, 1.0]])
    adjacency = graphs.ring_graph(N)
    lap = graphs.laplacian(adjacency)
    M = np.eye(2 * N) - np.kron(np.eye(N) + Phi * lap, G @ C)
    deg = adjacency.sum(1)
    noise = np.kron(np.diag(s.r * ((1 + Phi * deg) ** 2 + Phi**2 * (adjacency**2).sum(1))), G @ G.T)
    Q = np.kron(np.eye(N), np.diag([s.q_pos, s.q_vel]))
    P_post = sla.solve_discrete_lyapunov(M @ np.kron(np.eye(N), A), M @ Q @ M.T + noise)
    predicted = np.sqrt(2 * np.mean(np.diag(P_post)[::2]))  # two axes
    m = compare.simulate_team("vlahakis", N, 4, runs=100)
    assert abs(np.sqrt(np.mean(m["rmse_own"] ** 2)) / predicted - 1) < 0.03


@pytest.mark.parametrize("method", ["centralized", "song-eb"])
def test_kalman_type_filters_are_consistent_on_the_baseline(method):
    """Mean own-state NEES per dof over 100 runs: within 10 % of 1 (the filters' covariances are honest)."""
    m = compare.simulate_team(method, 5, 8, runs=100)
    assert abs(m["nees_own"].mean() - 1) < 0.1


# ---------------------------------------------------------------------------- the referee's checks


@pytest.mark.parametrize("dropout", [0.0, 0.3])
def test_forwarding_is_the_centralized_filter_on_the_own_state_task(dropout):
    """Own state measured, controls known: one hop of forwarded measurements is the centralized filter, run by run."""
    c = compare.simulate_team("centralized", 6, 4, runs=30, dropout=dropout)
    f = compare.simulate_team("forwarding", 6, 4, runs=30, dropout=dropout)
    np.testing.assert_allclose(f["rmse_own"], c["rmse_own"], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(f["nees_own"], c["nees_own"], rtol=1e-9)


def test_set_membership_centre_is_the_measurement_with_full_state_sensing():
    team = compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS)
    rng = np.random.default_rng(0)
    est = compare.make_estimator("set-membership", team, rng.standard_normal((3, 4, 4)))
    Z = rng.standard_normal((3, 4, 4, 4))
    est.update(Z, np.ones((1, 4, 4), bool))
    np.testing.assert_allclose(est.own, Z[:, np.arange(4), np.arange(4)], atol=1e-6)  # L = I


def test_vlahakis_gain_follows_the_filters_q():
    """More process noise in the filter's Q: a larger observer gain (the Q knob is not inverted)."""
    s = compare.SETTINGS
    gains = [compare.make_estimator("vlahakis", compare.team_setup(6, "gaussian", q, s), np.zeros((1, 6, 4))).filter.gain[0, 0]
             for q in (0.1, 1.0, 10.0)]
    assert gains[0] < gains[1] < gains[2]


def test_vlahakis_program_is_flat_in_phi():
    g = compare.vlahakis_profile(8, (0.0, 0.31, 1.0))
    values = [g["Phi = 0"], g["Phi = 0.31"], g["Phi = 1"]]
    assert (max(values) - min(values)) / min(values) < 1e-4


def test_ren_at_the_papers_q_is_close_but_overconfident():
    best = compare.simulate_shared("central-fusion", 8, 2, runs=300)
    ren = compare.simulate_shared("ren-kc", 8, 2, runs=300)
    untuned = compare.simulate_shared("ren-kc-q0", 8, 2, runs=300)
    assert 1.0 <= ren["rmse_own"].mean() / best["rmse_own"].mean() < 1.05
    assert 2 < ren["nees_own"].mean() < 20 and untuned["nees_own"].mean() > 1e6


def _own_trace(C: np.ndarray, task: str) -> np.ndarray:
    """Trace of the position block each agent is scored on: the target's, or the agent's own (localization)."""
    if task == "target":
        return np.trace(C[..., :2, :2], axis1=-2, axis2=-1)
    N = C.shape[-1] // 2
    return np.stack([np.trace(C[..., i, 2 * i:2 * i + 2, 2 * i:2 * i + 2], axis1=-2, axis2=-1) for i in range(N)],
                    -1)


@pytest.mark.parametrize("task", ["target", "localization"])
def test_centralized_matches_the_dare(task):
    """Common target and localization: the centralized filter's MSE and NEES agree with the steady-state DARE."""
    s = compare.SETTINGS
    model = (compare.target_model if task == "target" else compare.localization_model)(8)
    H, R = model.H_stacked, model.R_stacked
    prior = sla.solve_discrete_are(model.F.T, H.T, model.Q, R)
    post = prior - prior @ H.T @ np.linalg.solve(H @ prior @ H.T + R, H @ prior)
    predicted = float(np.mean(_own_trace(np.broadcast_to(post, (8, *post.shape)), task)))
    m = compare.simulate_target("centralized", 8, 7, runs=200, task=task)
    mse = m["rmse_own"] ** 2
    half = 1.96 * mse.std(ddof=1) / np.sqrt(mse.size)
    assert abs(mse.mean() - predicted) < 2 * half + 1e-3 * predicted, (mse.mean(), predicted, half)
    assert abs(m["nees_own"].mean() - 1) < 0.07
    assert s.steady_from >= 50  # the window starts after the filter has converged


@pytest.mark.parametrize("task, method", [("target", "local"), ("target", "ci-L1"), ("target", "forwarding"),
                                          ("localization", "local"), ("localization", "hcmci-L1")])
def test_rmse_matches_the_exact_error_covariance(task, method):
    """Monte Carlo MSE over the window = the exact error covariance (mascore.fusion.error_covariance)."""
    from mascore import fusion

    s = compare.SETTINGS
    model = (compare.target_model if task == "target" else compare.localization_model)(8)
    C, _ = fusion.error_covariance(compare.target_filter(method, model), s.p0 * np.eye(model.n_states), s.n_steps)
    exact = float(np.mean(_own_trace(C[s.steady_from:], task)))
    m = compare.simulate_target(method, 8, 5, runs=200, task=task)
    mse = m["rmse_own"] ** 2
    half = 1.96 * mse.std(ddof=1) / np.sqrt(mse.size)
    assert abs(mse.mean() - exact) < 2 * half, (mse.mean(), exact, half)


def _quick_rows(cells: list[dict]) -> pd.DataFrame:
    """The rows of `cells` in the quick sweep's table, which ``make test`` wrote before pytest.

    ``make test`` runs ``mascore compare --grid quick --out results`` first: the rows of the quick grid's cells are
    read from its table (``compare.run_cell`` at ``compare.SETTINGS``, as here) instead of being computed again.
    """
    path = results_dir() / "compare" / "table-quick-0.csv"
    if not path.exists():
        pytest.skip("the quick sweep has not been run (make reproduce)")
    ids = {sweep.cell_id(c) for c in cells}
    table = pd.read_csv(path)
    table = table[table["cell"].isin(ids)]
    assert set(table["cell"]) == ids and len(table) == len(ids) * compare.SETTINGS.runs
    return table


def test_headlines_have_no_nan_and_list_what_does_not_apply():
    """The headline tables of block 0's cells at N = 8 on the ring."""
    summary = compare.summarize(_quick_rows([c for c in compare.grid_cells("quick") if c["block"] == 0 and
                                             c["n_agents"] == 8 and c["dropout"] == 0.0 and c["graph"] == "ring"
                                             and c["study"] in ("target", "localization", "shared")]))
    for task in ("target", "localization", "shared"):
        table = compare.headline(summary, task)
        assert not table.isna().any().any(), task
    target = compare.headline(summary, "target")
    assert set(compare.TARGET_NOT_APPLICABLE) <= set(target.index)
    assert target.loc["ci-L5", "floats/step"] == 70.0


def test_song_estimates_non_neighbours_and_the_others_do_not():
    eb = compare.simulate_team("song-eb", 6, 1, runs=10)
    local = compare.simulate_team("local", 6, 1, runs=10)
    assert np.all(np.isfinite(eb["rmse_far"])) and np.all(eb["rmse_far"] > eb["rmse_own"])
    assert np.all(np.isnan(local["rmse_far"]))


def test_switching_topology_changes_and_leaves_the_centralized_filter_alone():
    G = compare.switching_graphs(16, 40)
    np.testing.assert_array_equal(G, compare.switching_graphs(16, 40))  # the same graphs for every cell
    assert (G != G[0]).any() and np.all(G == np.swapaxes(G, -1, -2)) and not np.any(G[:, np.arange(16), np.arange(16)])
    fixed = compare.simulate_target("centralized", 8, 3, runs=10)
    switching = compare.simulate_target("centralized", 8, 3, runs=10, graph="switching")
    np.testing.assert_allclose(switching["rmse_own"], fixed["rmse_own"], rtol=1e-12)  # it does not talk
    ci = compare.simulate_target("ci-L1", 8, 3, runs=10, graph="switching")
    assert np.all(ci["rmse_own"] > fixed["rmse_own"])
    loc = compare.simulate_target("ci-L1", 8, 3, runs=4, graph="switching", task="localization")
    loc_ring = compare.simulate_target("ci-L1", 8, 3, runs=4, task="localization")
    assert np.all(np.isfinite(loc["rmse_own"])) and not np.allclose(loc["rmse_own"], loc_ring["rmse_own"])


def test_switching_own_state_uses_the_graph_of_each_step(monkeypatch):
    """At step k the control's Laplacian, the measurements and Song et al.'s prediction use switching_graphs[k]."""
    from dataclasses import replace

    from mascore import distributed_kf as dkf
    from mascore import graphs

    s = replace(compare.SETTINGS, n_steps=30, steady_from=10)
    G = compare.switching_graphs(8, s.n_steps, s)
    assert (G != G[0]).any()
    control, predict, masks = [], [], []
    consensus_control, team_predict, team_update = (_team_kernels.control_inputs, dkf.TeamFilter.predict,
                                                    dkf.TeamFilter.update)

    def record_control(view, laplacian, K):
        control.append(np.array(laplacian))
        return consensus_control(view, laplacian, K)

    def record_predict(self, laplacian=None):
        predict.append(np.array(self.laplacian if laplacian is None else laplacian))
        return team_predict(self, laplacian)

    def record_update(self, Z, mask):
        masks.append(np.array(mask))
        return team_update(self, Z, mask)

    monkeypatch.setattr(_team_kernels, "control_inputs", record_control)  # the team loop's control law
    monkeypatch.setattr(dkf.TeamFilter, "predict", record_predict)
    monkeypatch.setattr(dkf.TeamFilter, "update", record_update)
    compare.simulate_team("song-eb", 8, 0, graph="switching", runs=3, settings=s)
    assert len(control) == len(predict) == len(masks) == s.n_steps
    for k in range(s.n_steps):
        L_k = graphs.laplacian(G[k])
        np.testing.assert_array_equal(control[k], L_k)
        np.testing.assert_array_equal(predict[k], L_k)  # the prediction after step k's control
        np.testing.assert_array_equal(masks[k].reshape(8, 8), (G[k] > 0) | np.eye(8, dtype=bool))


def test_switching_own_state_centralized_is_the_bound():
    runs = 40
    m = {method: compare.simulate_team(method, 16, 2, graph="switching", runs=runs)
         for method in ("centralized", "local", "forwarding")}
    assert np.all(np.isfinite(m["centralized"]["rmse_own"]))
    assert m["centralized"]["rmse_own"].mean() <= m["local"]["rmse_own"].mean()
    np.testing.assert_allclose(m["forwarding"]["rmse_own"], m["centralized"]["rmse_own"], rtol=1e-9)  # one hop
    assert abs(m["centralized"]["nees_own"].mean() - 1) < 0.1


def test_vlahakis_refuses_the_switching_topology_and_says_why():
    for method in compare.VLAHAKIS_PHI:
        with pytest.raises(ValueError, match=f"{method} does not apply on graph='switching'.*fixed Laplacian"):
            compare.simulate_team(method, 8, 0, graph="switching", runs=2)
    assert any("vlahakis" in k for k in compare.SWITCHING_NOT_APPLICABLE)
    cells = compare.grid_cells("quick") + compare.grid_cells("full")
    assert not any(c["method"] in compare.VLAHAKIS_PHI for c in cells if c["graph"] == "switching")


def test_localization_on_switching_matches_the_time_varying_riccati_recursion():
    """The centralized filter's MSE and NEES = an exact time-varying covariance recursion over the same graphs."""
    s = compare.SETTINGS
    N, n = 8, 16
    G = compare.switching_graphs(N, s.n_steps, s)
    I2, eye = np.eye(2), np.eye(N)
    P = s.p0 * np.eye(n)
    traces = []
    for A in G:  # built here from the graph: anchors 0 and N/2, z_ij = p_j - p_i on this step's links
        rows = [np.kron(eye[i], I2) for i in (0, N // 2)]
        rows += [np.kron(eye[j] - eye[i], I2) for i in range(N) for j in range(N) if A[i, j]]
        H = np.vstack(rows)
        P = P + s.q_pos * np.eye(n)
        P = np.linalg.inv(np.linalg.inv(P) + H.T @ H / s.r)
        traces.append(np.trace(P) / N)  # mean over agents of the own position's variance
    predicted = float(np.mean(traces[s.steady_from:]))
    m = compare.simulate_target("centralized", N, 11, runs=200, graph="switching", task="localization")
    mse = m["rmse_own"] ** 2
    half = 1.96 * mse.std(ddof=1) / np.sqrt(mse.size)
    assert abs(mse.mean() - predicted) < 2 * half, (mse.mean(), predicted, half)
    assert abs(m["nees_own"].mean() - 1) < 0.07
    _, step = compare._localization_switching(N, s)  # each step's information matrix, exactly
    for k in (0, 40, 149):
        rows = [np.kron(eye[i], I2) for i in (0, N // 2)]
        rows += [np.kron(eye[j] - eye[i], I2) for i in range(N) for j in range(N) if G[k][i, j]]
        H = np.vstack(rows)
        np.testing.assert_allclose(step(k)[0].information_matrices.sum(0), H.T @ H / s.r, atol=1e-9)



# ---------------------------------------------------------------------------- position-only sensing

_OLD_CELL = {"study": "scaling", "task": "team", "method": "local", "n_agents": 4, "graph": "ring",
             "noise": "gaussian", "dropout": 0.0, "q_scale": 1.0, "block": 0}


def test_old_cells_keep_their_seeds_and_numbers():
    """A cell without a sensing key (or with "full") gives the numbers of before the position study."""
    before = {"rmse_own": 0.04893716775245586, "nees_own": 0.9244810451838936, "spread": 0.08614569633939237}
    rows = compare.run_cell(_OLD_CELL)
    for key, value in before.items():  # stored from the code before the sensing coordinate existed
        assert rows[0][key] == pytest.approx(value, rel=1e-12, abs=0), key
    sm = {**_OLD_CELL, "study": "noise", "method": "set-membership", "n_agents": 8, "noise": "uniform", "block": 1}
    assert compare.run_cell(sm)[0]["rmse_own"] == pytest.approx(0.13921996031300424, rel=1e-12, abs=0)
    for cell in (_OLD_CELL, sm):
        strip = lambda rows: [{k: v for k, v in r.items() if k != CPU} for r in rows]  # noqa: E731
        a, b = strip(compare.run_cell(cell)), strip(compare.run_cell({**cell, "sensing": "full"}))
        assert json.dumps(a) == json.dumps(b)
    full = sweep.cell_seed(_OLD_CELL, compare.SEED_AXES)
    new = sweep.cell_seed({**_OLD_CELL, "sensing": "position"}, (*compare.SEED_AXES, "sensing"))
    assert full.entropy != new.entropy or full.spawn_key != new.spawn_key
    assert np.random.default_rng(full).random() != np.random.default_rng(new).random()


@pytest.mark.parametrize("cell, match", [
    ({**_OLD_CELL, "sensing": "velocity"}, "sensing"),
    ({**_OLD_CELL, "method": "song-mb", "sensing": "position"}, "position"),
    ({**_OLD_CELL, "task": "target", "method": "centralized", "sensing": "position"}, "sensing"),
])
def test_bad_sensing_is_refused_by_name(cell, match):
    with pytest.raises(ValueError, match=match):
        compare.run_cell(cell)


def test_simulate_team_refuses_bad_sensing():
    with pytest.raises(ValueError, match="sensing"):
        compare.simulate_team("local", 4, 0, runs=2, sensing="pos")
    with pytest.raises(ValueError, match="not applicable|does not apply"):
        compare.simulate_team("song-mb", 4, 0, runs=2, sensing="position")
    with pytest.raises(ValueError, match="does not apply"):
        compare.floats_per_step("song-mb", 4, sensing="position")


def test_position_only_local_kf_matches_the_dare():
    """The per-agent position-only filter reaches the DARE with C = [1 0] per axis; its MSE matches, within its interval."""
    s = compare.SETTINGS
    team = compare.team_setup(4, "gaussian", 1.0, s, sensing="position")
    est = compare.make_estimator("local", team, np.zeros((1, 4, 4)))
    for _ in range(400):
        est.update(np.zeros((1, 4, 4, 2)), np.ones((1, 4, 4), bool))
        est.predict(np.zeros((1, 4, 2)))
    A, C = np.array([[1.0, s.dt], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    prior = sla.solve_discrete_are(A.T, C.T, np.diag([s.q_pos, s.q_vel]), np.array([[s.r]]))
    P = np.broadcast_to(est.P, (1, 4, 4, 4)).reshape(-1, 4, 4)[0]
    np.testing.assert_allclose(P[np.ix_([0, 2], [0, 2])], prior, rtol=1e-8)  # x axis: [p_x, v_x]
    pos_only, full = compare.position_only_kf_rmse()
    m = compare.simulate_team("local", 8, 21, runs=200, sensing="position")
    mse = m["rmse_own"] ** 2
    half = 1.96 * mse.std(ddof=1) / np.sqrt(mse.size)
    assert abs(mse.mean() - pos_only**2) < 2 * half, (mse.mean(), pos_only**2, half)
    assert pos_only > full  # measuring the velocity too helps


def test_centralized_position_covariance_matches_the_dare_of_three_positions():
    """On the ring every agent's position is measured three times; the team filter splits per agent: its own block
    is the DARE with C = [1 0; 1 0; 1 0] per axis."""
    s = compare.SETTINGS
    N = 5
    team = compare.team_setup(N, "gaussian", 1.0, s, sensing="position")
    est = compare.make_estimator("centralized", team, np.zeros((1, N, 4)))
    S = ((team.adjacency > 0) | np.eye(N, dtype=bool))[None]
    for _ in range(400):
        est.predict(np.zeros((1, N, 2)))
        est.update(np.zeros((1, N, N, 2)), S)
    A, C = np.array([[1.0, s.dt], [0.0, 1.0]]), np.ones((3, 1)) @ np.array([[1.0, 0.0]])
    prior = sla.solve_discrete_are(A.T, C.T, np.diag([s.q_pos, s.q_vel]), s.r * np.eye(3))
    post = prior - prior @ C.T @ np.linalg.solve(C @ prior @ C.T + s.r * np.eye(3), C @ prior)
    own = est.own_cov[0]
    for i in range(N):
        np.testing.assert_allclose(own[i][np.ix_([1, 3], [1, 3])], post, rtol=1e-7)  # y axis
    P = est.P[0]
    off = P.copy()
    for i in range(N):
        off[4 * i:4 * i + 4, 4 * i:4 * i + 4] = 0
    assert np.abs(off).max() < 1e-12  # no cross-covariance: the task is separable


@pytest.mark.parametrize("dropout", [0.0, 0.3])
def test_forwarding_is_the_centralized_filter_with_positions_only(dropout):
    c = compare.simulate_team("centralized", 6, 4, runs=20, dropout=dropout, sensing="position")
    f = compare.simulate_team("forwarding", 6, 4, runs=20, dropout=dropout, sensing="position")
    np.testing.assert_allclose(f["rmse_own"], c["rmse_own"], rtol=1e-10)
    np.testing.assert_allclose(f["nees_own"], c["nees_own"], rtol=1e-9)
    local = compare.simulate_team("local", 6, 4, runs=20, dropout=dropout, sensing="position")
    assert np.all(local["rmse_own"] > c["rmse_own"])


def test_set_membership_with_positions_filters_and_contains_the_truth_at_every_step():
    """C = [I 0]: the centre is not the measurement; under uniform noise (guaranteed bounds) the set holds the
    true state after every correction and prediction; the gain applied to all agents is the package's own."""
    from mascore import set_membership

    s = compare.SETTINGS
    N, R = 4, 30
    team = compare.team_setup(N, "uniform", 1.0, s, sensing="position")
    rng = np.random.default_rng(7)
    box = lambda shape: rng.uniform(-np.sqrt(3.0), np.sqrt(3.0), shape)  # noqa: E731  unit variance, bounded
    x = rng.standard_normal((R, N, 4))
    est = compare.make_estimator("set-membership", team, x + np.sqrt(s.p0) * box((R, N, 4)))
    q_std = np.sqrt(np.diag(team.Q))
    moved = []
    for k in range(60):
        Z = x[:, None, :, :2] + np.sqrt(s.r) * box((R, N, N, 2))
        prior_c, prior_P = est.own.copy(), np.array(est.shape)
        est.update(Z, np.ones((1, N, N), bool))
        assert est.containment(x).all(), k
        y = Z[:, np.arange(N), np.arange(N)]
        moved.append(np.abs(est.own[..., :2] - y).max())
        if k == 0:  # the batched gain is the package's correction on every agent and run
            c, P, _ = est.model.correct(prior_c, np.broadcast_to(prior_P, (R, N, 4, 4)), y, check_consistency=False)
            np.testing.assert_allclose(est.own, c, rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(np.broadcast_to(est.shape, P.shape), P, rtol=1e-10)
        U = 0.1 * rng.standard_normal((R, N, 2))
        est.predict(U)
        x = x @ team.A.T + U @ team.B.T + q_std * box((R, N, 4))
        assert est.containment(x).all(), k
    assert min(moved) > 1e-3  # the correction does not return the measurement (L != I)
    assert isinstance(est.model, set_membership.SetMembershipModel)
    m = compare.simulate_team("set-membership", 6, 3, runs=30, noise="uniform", sensing="position")
    assert m["containment"].min() == 1.0
    assert np.all(m["set_size"] > m["rmse_own"])  # the set's largest semi-axis is larger than the error
    assert np.sqrt(2 * s.r) > m["rmse_own"].mean()  # better than the raw measurement


def test_position_headline_lists_every_method_and_what_does_not_apply():
    summary = compare.summarize(_quick_rows([c for c in compare.grid_cells("quick") if c["study"] == "position"
                                             and c["block"] == 0]))
    table = compare.headline(summary, "position")
    assert list(table.index) == [*compare.POSITION_METHODS, *compare.POSITION_NOT_APPLICABLE]
    assert not table.isna().any().any()
    assert table.loc["forwarding", "RMSE ratio [95 %]"].startswith("1.000")
    assert table.loc["set-membership", "contains, uniform"] == "1.000"
    assert float(table.loc["set-membership-c90", "set size (m)"]) < float(table.loc["set-membership", "set size (m)"])
    assert table.loc["centralized", "floats/step"] == 18.0  # positions up (2 per measurement), estimates down

def test_switching_own_state_keeps_the_last_received_view_of_an_agent_out_of_reach(monkeypatch):
    """A view of j held by i is j's broadcast estimate at the last step k' <= k with the link (i, j) in graph k'."""
    from dataclasses import replace


    s = replace(compare.SETTINGS, n_steps=40, steady_from=10)
    N = 8
    G = compare.switching_graphs(N, s.n_steps, s) > 0
    views = []
    consensus_control = _team_kernels.control_inputs

    def record(view, laplacian, K):
        views.append(np.array(view))
        return consensus_control(view, laplacian, K)

    monkeypatch.setattr(_team_kernels, "control_inputs", record)  # the team loop's control law
    compare.simulate_team("local", N, 5, graph="switching", runs=3, settings=s)
    assert len(views) == s.n_steps
    own = np.stack([v[:, np.arange(N), np.arange(N)] for v in views])  # (steps, R, N, 4): j's broadcast estimate
    checked = 0
    for k in range(s.n_steps):
        for i in range(N):
            for j in range(N):
                if i == j:
                    continue
                linked = np.flatnonzero(G[: k + 1, i, j])
                last = linked[-1] if linked.size else 0  # never linked: the view of the first step
                np.testing.assert_array_equal(views[k][:, i, j], own[last][:, j])
                checked += last != k
    assert checked > 0  # some views were held over steps without the link


def test_switching_own_state_runs_with_dropouts_for_every_applicable_method():
    from dataclasses import replace

    s = replace(compare.SETTINGS, n_steps=30, steady_from=10)
    for method in compare.CORE_METHODS:
        if method in compare.VLAHAKIS_PHI:
            continue
        m = compare.simulate_team(method, 8, 4, dropout=0.3, graph="switching", runs=3, settings=s)
        assert np.all(np.isfinite(m["rmse_own"])) and np.all(np.isfinite(m["rmse_view"])), method


def test_localization_riccati_is_the_exact_error_covariance_of_the_fusion_filters_on_a_fixed_graph():
    """localization_riccati (built from the graph) = fusion.error_covariance (the filters' exact error) on the ring."""
    from mascore import fusion

    s = compare.SETTINGS
    N = 8
    exact = compare.localization_riccati(N, "ring")
    model = compare.localization_model(N, "ring")
    own = 2 * np.arange(N)[:, None] + np.arange(2)
    w = slice(s.steady_from, s.n_steps)
    C, P = fusion.error_covariance(fusion.CentralizedFilter(model), s.p0 * np.eye(2 * N), s.n_steps)
    assert np.isclose(np.trace(C[w], axis1=1, axis2=2).mean() / N, exact["centralized"], rtol=1e-8)
    C, P = fusion.error_covariance(fusion.MeasurementForwardingFilter(model), s.p0 * np.eye(2 * N), s.n_steps)
    blocks = C[w][:, np.arange(N)[:, None, None], own[:, :, None], own[:, None, :]]  # (K', N, 2, 2)
    assert np.isclose(np.trace(blocks, axis1=-2, axis2=-1).mean(), exact["forwarding"], rtol=1e-8)
    # agents 2 and 6 of the ring never have an anchor within one hop: their own position drifts unobserved
    assert exact["anchor reach, least"] == 0.0 and exact["forwarding ratio"] > 5


def test_localization_forwarding_on_switching_matches_the_exact_recursion():
    """Forwarding on the switching graph: its MSE is the time-varying Riccati recursion's, its NEES 1."""
    N = 8
    exact = compare.localization_riccati(N, "switching")
    m = compare.simulate_target("forwarding", N, 13, runs=200, graph="switching", task="localization")
    mse = m["rmse_own"] ** 2
    half = 1.96 * mse.std(ddof=1) / np.sqrt(mse.size)
    assert abs(mse.mean() - exact["forwarding"]) < 2 * half, (mse.mean(), exact["forwarding"], half)
    assert abs(m["nees_own"].mean() - 1) < 0.07
    assert exact["anchor reach, least"] > 0  # every agent meets an anchor within one hop now and then


def test_every_knob_setting_is_swept_at_n_8_on_the_ring_beside_its_bound():
    for grid in ("quick", "full"):
        cells = compare.grid_cells(grid)
        ring8 = {(c["study"], c["task"], c["method"]) for c in cells
                 if c["n_agents"] == 8 and c["graph"] == "ring" and c["dropout"] == 0.0 and c["noise"] == "gaussian"}
        for knob in compare.KNOBS:
            assert len(knob.settings) >= 2 and set(knob.recipe) <= {s for s, _, _ in knob.settings}, knob.name
            for setting, study, method in knob.settings:
                assert (study, knob.task, method) in ring8, (grid, knob.name, setting)
                bound = "central-fusion" if knob.task == "shared" else "centralized"
                assert (study, knob.task, bound) in ring8, (grid, knob.name, study)
    names = {m for k in compare.KNOBS for _, _, m in k.settings}
    assert {f"ren-kc{q}" for q in ("-q0", "", "-q0.3", "-q0.6", "-q1")} <= names  # Q = Omega in {0, 0.1, 0.3, 0.6, 1}
    assert {"ci-L1", "ci-L2", "ci-L5", "ci-Ldiam", "hcmci-safe-L1", "icf-Ldiam"} <= names


def test_ren_knob_flips_the_consistency_verdict_and_the_table_says_so():
    """Q = Omega = 0 counts the priors again (overconfident); at Q = Omega = 1 the P is conservative."""
    cell = {"study": "shared", "task": "shared", "n_agents": 8, "graph": "ring", "noise": "gaussian",
            "dropout": 0.0, "q_scale": 1.0, "block": 0}
    rows = [{**r, **cell, "method": m, "cell": m} for m in ("central-fusion", *compare.REN_Q)
            for r in compare.run_cell({**cell, "method": m})]
    table = compare.knob_table(compare.summarize(pd.DataFrame(rows)))
    ren = table[table["scenario"] == "shared"].set_index("setting")
    assert list(ren.index) == ["0", "0.1 *", "0.3", "0.6", "1"]
    assert ren.loc["0", "consistency verdict"] == "overconfident" and ren.loc["1", "consistency verdict"] == "conservative"
    assert set(ren["flips"]) == {"accuracy, consistency"} or set(ren["flips"]) == {"consistency"}


def test_headline_cpu_is_one_agents_step_from_the_per_agent_table():
    """One CPU column everywhere: the headline's is the per-agent table's number at N = 8, never the batch's."""
    costs = pd.DataFrame({"task": ["team", "team", "team", "team"], "method": ["centralized", "local"] * 2,
                          "n_agents": [8, 8, 16, 16], "us_per_step": [40.0, 12.0, 80.0, 12.5],
                          "flops": [1.0, 1.0, 8.0, 1.0]})
    cell = {"study": "scaling", "task": "team", "n_agents": 8, "graph": "ring", "noise": "gaussian", "dropout": 0.0,
            "q_scale": 1.0, "block": 0}
    rows = [{**r, **cell, "method": m, "cell": m} for m in ("centralized", "local", "forwarding")
            for r in compare.run_cell({**cell, "method": m}, settings=replace(compare.SETTINGS, runs=3))]
    summary = compare.summarize(pd.DataFrame(rows))
    table = compare.headline(summary, "team", costs)
    assert table.loc["centralized", compare.CPU_COLUMN] == 40.0 and table.loc["local", compare.CPU_COLUMN] == 12.0
    assert table.loc["forwarding", compare.CPU_COLUMN] == "—"  # not in the per-agent table: not measured
    assert table.loc["centralized", "CPU slope in N"] == 1.0
    assert compare.CPU_COLUMN not in compare.headline(summary, "team").columns  # no batch CPU without it
    fig = compare.plot_cost(costs)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["centralized (slope 1.00)", "local (slope 0.06)"]


@pytest.mark.parametrize("task", ["team", "position", "target", "localization", "shared"])
def test_accuracy_against_floats_is_drawn_for_every_scenario(task):
    from mascore.compare import plots

    study, bound, _ = plots.PARETO_SCENARIOS[task]
    methods = plots._pareto_methods(task)[:3]
    summary = pd.DataFrame({"study": study, "task": task, "method": methods, "n_agents": 8, "graph": "ring",
                            "dropout": 0.0, "noise": "gaussian", "floats": [0.0, 4.0, 8.0],
                            "ratio_mean": [1.0, 1.5, 1.2], "ratio_lo": [1.0, 1.4, 1.1], "ratio_hi": [1.0, 1.6, 1.3]})
    fig = compare.plot_pareto(summary, task)
    assert bound in fig.axes[0].get_ylabel()
    assert [t.get_text() for t in fig.legends[0].get_texts()] == list(methods)
    with pytest.raises(ValueError, match="task must be one of"):
        compare.plot_pareto(summary, "nowhere")


def test_model_on_another_graph_equals_the_model_built_on_it():
    model = compare.target_model(8)
    A = compare.switching_graphs(8, 3)[2]
    moved = model.on_graph(A)
    built = type(model)(model.F, model.Q, model.H, model.R, A)
    assert moved == built
    for name in type(model).__slots__:
        a, b = getattr(moved, name), getattr(built, name)
        if isinstance(a, np.ndarray):
            assert a.tobytes() == b.tobytes() and not a.flags.writeable, name
    with pytest.raises(ValueError, match="adjacency"):
        model.on_graph(np.ones((3, 3)))


def test_the_full_grid_scales_both_fusion_tasks_to_64_where_methods_and_graphs_allow():
    cells = compare.grid_cells("full")
    assert len({sweep.cell_id(c) for c in cells}) == len(cells)
    limits = {task: compare.scale_limits(task) for task in ("target", "localization")}
    for task in ("target", "localization"):
        for graph in compare.SCALE_GRAPHS:
            top = limits[task].get(f"{graph} graph", (64,))[0]
            for method in compare.target_methods(task):
                sizes = {c["n_agents"] for c in cells if c["task"] == task and c["graph"] == graph
                         and c["method"] == method and c["dropout"] == 0.0}
                stop = min(top, limits[task].get(method, (64,))[0])
                assert sizes >= {n for n in compare.SCALE_SIZES if n <= stop}, (task, graph, method)
                assert max(sizes) <= stop, (task, graph, method)
    assert limits["localization"]["ci-diffusion"][0] == 32 and "N^4" in limits["localization"]["ci-diffusion"][1]
    with pytest.raises(ValueError, match="connected"):
        compare.benchmark_graph("geometric", 64)  # why the geometric graph stops at 32
    assert all(c["n_agents"] < 64 for c in compare.grid_cells("quick"))


@pytest.mark.parametrize("method", ["set-membership", "set-membership-c90"])
def test_full_state_set_membership_shares_one_set_and_equals_a_set_per_agent_and_run(method):
    """One (4, 4) shape per step serves every agent and run: the same centres, bit for bit, and the same
    shapes as the batched filter that keeps one set per agent and run (set_membership.correct / predict)."""
    from mascore import set_membership
    from mascore.compare.team import make_estimator, team_setup

    team = team_setup(4, "uniform", 1.0, compare.SETTINGS)
    rng = np.random.default_rng(3)
    x_hat0 = rng.standard_normal((3, 4, 4))
    est = make_estimator(method, team, x_hat0)
    model = est.model
    own = x_hat0.copy()
    shape = np.broadcast_to(est.shape, (3, 4, 4, 4)).copy()
    for _ in range(4):
        Z = own[:, None] + 0.05 * rng.uniform(-1, 1, (3, 4, 4, 4))
        U = 0.1 * rng.standard_normal((3, 4, 2))
        est.update(Z, None)
        own, shape, _ = set_membership.correct(own, shape, Z[:, np.arange(4), np.arange(4)], model.C, model.D,
                                               model.R, check_consistency=False)
        assert est.own.tobytes() == own.tobytes()
        est.predict(U)
        own, shape = set_membership.predict(own, shape, model.A, model.G, model.Q, model.B, U)
        assert est.own.tobytes() == own.tobytes()
        assert est.shape.shape == (4, 4) and (shape == est.shape).all()


def _link_rows() -> tuple[pd.DataFrame, pd.DataFrame]:
    """An ideal-link summary of two methods, and a links summary with one lossy cell of one and one late cell of the
    other."""
    base = {"task": "target", "n_agents": 8, "graph": "ring", "n": 200, "nees_bound_lo": 0.9, "nees_bound_hi": 1.1,
            "containment_mean": np.nan}
    ideal = pd.DataFrame([{**base, "study": "target", "method": m, "dropout": 0.0, "ratio_mean": r, "ratio_lo": r - 0.01,
                           "ratio_hi": r + 0.02, "nees_own_mean": e} for m, r, e in (("ci-L1", 1.3, 0.7),
                                                                                     ("icf-L1", 1.1, 1.05))])
    lossy = pd.DataFrame([{**base, "study": "loss", "method": "ci-L1", "dropout": 0.3, "ratio_mean": 1.4,
                           "ratio_lo": 1.38, "ratio_hi": 1.43, "nees_own_mean": 1.5},
                          {**base, "study": "latency", "method": "icf-L1", "dropout": 0.0, "ratio_mean": 1.2,
                           "ratio_lo": 1.19, "ratio_hi": 1.22, "nees_own_mean": 0.95}])
    return ideal, lossy


def test_link_table_as_text_says_what_its_numbers_say():
    """The shown table (ratios with intervals, ANEES verdicts, one row per cell run) and the numeric one agree."""
    ideal, lossy = _link_rows()
    numbers, text = compare.link_table(ideal, lossy), compare.link_table(ideal, lossy, text=True)
    assert numbers.index.tolist() == ["ci-L1", "icf-L1"]
    assert numbers["RMSE ratio"].columns.tolist() == ["ideal", "loss 0.3", "late, loss 0"]
    assert text.index.tolist() == [("ci-L1", "ideal"), ("ci-L1", "loss 0.3"), ("icf-L1", "ideal"),
                                   ("icf-L1", "late, loss 0")]  # table order; the cells not run left out
    for (m, links), row in text.iterrows():
        mean, lo, hi = map(float, re.findall(r"\d+\.\d+", row["RMSE ratio [95 %]"]))
        assert lo <= mean <= hi and mean == pytest.approx(numbers.loc[m, ("RMSE ratio", links)], abs=5e-4)
        anees = float(re.search(r"ANEES (\d+\.\d+)", row["consistency"]).group(1))
        assert anees == pytest.approx(numbers.loc[m, ("NEES/dof", links)], abs=5e-3)
    assert text["consistency"].tolist() == ["ANEES 0.70, conservative", "ANEES 1.50, overconfident",
                                            "ANEES 1.05, consistent", "ANEES 0.95, consistent"]


def test_interval_table_orders_its_cells_and_refuses_ambiguous_ones():
    ideal, _ = _link_rows()
    table = compare.interval_table(ideal, "graph", ["icf-L1", "absent", "ci-L1"], order=["ring", "switching"])
    assert table.to_dict("index") == {"icf-L1": {"ring": "1.100 [1.090, 1.120]", "switching": "—"},
                                      "ci-L1": {"ring": "1.300 [1.290, 1.320]", "switching": "—"}}
    with pytest.raises(ValueError, match="two rows for one method and graph"):
        compare.interval_table(pd.concat([ideal, ideal]), "graph")
    with pytest.raises(ValueError, match="quantity must be"):
        compare.interval_table(ideal, "graph", quantity="nees")
    with pytest.raises(ValueError, match="columns must name a column of frame"):
        compare.interval_table(ideal, "links")
