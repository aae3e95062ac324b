"""Tests of the Ren, Beard and Kingston (2005) scenarios (mascore.papers.ren2005)."""

import json

import numpy as np
import pytest

from mascore import consensus as cs
from mascore.graphs import has_spanning_tree, is_connected, spanning_tree_roots
from mascore.papers import ren2005 as ren
from mascore.reproduce import reproduce_paper


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
    assert res.pairings.shape == (ren.FIG1["n_steps"], 10, 10)
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
        assert v["actual"].shape == v["believed"].shape == (ren.FIG1["n_steps"] + 1, 10)
        assert np.all(v["actual"] >= st["fused_variance"] * (1 - 1e-9))  # nothing beats central fusion
    np.testing.assert_allclose(paper["believed"][-1], 0.05, rtol=1e-6)  # fixed point of eq. (4) on pairings
    assert np.all(paper["actual"][-1] > paper["believed"][-1])
    assert np.all(ideal["believed"][-1] < 1e-3 * ideal["actual"][-1])


@pytest.mark.slow
def test_reproduce_writes_figures_tables_and_claims(tmp_path):
    claims = reproduce_paper("ren2005", tmp_path, seed=1)
    out = tmp_path / "ren2005"
    for name in ("fig1.png", "fig2_fig3.png", "theorems.png", "bias.png", "overconfidence.png"):
        assert (out / "figures" / name).stat().st_size > 0
    for name in ("fig1_final.csv", "theorems.csv", "bias.csv"):
        assert (out / "tables" / name).exists()
    doc = json.loads((out / "claims.json").read_text())
    ids = {c["id"] for c in doc["claims"]}
    required = {"fig1-consensus-equal", "fig1-confident-agent-dominates", "thm32-continuous-consensus",
                "thm39-switching-union-consensus", "no-spanning-tree-no-consensus", "noise-consensus-approximate",
                "beyond-fusion-bias", "beyond-overconfidence"}
    assert {f"ren2005/{r}" for r in required} <= ids
    verdicts = {c.id: c.verdict for c in claims}
    assert all(verdicts[f"ren2005/{r}"] == "holds" for r in required), verdicts
