"""Tests of the Ren, Beard and Kingston (2005) scenarios (mascore.papers.ren2005)."""

import dataclasses
import json

import matplotlib
import numpy as np
import pytest

from mascore import consensus as cs
from mascore.graphs import has_spanning_tree, is_connected, spanning_tree_roots
from mascore.papers import ren2005 as ren
from mascore.registry import paper_registry, show_settings

matplotlib.use("Agg")

#: Small settings for the tests that only check shapes and drawing (the full run is the slow test's).
CHEAP = dataclasses.replace(ren.SETTINGS, switch_steps=100, t_final=20.0, noise_runs=10, noise_steps=40,
                            noise_paths=4, noise_t_final=4.0, bias_runs=20)


def test_fig2_graph_matches_the_caption():
    """Sec. III-A: spanning trees rooted at A5 (double arrows), A1 and A4; not strongly connected."""
    A = ren.fig2_graph()
    np.testing.assert_array_equal(spanning_tree_roots(A) + 1, [1, 4, 5])
    tree = np.zeros_like(A)
    for j, i in ren.FIG2_TREE:
        assert A[i, j] > 0, "highlighted edge must be an edge of Fig. 2"
        tree[i, j] = 1.0
    np.testing.assert_array_equal(tree.sum(axis=1), [1, 1, 1, 1, 0, 1])  # one parent each, A5 the root
    np.testing.assert_array_equal(spanning_tree_roots(tree), [4])


def test_fig3_graphs_have_no_spanning_tree_but_their_union_does():
    a, b = ren.fig3a_graph(), ren.fig3b_graph()
    assert not has_spanning_tree(a) and not has_spanning_tree(b)
    assert np.all(a.sum(axis=1)[[0, 3]] == 0)  # Fig. 3(a): A1 and A4 hear nobody (two leaders)
    assert not is_connected(b)  # Fig. 3(b): two isolated groups
    assert has_spanning_tree(a + b)
    assert not has_spanning_tree(ren.no_union_sequence().sum(axis=0))


def test_fig1_scenario():
    """Sec. II-C: n = 10, Omega = Q = 0.1; equal variances agree on the average, P -> 0.05."""
    res = ren.fig1(seed=1)
    assert res.pairings.shape == (ren.SETTINGS.n_steps, 10, 10)
    assert res.equal.spread[-1] < 1e-3 * res.equal.spread[0]
    assert res.equal.final_value == pytest.approx(5.5, abs=1e-6)
    assert res.confident.P[0, ren.CONFIDENT_AGENT] == 0.001 and res.confident.xi[0, ren.CONFIDENT_AGENT] == 7.0
    np.testing.assert_allclose(res.confident.P[-1], 0.05, rtol=1e-6)
    assert res.fused_confident == pytest.approx(cs.central_fusion(*ren.fig1_initial(True))[0])
    again = ren.fig1(seed=1)
    assert again.confident.xi.tobytes() == res.confident.xi.tobytes()


def test_switching_demos():
    good, bad = ren.switching_demo(ren.union_sequence()), ren.switching_demo(ren.no_union_sequence())
    assert good.union_ok and not bad.union_ok
    assert good.discrete.spread[-1] < 1e-5 * good.discrete.spread[0]
    assert bad.discrete.spread[-1] > 0.5 * bad.discrete.spread[0]
    # with no spanning tree each group agrees internally but the groups do not
    assert cs.spread(bad.discrete.xi[-1, :3, None]) < 1e-6 and cs.spread(bad.discrete.xi[-1, 3:, None]) < 1e-6
    assert ren.decay_rate(good.continuous.t, good.continuous.spread) < 0


def test_bias_study_shapes_and_equal_variance_case():
    st = ren.bias_study(seed=2, n_runs=50, n_steps=100)
    assert st["values"].shape == (50,)
    assert st["fused"] == pytest.approx(cs.central_fusion(*ren.fig1_initial(True))[0])
    assert st["average"] < st["values"].mean() < st["fused"]  # pulled towards 7, not all the way


def test_noise_study_floor():
    """Q > 0: a stationary disagreement floor (log-log slope ~ 0); Q = 0: decay like 1/sqrt(k) (slope ~ -1/2)."""
    st = ren.noise_study(seed=3, n_runs=40, n_steps=200)
    assert st["rms"].shape == (201,)
    assert st["floor"] > 1e-2 and abs(st["slope"]) < 0.1
    q0 = ren.noise_study(seed=3, n_runs=40, n_steps=200, Q=0.0)
    assert -0.8 < q0["slope"] < -0.3


def test_overconfidence_study():
    st = ren.overconfidence(seed=2)
    paper, ideal = st["variants"].values()
    for v in (paper, ideal):
        assert v["actual"].shape == v["believed"].shape == (ren.SETTINGS.n_steps + 1, 10)
        assert np.all(v["actual"] >= st["fused_variance"] * (1 - 1e-9))  # nothing beats central fusion
    np.testing.assert_allclose(paper["believed"][-1], 0.05, rtol=1e-6)  # fixed point of eq. (4) on pairings
    assert np.all(paper["actual"][-1] > paper["believed"][-1])
    assert np.all(ideal["believed"][-1] < 1e-3 * ideal["actual"][-1])


def test_settings_are_frozen_documented_and_read_by_the_run():
    s = ren.SETTINGS
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.Q = 0.2
    for f in dataclasses.fields(s):
        assert f.metadata["source"] in ("paper", "chosen", "derived") and f.metadata["note"], f.name
        assert not isinstance(getattr(s, f.name), list | np.ndarray), f.name
    table = str(show_settings(s))
    assert "`n_steps`" in table and "**our choice**" in table and "Sec. II-C" in table
    assert s.xi0[s.confident_agent - 1] == 7.0 and ren.CONFIDENT_AGENT == s.confident_agent - 1
    assert ren.THEOREM["t_final"] == s.t_final and ren.FIG1["max_duration"] == s.max_call  # the aliases
    short = dataclasses.replace(CHEAP, n_steps=30, P_confident=0.01)
    res = ren.fig1(seed=1, settings=short)
    assert res.pairings.shape == (30, 10, 10) and res.confident.P[0, ren.CONFIDENT_AGENT] == 0.01


@pytest.fixture(scope="module")
def cheap_result():
    return ren.run(CHEAP, seed=3)


def test_registry_declares_one_study_with_its_figures_tables_and_claims(cheap_result):
    reg = paper_registry("ren2005")
    assert reg is ren.REGISTRY and reg.citation == "Ren, Beard and Kingston 2005" and reg.errata
    study = reg.study("kalman-consensus")
    assert study.chapter == "ren2005_kalman_consensus" and study.settings is ren.SETTINGS
    numbers = {f.name: f.number for f in study.figures}
    assert numbers == {"fig1": "Fig. 1", "average": "", "fig2_fig3": "Figs. 2-3",
                       "theorems": "Theorems 3.2 and 3.9 (our check)", "noise": "",
                       "noise_continuous": "", "bias": "", "overconfidence": ""}
    assert all("look for" in f.caption.lower() for f in study.figures if f.number.startswith("Fig"))
    claims = study.claims(cheap_result)
    assert len(claims) == 9 and all(c.rule and c.paper_value is None for c in claims)
    assert all(len(c.value) <= 6 for c in claims), "the ledger shows at most six labelled values per claim"
    for spec in study.tables:
        table = study.build(spec.name, cheap_result)
        assert len(table) > 0 and table.notna().all().all(), spec.name


@pytest.mark.parametrize("name", [f.name for f in ren.STUDY.figures])
def test_every_registered_figure_draws_with_labelled_axes(cheap_result, name):
    fig = ren.STUDY.draw(name, cheap_result)
    try:
        assert isinstance(fig, matplotlib.figure.Figure)
        visible = [ax for ax in fig.axes if ax.axison]
        if visible:  # graph drawings (Figs. 2-3) have no axes, only titles
            assert any(ax.get_xlabel() for ax in visible) and any(ax.get_ylabel() for ax in visible)
        assert all(ax.get_title() or ax.get_xlabel() or ax.get_ylabel() for ax in fig.axes)
    finally:
        matplotlib.pyplot.close(fig)


def test_run_reuses_the_fig1_pairings_and_the_bias_runs(cheap_result):
    r = cheap_result
    assert r.fig1.pairings.shape == (CHEAP.n_steps, 10, 10)
    assert r.bias["paper"]["values"].shape == (CHEAP.bias_runs,)
    assert set(r.noise) == {"paper", "small_Omega", "Q0"} and r.noise["small_Omega"]["Omega"] == CHEAP.noise_Omega_small
    again = ren.overconfidence(3, CHEAP)  # same seed: same pairings as the run's Fig. 1
    np.testing.assert_array_equal(again["variants"]["paper"]["actual"],
                                  r.overconfidence["variants"]["paper"]["actual"])


@pytest.mark.slow
def test_reproduce_writes_figures_tables_and_claims(published):
    """The published results (results/ren2005, seed 1); the chapter's run and claims give the same ledger."""
    out, claims = published("ren2005")
    for spec in ren.STUDY.figures:
        assert (out / "figures" / f"{spec.name}.png").stat().st_size > 0
    for spec in ren.STUDY.tables:
        assert (out / "tables" / f"{spec.name}.csv").exists()
    doc = json.loads((out / "claims.json").read_text())
    assert doc["seed"] == 1
    ids = {c["id"] for c in doc["claims"]}
    required = {"fig1-consensus-equal", "fig1-confident-agent-dominates", "fig2-fig3-graphs",
                "thm32-continuous-consensus",
                "thm39-switching-union-consensus", "no-spanning-tree-no-consensus", "noise-consensus-approximate",
                "beyond-fusion-bias", "beyond-overconfidence"}
    assert ids == {f"ren2005/{r}" for r in required}
    verdicts = {c.id: c.verdict for c in claims}
    assert all(v == "holds" for v in verdicts.values()), verdicts
    # the chapter shows the same ledger: run + claims with the same seed
    assert [c.to_dict() for c in ren.STUDY.claims(ren.run(ren.SETTINGS, 1))] == \
        [{k: v for k, v in c.items() if k != "study"} for c in doc["claims"]]


# --------------------------------------------------------------------------- bad input (issue 14)

_FIG1_SMALL = None


def _small_fig1():
    global _FIG1_SMALL
    if _FIG1_SMALL is None:
        _FIG1_SMALL = ren.fig1(seed=1, settings=dataclasses.replace(ren.SETTINGS, n_steps=5))
    return _FIG1_SMALL


_OC_STUDY = {"variants": {"paper": {"actual": np.ones((3, 10)), "believed": np.ones((3, 10)), "label": "x"}},
             "fused_variance": 0.1}
_T = np.arange(6.0)
_SPREAD = np.exp(-_T)
_BAD_INPUT = [
    (lambda: ren.fig1(seed=-1), "seed"),
    (lambda: ren.run(CHEAP, seed=-1), "seed"),
    (lambda: ren.overconfidence(seed=-1), "seed"),
    (lambda: ren.noise_study(seed=-1, settings=CHEAP), "seed"),
    (lambda: ren.noise_study(n_runs=0, settings=CHEAP), "n_runs"),
    (lambda: ren.noise_study(n_runs=-2, settings=CHEAP), "n_runs"),
    (lambda: ren.noise_study(n_runs=2.0, settings=CHEAP), "n_runs"),
    (lambda: ren.noise_study(n_runs="2", settings=CHEAP), "n_runs"),
    (lambda: ren.noise_study(n_steps=3, settings=CHEAP), "n_steps"),
    (lambda: ren.bias_study(seed=-1, settings=CHEAP), "seed"),
    (lambda: ren.bias_study(n_runs=0, settings=CHEAP), "n_runs"),
    (lambda: ren.bias_study(n_runs=1, settings=CHEAP), "n_runs"),
    (lambda: ren.bias_study(n_runs=4.0, settings=CHEAP), "n_runs"),
    (lambda: ren.bias_study(n_runs="4", settings=CHEAP), "n_runs"),
    (lambda: ren.bias_study(n_steps=0, settings=CHEAP), "n_steps"),
    (lambda: ren.decay_rate([0.0, np.nan, 2.0, 3.0], _SPREAD[:4]), "t"),
    (lambda: ren.decay_rate(_T, np.where(_T == 3, np.nan, _SPREAD)), "spread"),
    (lambda: ren.decay_rate(_T, np.where(_T == 3, np.inf, _SPREAD)), "spread"),
    (lambda: ren.decay_rate(_T, "abc"), "spread"),
    (lambda: ren.decay_rate(_T, _SPREAD[:4]), "spread"),
    (lambda: ren.decay_rate(_T, -_SPREAD), "spread"),
    (lambda: ren.decay_rate(_T[:2], _SPREAD[:2]), "t"),
    (lambda: ren.plot_directed(np.where(np.eye(6) > 0, 0.0, np.nan), ren.FIG3_LAYOUT), "A"),
    (lambda: ren.plot_directed("abc", ren.FIG3_LAYOUT), "A"),
    (lambda: ren.plot_directed(ren.fig2_graph()[:5], ren.FIG3_LAYOUT), "A"),
    (lambda: ren.plot_directed(-ren.fig2_graph(), ren.FIG3_LAYOUT), "A"),
    (lambda: ren.plot_directed(ren.fig2_graph(), np.where(ren.FIG3_LAYOUT > 1, np.nan, 0.0)), "layout"),
    (lambda: ren.plot_directed(ren.fig2_graph(), np.full((6, 2), np.inf)), "layout"),
    (lambda: ren.plot_directed(ren.fig2_graph(), "abc"), "layout"),
    (lambda: ren.plot_directed(ren.fig2_graph(), ren.FIG3_LAYOUT[:4]), "layout"),
    (lambda: ren.plot_directed(ren.fig2_graph(), ren.FIG3_LAYOUT, highlight=[(0, 9)]), "highlight"),
    (lambda: ren.plot_fig1(_small_fig1(), confident_agent=0), "confident_agent"),
    (lambda: ren.plot_fig1(_small_fig1(), confident_agent=-1), "confident_agent"),
    (lambda: ren.plot_fig1(_small_fig1(), confident_agent=7.0), "confident_agent"),
    (lambda: ren.plot_fig1(_small_fig1(), confident_agent="7"), "confident_agent"),
    (lambda: ren.plot_fig1(_small_fig1(), confident_agent=11), "confident_agent"),
    (lambda: ren.plot_overconfidence(_OC_STUDY, confident_agent=0), "confident_agent"),
    (lambda: ren.plot_overconfidence(_OC_STUDY, confident_agent=-3), "confident_agent"),
    (lambda: ren.plot_overconfidence(_OC_STUDY, confident_agent=7.0), "confident_agent"),
    (lambda: ren.plot_overconfidence(_OC_STUDY, confident_agent="7"), "confident_agent"),
    (lambda: ren.switching_demo("abc", CHEAP), "graphs"),
    (lambda: ren.switching_demo(ren.union_sequence()[:, :5, :5], CHEAP), "graphs"),
    (lambda: ren.switching_demo(ren.fig2_graph(), CHEAP), "graphs"),
    (lambda: ren.switching_demo(-ren.union_sequence(), CHEAP), "graphs"),
    (lambda: ren.variant_label(np.nan, 0.1), "Q"),
    (lambda: ren.variant_label(np.inf, 0.1), "Q"),
    (lambda: ren.variant_label(-0.1, 0.1), "Q"),
    (lambda: ren.variant_label("0.1", 0.1), "Q"),
    (lambda: ren.variant_label(0.1, np.nan), "Omega"),
    (lambda: ren.variant_label(0.1, np.inf), "Omega"),
    (lambda: ren.variant_label(0.1, -1.0), "Omega"),
    (lambda: ren.variant_label(0.1, "0.1"), "Omega"),
]


@pytest.mark.parametrize("call, name", _BAD_INPUT, ids=[f"{i}-{n}" for i, (_, n) in enumerate(_BAD_INPUT)])
def test_bad_input_names_the_argument(call, name):
    import matplotlib.pyplot as plt
    try:
        with pytest.raises((ValueError, TypeError), match=rf"\b{name}\b"):
            call()
    finally:
        plt.close("all")


def test_checked_functions_accept_their_valid_inputs():
    import matplotlib.pyplot as plt
    assert ren.variant_label(0, 0.0) == "Q = 0, Ω = 0"
    assert ren.decay_rate(list(_T), list(_SPREAD)) == pytest.approx(-1.0)
    ax = ren.plot_directed(np.zeros((6, 6)), ren.FIG3_LAYOUT.tolist(), highlight=np.array([[0, 1]]))
    assert ax is not None
    assert ren.bias_study(n_runs=2, n_steps=5, settings=CHEAP)["values"].shape == (2,)
    plt.close("all")
