"""Tests of the Song et al. (2023) linear scenarios (Sec. V.A, Figs. 2-3, Theorem 1) and its registry."""

import re
from dataclasses import fields, replace
from pathlib import Path

import matplotlib
import numpy as np
import pytest

from mascore import team_observability
from mascore.graphs import is_connected
from mascore.ledger import VERDICTS
from mascore.papers import song2023 as S
from mascore.registry import paper_registry
from mascore.rendezvous import RendezvousModel, expected_spread, simulate_rendezvous, team_spread

matplotlib.use("Agg")

#: Cheap settings for the registry tests (the paper's run takes about half a minute).
SMALL = replace(S.SETTINGS, fig2_runs=5, fig3_runs=4, horizon=10.0, process_noise_q=(1.0, 0.01),
                process_noise_runs=2, process_noise_horizon=6.0)


def test_table_I_values():
    """Song et al. 2023, Table I (rendezvous rows), as settings and as the registered table."""
    t = S.TABLE_I
    assert (t["N"], t["n"], t["dt"], t["r"], t["rho1"], t["rho2"]) == (8, 2, 0.1, 150.0, 0.5, 1.5)
    s = S.setup()
    np.testing.assert_array_equal(s.K, [[0.5, 0, 1.5, 0], [0, 0.5, 0, 1.5]])
    np.testing.assert_allclose(s.B, [[0.005, 0], [0, 0.005], [0.1, 0], [0, 0.1]])
    st = S.SETTINGS
    assert (st.fig2_q, st.fig2_r, st.fig3_q, st.fig3_r, st.fig3_runs) == (1.0, 1.0, 1.0, 100.0, 50)


def test_settings_say_where_every_value_comes_from():
    for f in fields(S.RendezvousSettings):
        meta = f.metadata
        assert meta["source"] in ("paper", "chosen", "derived"), f.name
        assert meta["where"] and meta["note"], f.name
    topology = next(f for f in fields(S.RendezvousSettings) if f.name == "fig3_topology")
    assert topology.metadata["source"] == "chosen" and "fixed per run" in S.SETTINGS.fig3_topology
    assert "Remark 6" in topology.metadata["note"]
    hash(S.SETTINGS)  # frozen, tuples only


def test_registry_holds_both_studies_and_errata():
    reg = paper_registry("song2023")
    assert reg is S.REGISTRY
    assert [s.name for s in reg.studies] == ["rendezvous", "flocking"]
    study = reg.study("rendezvous")
    assert study.chapter == "song2023_rendezvous"
    assert (Path(__file__).parents[1] / "notebooks" / f"{study.chapter}.ipynb").exists()
    assert [f.name for f in study.figures] == ["fig2", "nees", "theorem1", "fig3", "fig3_remark6"]
    assert {f.name: f.number for f in study.figures}["fig3"] == "Fig. 3"
    assert [t.name for t in study.tables] == ["table1", "fig3_std", "process_noise"]
    assert any("Eq. (31)" in e and "e_i e^T" in e for e in reg.errata)
    assert not hasattr(S, "reproduce")  # reproduce_paper writes the registry


def test_random_initial_states_are_connected_and_observable():
    rng = np.random.default_rng(0)
    s = S.setup()
    for _ in range(3):
        x0, A = S.random_initial_states(rng, s)
        assert x0.shape == (8, 4) and is_connected(A)
        assert team_observability.observable_agents(s.A, s.BK, A).all()
        d = np.linalg.norm(x0[:, None, :2] - x0[None, :, :2], axis=-1)
        np.testing.assert_array_equal(A > 0, (d <= 150.0) & ~np.eye(8, dtype=bool))


def test_fig2_small_error_matches_covariance_and_is_deterministic():
    """Fig. 2(c)-(d): RMS error over sqrt(trace) close to 1; same seed -> same numbers."""
    a = S.fig2(seed=3, n_runs=20, horizon=10.0)
    b = S.fig2(seed=3, n_runs=20, horizon=10.0)
    np.testing.assert_array_equal(a.estimation.states, b.estimation.states)
    ratio = a.error_to_std_ratio()
    assert np.all(np.abs(ratio - 1) < 0.2)
    assert abs(ratio.mean() - 1) < 0.08
    # the centralized filter is the accuracy bound
    assert np.all(a.estimation.pos_std[:, 0] >= a.estimation.central_pos_std - 1e-9)


@pytest.fixture(scope="module")
def small_result():
    return S.RENDEZVOUS_STUDY.run(SMALL, seed=0)


def test_every_figure_draws_with_labelled_axes(small_result):
    import matplotlib.pyplot as plt

    for spec in S.RENDEZVOUS_STUDY.figures:
        fig = S.RENDEZVOUS_STUDY.draw(spec.name, small_result)
        assert isinstance(fig, matplotlib.figure.Figure), spec.name
        for ax in fig.axes:
            assert ax.get_xlabel() and ax.get_ylabel(), (spec.name, ax.get_title())
        assert "Look for" in spec.caption, spec.name
        plt.close(fig)


def test_tables_and_claims_from_a_small_run(small_result):
    t1 = S.RENDEZVOUS_STUDY.build("table1", small_result)
    assert list(t1["value"]) == [8, 2, 0.1, 150.0, 0.5, 1.5]
    std = S.RENDEZVOUS_STUDY.build("fig3_std", small_result)
    assert std.shape == (11, 1 + 2 * len(S.LAWS)) and std["time_s"].iloc[-1] == pytest.approx(10.0)
    assert len(S.RENDEZVOUS_STUDY.build("process_noise", small_result)) == 4
    claims = S.RENDEZVOUS_STUDY.claims(small_result)
    assert len({c.id for c in claims}) == len(claims) == 9
    assert all(c.verdict in VERDICTS for c in claims)
    assert all(c.rule for c in claims if c.paper_value is None)


def test_remark6_loop_with_the_sensing_graph_is_the_estimation_loop():
    """simulate_remark6(control = sensing graph) is simulate_rendezvous(mode="estimation"), same noise."""
    s = S.setup()
    rng = np.random.default_rng(5)
    x0, A = S.random_initial_states(rng, s)
    X0 = np.repeat(x0[None], 3, axis=0)
    xh0 = S._initial_estimates(rng, s, X0)
    Q, R = np.eye(4), 10 * np.eye(4)
    ref = simulate_rendezvous(np.random.default_rng(9), RendezvousModel(s.A, s.B, s.K, Q, R, s.dt), X0, A, 30,
                              "estimation", x_hat0=xh0, P0=s.P0())
    ours = S.simulate_remark6(np.random.default_rng(9), X0, A, s, Q, R, 30, xh0, control_adjacency=A)
    np.testing.assert_allclose(ours, ref.states, rtol=1e-10, atol=1e-9)
    # the Remark 6 reading (complete control graph) is a different, still bounded loop
    full = S.simulate_remark6(np.random.default_rng(9), X0, A, s, Q, R, 30, xh0)
    assert not np.allclose(full, ref.states) and np.all(np.isfinite(full))


@pytest.fixture(scope="module")
def fig3_small():
    return S.fig3(seed=1, n_runs=10, horizon=20.0)


def test_fig3_small_velocity_spread_smaller_with_estimates(fig3_small):
    """Fig. 3(b) ordering with a reduced Monte Carlo (10 runs, 20 s)."""
    c = fig3_small.converged("vel")
    assert c[S.ESTIMATION] < c[S.CONVENTIONAL]
    assert c[S.REMARK6] < c[S.CONVENTIONAL]
    assert c[S.TRUE_STATES] < c[S.ESTIMATION]


@pytest.mark.parametrize("law", [S.CONVENTIONAL, S.TRUE_STATES])
@pytest.mark.parametrize("which", ["pos", "vel"])
def test_fig3_monte_carlo_spread_matches_exact_expectation(fig3_small, law, which):
    """Independent check of the Fig. 3 statistic: Monte Carlo spread vs its exact expectation (laws (4), (5))."""
    r = fig3_small
    mc = (r.pos_runs if which == "pos" else r.vel_runs)[law]
    ex = (r.exact_pos_runs if which == "pos" else r.exact_vel_runs)[law]
    np.testing.assert_allclose(mc[0], ex[0], rtol=1e-12)  # known initial states
    k0 = np.searchsorted(r.time, r.converged_from)
    d = np.mean(mc[k0:] ** 2, axis=0) - np.mean(ex[k0:] ** 2, axis=0)  # per run, independent across runs
    assert abs(d.mean()) < 4 * d.std(ddof=1) / np.sqrt(d.size)  # z-test over the 10 independent runs
    # a mis-normalised statistic (per axis, or over N - 1 agents) would be off by far more than the noise
    assert d.std(ddof=1) / np.sqrt(d.size) < 0.25 * np.mean(ex[k0:] ** 2)


def test_expected_spread_is_zero_without_noise_and_matches_noise_free_run():
    s = S.setup(4)
    x0 = np.random.default_rng(3).normal(scale=50, size=(2, 4, 4))
    A = np.ones((4, 4)) - np.eye(4)
    Z = np.zeros((4, 4))
    model = RendezvousModel(s.A, s.B, s.K, Z, np.eye(4), s.dt)
    run = simulate_rendezvous(0, model, x0, A, 30, "true")
    ex = expected_spread(model, x0, A, 30, "true")
    np.testing.assert_allclose(np.sqrt(ex[..., :2].sum(-1)), team_spread(run.states[..., :2]), rtol=1e-9)
    with pytest.raises(ValueError, match="mode must be 'true' or 'measurement'"):
        expected_spread(model, x0, A, 30, "estimation")


def test_noise_free_true_state_law_reaches_rendezvous():
    """Eq. (4) with no noise: positions and velocities reach a common value (Sec. II.C)."""
    s = S.setup()
    x0, A = S.random_initial_states(np.random.default_rng(2), s)
    model = RendezvousModel(s.A, s.B, s.K, np.zeros((4, 4)), np.eye(4), s.dt)
    res = simulate_rendezvous(0, model, x0, A, 800, "true")  # one run: no run axis
    assert res.states.shape == (801, *x0.shape)
    assert team_spread(res.states[-1, :, :2]) < 1e-3 * team_spread(res.states[0, :, :2])
    assert team_spread(res.states[-1, :, 2:]) < 1e-3


def test_one_run_equals_the_first_of_a_batch_of_one():
    """x0 of shape (N, m) is the same run as (1, N, m), without the run axis."""
    s = S.setup(4)
    x0, A = S.random_initial_states(np.random.default_rng(4), s)
    model = RendezvousModel(s.A, s.B, s.K, 0.01 * np.eye(4), np.eye(4), s.dt)
    xh0 = x0.reshape(-1) + 1.0
    one = simulate_rendezvous(3, model, x0, A, 15, "estimation", x_hat0=xh0, P0=np.eye(4), central=True)
    batch = simulate_rendezvous(3, model, x0[None], A, 15, "estimation", x_hat0=xh0[None], P0=np.eye(4), central=True)
    for name in ("states", "pos_error", "pos_std", "nees", "central_pos_std", "central_pos_error"):
        np.testing.assert_array_equal(getattr(one, name), getattr(batch, name)[:, 0])
    np.testing.assert_array_equal(one.sigma_i, batch.sigma_i)


#: The note of a Fig. 3 claim states the exact expected spreads of laws (5) and (4) beside their Monte Carlo values.
_EXACT_NOTE = re.compile(r"propagated exactly \(.*?\): ([\d.]+) and ([\d.]+) m(?:/s)? against the Monte Carlo "
                         r"([\d.]+) and ([\d.]+) m(?:/s)? \(([-+][\d.]+) and ([-+][\d.]+) standard errors")


def test_published_claims(published):
    """The published ledger of the rendezvous study (results/song2023, seed 1): computed verdicts and the
    documented mismatch."""
    _, claims = published("song2023")
    by_id = {c.id: c for c in claims if c.study == "rendezvous"}
    for key in ("fig2-error-matches-covariance", "nees-rendezvous", "nees-rendezvous-measurement-based",
                "theorem1-lyapunov-decrease", "centralized-bound", "fig3-velocity-std", "fig3-position-std-remark6",
                "fig3-velocity-std-remark6"):
        assert by_id[f"song2023/{key}"].verdict == "holds", key
    # documented mismatch: on the neighbours' estimates the position spreads of the two laws are
    # statistically indistinguishable; Remark 6's reading gives the paper's ordering
    pos = by_id["song2023/fig3-position-std"]
    assert pos.verdict == "fails"
    v = pos.value
    assert abs(v["estimation-based (m)"] - v["conventional (m)"]) < 0.1 * v["conventional (m)"]
    assert abs(v["paired difference (m²)"]) < 2 * v["its standard error (m²)"]
    assert v["excess removed"] < 0.3 < by_id["song2023/fig3-velocity-std"].value["excess removed"]
    r6 = by_id["song2023/fig3-position-std-remark6"].value
    assert r6["paired difference (m²)"] < -3 * r6["its standard error (m²)"]
    # the Monte Carlo statistic agrees with its exact expectation (laws (4), (5)) to sampling accuracy,
    # as the claims' notes state it: within 10 % and 4 standard errors
    for which, unit in (("position", "m"), ("velocity", "m/s")):
        claim = by_id[f"song2023/fig3-{which}-std"]
        m = _EXACT_NOTE.search(claim.note)
        assert m, claim.note
        exact_conv, exact_true, mc_conv, mc_true, z_conv, z_true = map(float, m.groups())
        # the note's Monte Carlo numbers are the claim's values, printed to 3 significant digits
        assert abs(mc_conv / claim.value[f"conventional ({unit})"] - 1) < 6e-3
        assert abs(mc_true / claim.value[f"true-state reference ({unit})"] - 1) < 6e-3
        for mc, ex, z in ((mc_conv, exact_conv, z_conv), (mc_true, exact_true, z_true)):
            assert abs(mc / ex - 1) < 0.1 and abs(z) < 4, (which, mc, ex, z)


def test_process_noise_study_small_q_restores_position_ordering():
    """Beyond the paper: with little process noise the estimation-based law also wins on position."""
    df = S.process_noise_study(seed=0, q_values=(0.01,), n_runs=3, horizon=24.0)
    pos = df.set_index("law")["pos_std_m"]
    assert pos[S.ESTIMATION] < 0.5 * pos[S.CONVENTIONAL]


# ---------------------------------------------------------------- bad input (issue 14)


def _remark6_args(**override):
    """Valid arguments of simulate_remark6 (1 run, 3 steps), with `override` spoiling one."""
    s = S.setup()
    x0, adj = S.random_initial_states(np.random.default_rng(0), s)
    X0 = x0[None]
    args = dict(rng=np.random.default_rng(1), x0=X0, adjacency=adj, s=s, Q=np.eye(s.m), R=np.eye(s.m), n_steps=3,
                x_hat0=X0.reshape(1, -1))
    return {**args, **override}


_BAD_X0 = np.zeros((1, 8, 3))


@pytest.mark.parametrize("fn", [S.fig2, S.fig3, S.process_noise_study])
@pytest.mark.parametrize("arg, bad", [("seed", -1), ("seed", "0"), ("n_runs", 0), ("n_runs", -2), ("n_runs", 2.0),
                                      ("n_runs", "3"), ("horizon", np.nan), ("horizon", np.inf), ("horizon", 0.0),
                                      ("horizon", -1.0), ("horizon", "40"), ("horizon", 0.01)])
def test_run_functions_name_bad_argument(fn, arg, bad):
    with pytest.raises((TypeError, ValueError), match=arg):
        fn(**{arg: bad})


@pytest.mark.parametrize("bad", [(np.nan,), (-1.0,), (), "0.1", ((0.1, 0.2),)])
def test_process_noise_study_names_bad_q_values(bad):
    with pytest.raises((TypeError, ValueError), match="q_values"):
        S.process_noise_study(q_values=bad, n_runs=1, horizon=1.0)


@pytest.mark.parametrize("arg, bad", [
    ("rng", -1), ("rng", "seed"), ("x0", np.full((1, 8, 4), np.nan)), ("x0", np.full((1, 8, 4), np.inf)),
    ("x0", "x"), ("x0", _BAD_X0), ("n_steps", 0), ("n_steps", -1), ("n_steps", 2.0), ("n_steps", "3"),
    ("x_hat0", np.full((1, 32), np.nan)), ("x_hat0", np.full((1, 32), np.inf)), ("x_hat0", "x"),
    ("x_hat0", np.zeros((1, 31))), ("control_adjacency", np.ones((3, 3))), ("s", "setup"),
])
def test_simulate_remark6_names_bad_argument(arg, bad):
    with pytest.raises((TypeError, ValueError), match=arg):
        S.simulate_remark6(**_remark6_args(**{arg: bad}))


def test_simulate_remark6_unchanged_by_checks():
    """A seed is now accepted as `rng`; with a Generator the numbers are those of the same seed."""
    a = S.simulate_remark6(**_remark6_args(rng=np.random.default_rng(5)))
    b = S.simulate_remark6(**_remark6_args(rng=5))
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("call, name", [
    (lambda: S.setup(n_agents=0), "n_agents"), (lambda: S.setup(n_agents=2.5), "n_agents"),
    (lambda: S.estimator_step_seconds(2), "n_agents"), (lambda: S.estimator_step_seconds(4, repeat=0), "repeat"),
    (lambda: S.estimator_step_seconds(4, plain_repeat=-1), "plain_repeat"), (lambda: S.run(seed=-1), "seed"),
])
def test_other_functions_name_bad_argument(call, name):
    with pytest.raises((TypeError, ValueError), match=name):
        call()


@pytest.mark.parametrize("call, name", [
    (lambda: S.plot_theorem1(None, {}, agent=-1), "agent"), (lambda: S.plot_theorem1(None, {}, agent="0"), "agent"),
    (lambda: S.fig3_table(None, every=0.0), "every"), (lambda: S.fig3_table(None, every=np.nan), "every"),
])
def test_plot_and_table_helpers_name_bad_argument(call, name):
    with pytest.raises((TypeError, ValueError), match=name):
        call()
