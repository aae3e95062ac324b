"""Tests of the Song et al. (2023) flocking scenarios (Sec. V-B, Figs. 4-6) and their claims."""

import json

import numpy as np
import pytest

from mascore.graphs import is_connected, proximity_graph
from mascore.papers import song2023_flocking as s

CLAIM_IDS = (
    "song2023/fig4-non-neighbour-error-bounded",
    "song2023/fig5-position-std",
    "song2023/fig5-velocity-std",
    "song2023/fig6-within-boundary",
)


def test_table_one_settings():
    """Song et al. 2023, Table I and Sec. V-B."""
    g = s.GAINS
    assert (s.N_AGENTS, s.N_DIM, s.DT, s.SENSING_RANGE) == (8, 2, 0.1, 150.0)
    assert (g.rho3, g.rho4, g.rho5, g.rho6, g.beta, g.R) == (3.0, 1.0, 2.0, 1.0, 0.33, 120.0)
    np.testing.assert_array_equal(s.Q_AGENT, np.eye(4))
    np.testing.assert_array_equal(s.R_FIG5, 10 * np.eye(4))
    assert s.N_RUNS == 50


def test_initial_states_connected_and_reproducible():
    a = s.initial_states(np.random.default_rng(3), 6)
    b = s.initial_states(np.random.default_rng(3), 6)
    assert a.shape == (6, 8, 4) and a.tobytes() == b.tobytes()
    assert all(is_connected(proximity_graph(x[:, :2], s.SENSING_RANGE)) for x in a)
    assert np.all(np.abs(a[..., 2:]) <= s.V0_MAX)


def test_initial_estimates_follow_sigma0():
    rng = np.random.default_rng(4)
    X0 = s.initial_states(rng, 200)
    X_hat0, Sigma0 = s.initial_estimates(rng, X0)
    assert X_hat0.shape == (200, 8, 8, 4)
    err = (X_hat0 - X0[:, None]).reshape(-1, 4)
    np.testing.assert_allclose(err.var(axis=0), np.diag(s.SIGMA0_AGENT), rtol=0.05)
    np.testing.assert_array_equal(Sigma0, np.kron(np.eye(8), s.SIGMA0_AGENT))


def test_fig4_claim_holds_and_agent_one_has_non_neighbours():
    run = s.run_fig4(seed=1)
    claim = s.fig4_claim(run)
    assert claim.id == CLAIM_IDS[0]
    v = claim.value
    assert 0.05 < v["fraction_of_steps_non_neighbour"] < 0.95
    assert v["mean_statistical_error_non_neighbours_m"] > 2 * v["mean_statistical_error_neighbours_m"]
    assert claim.verdict == "holds"
    # Fig. 4(b): the final network is not fully connected
    assert not run.adjacency[-1][~np.eye(8, dtype=bool)].all()


def test_fig4_run_is_deterministic():
    a, b = s.run_fig4(seed=2), s.run_fig4(seed=2)
    assert a.X_hat.tobytes() == b.X_hat.tobytes()


def test_small_monte_carlo_orders_the_cases():
    """Three runs already show the ordering of Fig. 5(a): (ii), (iii) much tighter than (i)."""
    res = s.run_fig5(seed=3, n_runs=3)
    assert res.std_p.shape == (3, s.n_steps() + 1) and res.final.shape == (3, 3, 8, 4)
    settled = res.settled(res.std_p)
    assert settled[1] < 0.8 * settled[0] and settled[2] < 0.8 * settled[0]
    claims = [*s.fig5_claims(res), s.fig6_claim(res)]
    assert [c.id for c in claims] == list(CLAIM_IDS[1:])
    assert np.all(res.rms_error[:, -1] < 20.0)  # estimates of the whole team stay within metres


@pytest.mark.slow
def test_full_reproduction_writes_figures_and_claims(tmp_path):
    """The full Figs. 4-6 work (50 runs x 3 cases): four claims, three figures; current verdicts all hold."""
    claims = s.flocking_claims_and_figures(tmp_path, seed=1)
    assert [c.id for c in claims] == list(CLAIM_IDS)
    for name in ("fig4.png", "fig5.png", "fig6.png"):
        assert (tmp_path / "figures" / name).stat().st_size > 10_000
    assert (tmp_path / "tables" / "fig5_fig6_flocking.csv").exists()
    json.dumps([c.to_dict() for c in claims], allow_nan=False)
    assert {c.verdict for c in claims} == {"holds"}, [(c.id, c.verdict, c.value) for c in claims]


def test_beyond_study_flags_unstable_large_teams():
    """Beyond the paper: with Table I gains and dt = 0.1 s, N = 24 diverges for the (virtually)
    fully-connected cases (ii), (iii) but not on the proximity graph (i)."""
    res = s.run_fig5(seed=1, n_runs=1, n_agents=24, t_final=10.0)
    assert res.diverged == (False, True, True)
    assert np.all(np.isfinite(res.max_distance[0])) and np.all(np.isnan(res.max_distance[1:]))
    table = s.beyond_study(1, sensing_ranges=(200.0,), sizes=(4,), n_runs=1, t_final=3.0)
    assert list(table["N"]) == [4, 8] and list(table["r_m"]) == [150.0, 200.0]
    assert set(table["unstable"]) == {"-"}
    assert np.all(np.isfinite(table["ekf_step_ms"])) and np.all(table["ekf_step_ms"] > 0)
