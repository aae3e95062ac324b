"""Tests of the Song et al. (2023) flocking study (Sec. V-B, Figs. 4-6): settings, run, figures, claims."""

import dataclasses
import json

import matplotlib
import numpy as np
import pandas as pd
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from mascore.graphs import is_connected, proximity_graph  # noqa: E402
from mascore.papers import song2023_flocking as s  # noqa: E402
from mascore.registry import PaperRegistry, show_settings, write_study  # noqa: E402

CLAIM_IDS = (
    "song2023/fig4-non-neighbour-error-bounded",
    "song2023/fig5-position-std",
    "song2023/fig5-velocity-std",
    "song2023/fig6-within-boundary",
)

#: Cheap settings for the tests that only need the machinery (3 runs, short sweep).
CHEAP = dataclasses.replace(s.SETTINGS, n_runs=3, beyond_sensing_ranges=(200.0,), beyond_sizes=(4,),
                            beyond_runs=1, beyond_t_final=3.0)


@pytest.fixture(scope="module")
def cheap_result():
    return s.run(CHEAP, seed=3)


def test_table_one_settings():
    """Song et al. 2023, Table I and Sec. V-B, as settings and as the module constants."""
    st = s.SETTINGS
    g = st.gains
    assert (st.n_agents, st.n_dim, st.dt, st.sensing_range) == (8, 2, 0.1, 150.0)
    assert (g.rho3, g.rho4, g.rho5, g.rho6, g.beta, g.R) == (3.0, 1.0, 2.0, 1.0, 0.33, 120.0)
    assert s.GAINS == g and (s.N_AGENTS, s.DT, s.SENSING_RANGE, s.N_RUNS) == (8, 0.1, 150.0, 50)
    np.testing.assert_array_equal(st.Q, np.eye(4))
    np.testing.assert_array_equal(st.R_fig4, np.eye(4))
    np.testing.assert_array_equal(st.R_fig5, 10 * np.eye(4))
    assert st.n_runs == 50 and st.n_steps == 600 and st.observer == 1


def test_settings_are_documented_and_frozen():
    fields = dataclasses.fields(s.FlockingSettings)
    assert all(f.metadata.get("source") in ("paper", "chosen", "derived") and f.metadata.get("note") for f in fields)
    assert {f.name for f in fields if f.metadata["source"] == "paper"} >= {"n_agents", "rho3", "n_runs"}
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.SETTINGS.n_runs = 10
    table = show_settings(s.SETTINGS)._repr_markdown_()
    assert "FlockingGains(" not in table and "| `similar_fraction` |" in table
    similar = next(line for line in table.splitlines() if "similar_fraction" in line)
    assert similar.count("|") == 6, "a '|' inside the math of a note would split the table cell"


def test_initial_states_connected_and_reproducible():
    a = s.initial_states(np.random.default_rng(3), 6)
    b = s.initial_states(np.random.default_rng(3), 6)
    assert a.shape == (6, 8, 4) and a.tobytes() == b.tobytes()
    assert all(is_connected(proximity_graph(x[:, :2], s.SENSING_RANGE)) for x in a)
    assert np.all(np.abs(a[..., 2:]) <= s.SETTINGS.v0_max)


def test_initial_estimates_follow_sigma0():
    rng = np.random.default_rng(4)
    X0 = s.initial_states(rng, 200)
    X_hat0, Sigma0 = s.initial_estimates(rng, X0)
    assert X_hat0.shape == (200, 8, 8, 4)
    err = (X_hat0 - X0[:, None]).reshape(-1, 4)
    np.testing.assert_allclose(err.var(axis=0), np.diag(s.SIGMA0_AGENT), rtol=0.05)
    np.testing.assert_array_equal(Sigma0, np.kron(np.eye(8), s.SIGMA0_AGENT))


def test_fig4_initial_state_is_the_grid():
    X0 = s.fig4_initial_state(np.random.default_rng(0))
    np.testing.assert_array_equal(X0[:, :2], 100.0 * np.array([[0, 0], [1, 0], [2, 0], [3, 0],
                                                                [0, 1], [1, 1], [2, 1], [3, 1]]))


def test_fig4_claim_holds_and_agent_one_has_non_neighbours(cheap_result):
    run = cheap_result.fig4
    stats = s.fig4_statistics(run)
    assert 0.05 < stats["fraction_non_neighbour"] < 0.95
    assert stats["mean_sigma_non_neighbours"] > 2 * stats["mean_sigma_neighbours"]
    assert stats["entries_into_range"] >= 1
    claim = s.fig4_claim(run)
    assert claim.id == CLAIM_IDS[0] and claim.verdict == "holds", claim.value
    assert len(claim.value) <= 6 and claim.rule  # readable in the ledger, decided by a stated rule
    # Fig. 4(b): the final network is not fully connected
    assert not run.adjacency[-1][~np.eye(8, dtype=bool)].all()


def test_fig4_run_is_deterministic():
    a, b = s.run_fig4(s.SETTINGS, seed=2), s.run_fig4(s.SETTINGS, seed=2)
    assert a.X_hat.tobytes() == b.X_hat.tobytes()


def test_small_monte_carlo_orders_the_cases(cheap_result):
    """Three runs already show the ordering of Fig. 5(a): (ii), (iii) much tighter than (i)."""
    res = cheap_result.fig5
    assert res.std_p.shape == (3, CHEAP.n_steps + 1) and res.final.shape == (3, 3, 8, 4)
    settled = res.settled(res.std_p)
    assert settled[1] < 0.8 * settled[0] and settled[2] < 0.8 * settled[0]
    assert np.all(res.rms_error[:, -1] < 20.0)  # estimates of the whole team stay within metres


def test_claims_from_the_result_are_labelled(cheap_result):
    claims = s.FLOCKING_STUDY.claims(cheap_result)
    assert [c.id for c in claims] == list(CLAIM_IDS)
    json.dumps([c.to_dict() for c in claims], allow_nan=False)
    fig5 = claims[1]
    assert set(fig5.value) == {"case (i)", "case (ii)", "case (iii)"} and fig5.unit == "m"
    assert claims[2].unit == "m/s"
    # the explanation shared by the two Fig. 5 claims is one identical paragraph (shown once)
    shared = set(fig5.note.split("\n\n")) & set(claims[2].note.split("\n\n"))
    assert len(shared) == 1
    assert set(claims[3].value["runs within R (fraction)"]) == {"case i", "case ii", "case iii"}


def test_every_figure_draws_with_labelled_axes(cheap_result):
    study = s.FLOCKING_STUDY
    assert [(f.name, f.number) for f in study.figures] == [
        ("fig4", "Fig. 4"), ("fig5", "Fig. 5"), ("fig6", "Fig. 6"), ("flocking_beyond", "")]
    for spec in study.figures:
        fig = study.draw(spec.name, cheap_result)
        assert isinstance(fig, plt.Figure), spec.name
        for ax in fig.axes:
            assert ax.get_xlabel() and ax.get_ylabel(), f"{spec.name}: unlabelled axes {ax.get_title()!r}"
        titles = [ax.get_title() or ax.get_title(loc="left") for ax in fig.axes]
        letters = [t[:3] for t in titles if t.startswith("(")]
        assert len(letters) == len(fig.axes) == len(set(letters)), f"{spec.name}: panel letters {titles}"
        assert fig.get_size_inches()[0] <= 7.6, f"{spec.name}: wider than the book's text"
        assert not any(ax.get_legend() for ax in fig.axes), f"{spec.name}: legend inside a panel"
        plt.close(fig)


def test_tables_and_write_study(cheap_result, tmp_path):
    study = s.FLOCKING_STUDY
    table = study.build("fig5_fig6_flocking", cheap_result)
    assert list(table["case"]) == list(s.CASES) and table.shape == (3, 6)
    sweep = study.build("flocking_beyond_sweep", cheap_result)
    assert list(sweep["N"]) == [4, 8] and list(sweep["r (m)"]) == [150.0, 200.0]
    assert set(sweep["unstable"]) == {"-"}
    reg = PaperRegistry("song2023", "Song et al. 2023", (study,))
    claims = write_study(reg, study, cheap_result, tmp_path)
    assert [c.study for c in claims] == ["flocking"] * 4
    for spec in study.figures:
        assert (tmp_path / "figures" / f"{spec.name}.png").stat().st_size > 10_000
    assert isinstance(pd.read_csv(tmp_path / "tables" / "fig5_fig6_flocking.csv"), pd.DataFrame)


def test_full_study_verdicts(published):
    """The published run (50 runs x 3 cases, seed 1, in results/song2023): every flocking claim holds."""
    _, claims = published("song2023")
    claims = [c for c in claims if c.study == "flocking"]
    assert [c.id for c in claims] == list(CLAIM_IDS)
    assert {c.verdict for c in claims} == {"holds"}, [(c.id, c.verdict, c.value) for c in claims]
    frac = claims[3].value["runs within R (fraction)"]
    assert frac == {"case i": 0.0, "case ii": 1.0, "case iii": 1.0}


def test_beyond_study_flags_unstable_large_teams():
    """Beyond the paper: with Table I gains and dt = 0.1 s, N = 24 diverges for the (virtually)
    fully-connected cases (ii), (iii) but not on the proximity graph (i)."""
    big = dataclasses.replace(s.SETTINGS, n_runs=1, n_agents=24, t_final=10.0)
    res = s.run_fig5(big, seed=1)
    assert res.diverged == (False, True, True)
    assert np.all(np.isfinite(res.max_distance[0])) and np.all(np.isnan(res.max_distance[1:]))


def test_ekf_step_seconds_is_positive():
    assert 0 < s.ekf_step_seconds(s.SETTINGS, repeat=1) < 10


# ---------------------------------------------------------------- bad input (issue 14)


@pytest.mark.parametrize("fn", [s.run_fig4, s.run_fig5, s.beyond_study, s.run, s.ekf_step_seconds])
@pytest.mark.parametrize("bad", [-1, "1", 1.5])
def test_seeded_functions_name_bad_seed(fn, bad):
    with pytest.raises((TypeError, ValueError), match="seed"):
        fn(seed=bad)


@pytest.mark.parametrize("call, name", [
    (lambda: s.fig4_initial_state(-1), "rng"), (lambda: s.fig4_initial_state("rng"), "rng"),
    (lambda: s.initial_estimates("rng", np.zeros((8, 4))), "rng"),
    (lambda: s.initial_estimates(np.random.default_rng(0), np.full((8, 4), np.nan)), "X0"),
    (lambda: s.initial_estimates(np.random.default_rng(0), np.zeros((8, 3))), "X0"),
    (lambda: s.initial_estimates(np.random.default_rng(0), "X0"), "X0"),
    (lambda: s.ekf_step_seconds(repeat=0), "repeat"),
])
def test_functions_name_bad_argument(call, name):
    with pytest.raises((TypeError, ValueError), match=name):
        call()


def test_initial_estimates_unchanged_for_lists():
    X0 = np.arange(32.0).reshape(8, 4)
    a = s.initial_estimates(np.random.default_rng(3), X0)[0]
    b = s.initial_estimates(np.random.default_rng(3), X0.tolist())[0]
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("call, name", [
    (lambda: s.plot_fig6(None, run_index=-1), "run_index"), (lambda: s.plot_fig6(None, run_index=0.5), "run_index"),
    (lambda: s.fig4_statistics(None, transient=-1.0), "transient"),
    (lambda: s.fig4_statistics(None, transient=np.nan), "transient"),
])
def test_plot_and_statistics_helpers_name_bad_argument(call, name):
    with pytest.raises((TypeError, ValueError), match=name):
        call()
