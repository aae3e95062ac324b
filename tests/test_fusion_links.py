"""Packet loss, one-step latency and send-on-delta messages on the target and localization tasks."""

import numpy as np
import pandas as pd
import pytest

from mascore import compare, fusion, fusion_links, graphs, sensor_network
from mascore.compare import grid
from mascore.compare.stats import NEES_DIMENSION, anees_bounds
from mascore.compare.target import LATENCY_METHODS, LINK_STUDIES, SEND_ON_DELTA_METHODS, _filter_links


def _cell(study, method, task="target", dropout=0.0, block=0):
    return {"study": study, "task": task, "method": method, "n_agents": 8, "graph": "ring", "noise": "gaussian",
            "dropout": dropout, "q_scale": 1.0, "block": block}


def test_lossy_graphs_symmetric_nested_seeded_and_at_the_rate():
    A = graphs.ring_graph(8)
    G1 = fusion_links.lossy_graphs(A, 0.1, 400, np.random.default_rng(5))
    G3 = fusion_links.lossy_graphs(A, 0.3, 400, np.random.default_rng(5))
    assert (G3 == G3.transpose(0, 2, 1)).all()                   # a lost exchange is lost both ways
    assert not (G3 > A).any() and not (G1 > A).any()             # only the graph's links, never a new one
    assert not ((G3 > 0) & (G1 == 0)).any()                      # nested: lost at 0.1, lost at 0.3
    links = 400 * 8                                              # undirected link-steps
    for p, G in ((0.1, G1), (0.3, G3)):
        lost = links - G.sum() / 2
        assert abs(lost - p * links) < 4 * np.sqrt(links * p * (1 - p))    # binomial, 4 sigma
    again = fusion_links.lossy_graphs(A, 0.3, 400, np.random.default_rng(5))
    assert again.tobytes() == G3.tobytes()
    assert fusion_links.lossy_graphs(A, 0.0, 10, 0).tobytes() == np.broadcast_to(A, (10, 8, 8)).tobytes()


def test_ideal_links_through_the_link_machinery_are_bit_identical_to_the_tables():
    """p = 0, latency 0: the per-step filters on the unchanged graph give the plain run's numbers bit for bit."""
    s = compare.SETTINGS
    for task in ("target", "localization"):
        model = (compare.target_model if task == "target" else compare.localization_model)(8, "ring", s)
        n = model.n_states
        _, z = model.simulate(np.zeros(n), s.p0 * np.eye(n), 60, np.random.default_rng(1), n_runs=4)
        G = fusion_links.lossy_graphs(model.adjacency, 0.0, 60, 0)
        for method in ("forwarding", "ci-L5", "icf-L1", "diffusion"):
            x, P, _, sent = _filter_links(method, model, task, G, z, s.p0 * np.eye(n), 0, None)
            xr, Pr = compare.target_filter(method, model, task).run(np.zeros(n), s.p0 * np.eye(n), z)
            assert sent is None and x.tobytes() == xr.tobytes() and P.tobytes() == Pr.tobytes()
    # and the grid's own target cells still run without links
    plain = compare.simulate_target("ci-L1", 8, 3, runs=10)
    again = compare.simulate_target("ci-L1", 8, 3, runs=10, loss=0.0, latency=0, send_delta=None)
    assert plain["rmse_own"].tobytes() == again["rmse_own"].tobytes()


def test_track_messages_on_ideal_links_is_the_filter():
    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), np.eye(4), 80, rng=2, n_runs=6)
    for filt in (fusion.ConsensusOnInformationFilter(model, 1), fusion.InformationConsensusFilter(model, 1)):
        xr, Pr = filt.run(np.zeros(4), np.eye(4), z)
        x, P, sent = fusion_links.track_messages([filt] * 80, np.zeros(4), np.eye(4), z)
        np.testing.assert_allclose(x, xr, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(P, np.broadcast_to(Pr, P.shape), rtol=1e-9, atol=1e-12)
        assert sent.all()
        # delta = 0: every agent sends at every step, so the estimates are the plain filter's
        x0, P0, sent0 = fusion_links.track_messages([filt] * 80, np.zeros(4), np.eye(4), z, send_delta=0.0)
        assert sent0.all()
        np.testing.assert_allclose(x0, xr, rtol=1e-9, atol=1e-9)


def test_latency_first_step_fuses_nothing_received():
    """With latency nothing has arrived at the first step: each agent's estimate is its own local filter's."""
    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), np.eye(4), 3, rng=4, n_runs=2)
    ci = fusion.ConsensusOnInformationFilter(model, 1)
    x, P, _ = fusion_links.track_messages([ci] * 3, np.zeros(4), np.eye(4), z, latency=1)
    local = fusion.ConsensusOnInformationFilter(model, 0)
    xl, Pl = local.update(*local.predict(np.zeros((8, 4)), np.broadcast_to(np.eye(4), (8, 4, 4))), z[0])
    np.testing.assert_allclose(x[0], xl, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P[0], Pl, rtol=1e-12, atol=1e-12)
    assert not np.allclose(x[1], ci.update(*ci.predict(x[0], P[0]), z[1])[0])   # late pairs differ from fresh ones


@pytest.mark.parametrize("delta", [0.0, 1.0])
@pytest.mark.parametrize("method", ["ci-L1", "icf-L1"])
def test_send_on_delta_floats_as_sent(method, delta):
    m = compare.simulate_target(method, 8, 7, runs=10, send_delta=delta)
    plain_floats = compare.target_cost(method, 8, 2)[0]
    if delta == 0.0:  # every agent sends at every step: the plain method's floats, and its estimates
        assert (m["floats"] == plain_floats).all()
        plain = compare.simulate_target(method, 8, 7, runs=10)
        np.testing.assert_allclose(m["rmse_own"], plain["rmse_own"], rtol=1e-9)
    else:
        assert (m["floats"] < plain_floats).all() and (m["floats"] > 0).all()


def test_loss_and_latency_cells_seeded_and_scored_with_the_existing_statistics():
    """Loss from the cell's seed, byte for byte; ANEES with its chi-square bounds; the exact filters stay consistent.

    Forwarding under loss and under latency is still a Kalman filter (on the measurements that
    arrived, and one step behind on the neighbours'), and CI's convex combination of consistent
    densities is consistent whatever arrives: their ANEES must not exceed the upper bound.
    """
    rows = []
    for study, p, methods in (("loss", 0.3, ["centralized", "forwarding", "ci-L1", "icf-L1"]),
                              ("latency", 0.1, ["centralized", "forwarding", "ci-L1"])):
        for method in methods:
            cell = _cell(study, method, dropout=p)
            out = grid.run_cell(cell)
            rows += [{**r, **cell, "cell": f"{study}-{method}"} for r in out]
    again = grid.run_cell(_cell("loss", "ci-L1", dropout=0.3))
    assert [r["rmse_own"] for r in again] == [r["rmse_own"] for r in rows if r["cell"] == "loss-ci-L1"]
    s = grid.summarize(pd.DataFrame(rows)).set_index(["study", "method"])
    lo, hi = anees_bounds(50, NEES_DIMENSION["target"])
    assert np.allclose(s["nees_bound_lo"], lo) and np.allclose(s["nees_bound_hi"], hi)
    for key in [("loss", "forwarding"), ("latency", "forwarding"), ("loss", "centralized")]:
        assert lo <= s.loc[key, "nees_own_mean"] <= hi, key
    for key in [("loss", "ci-L1"), ("latency", "ci-L1")]:
        assert s.loc[key, "nees_own_mean"] <= hi, key
    assert (s["ratio_lo"] <= s["ratio_mean"]).all() and (s.loc[("loss", "centralized"), "ratio_mean"] == 1.0)
    # loss and latency cost accuracy: worse than on ideal links, on the same seeds
    ideal = compare.simulate_target("ci-L1", 8, grid.cell_seed(_cell("loss", "ci-L1"), compare.SEED_AXES, 0))
    assert s.loc[("loss", "ci-L1"), "rmse_own_mean"] > ideal["rmse_own"].mean()


def test_link_studies_in_the_grids():
    quick, full = grid.grid_cells("quick"), grid.grid_cells("full")
    q = [c for c in quick if c["study"] in LINK_STUDIES]
    f = [c for c in full if c["study"] in LINK_STUDIES]
    assert {c["task"] for c in q} == {"target"} and {c["task"] for c in f} == {"target", "localization"}
    assert {c["dropout"] for c in f if c["study"] == "loss"} == {0.1, 0.3}
    assert all(c["method"] in LATENCY_METHODS for c in f if c["study"] == "latency")
    assert all(c["method"] in SEND_ON_DELTA_METHODS for c in f if c["study"].startswith("send-on-delta"))
    assert all(c["n_agents"] == 8 and c["graph"] == "ring" for c in f)
    for c in f:  # every cell has its bound in its group (the ratio's reference)
        assert any(b["method"] == "centralized" and all(b[k] == c[k] for k in ("study", "task", "dropout", "block"))
                   for b in f)


def test_bad_link_arguments_are_named():
    with pytest.raises(ValueError, match="loss"):
        compare.simulate_target("ci-L1", 8, 0, runs=2, loss=1.0)
    with pytest.raises(ValueError, match="latency"):
        compare.simulate_target("ci-L1", 8, 0, runs=2, latency=2)
    with pytest.raises(ValueError, match="not modelled on the switching localization"):
        compare.simulate_target("kcf", 8, 0, runs=2, latency=1, graph="switching", task="localization")
    with pytest.raises(ValueError, match="send_delta: method"):
        compare.simulate_target("ci-L5", 8, 0, runs=2, send_delta=1.0)
    with pytest.raises(ValueError, match="send_delta must be"):
        compare.simulate_target("ci-L1", 8, 0, runs=2, send_delta=float("nan"))
    with pytest.raises(ValueError, match="send_delta needs a fixed graph"):
        compare.simulate_target("ci-L1", 8, 0, runs=2, send_delta=1.0, loss=0.1)
    model = compare.target_model(8)
    with pytest.raises(ValueError, match="one density"):
        fusion_links.track_messages([fusion.ConsensusOnInformationFilter(model, 2)], np.zeros(4), np.eye(4),
                                    np.zeros((1, 8)), send_delta=1.0)
    with pytest.raises(ValueError, match="one density"):
        fusion_links.track_messages([fusion.ConsensusOnInformationFilter(model, 1, "N")], np.zeros(4), np.eye(4),
                                    np.zeros((1, 8)), delivered=np.ones((1, 8, 8)))
    with pytest.raises(ValueError, match="same rounds"):
        fusion_links.track_messages([fusion.ConsensusOnInformationFilter(model, 1),
                                     fusion.ConsensusOnInformationFilter(model, 2)], np.zeros(4), np.eye(4),
                                    np.zeros((2, 8)), latency=1)
    with pytest.raises(ValueError, match="ConsensusOnInformationFilter"):
        fusion_links.track_messages([fusion.DiffusionKalmanFilter(model)], np.zeros(4), np.eye(4), np.zeros((1, 8)))
    with pytest.raises(ValueError, match="per-agent"):
        fusion_links.track_behind([fusion.CentralizedFilter(model)], np.zeros(4), np.eye(4), np.zeros((1, 8)))
    singular = sensor_network.SensorNetworkModel(np.zeros((4, 4)), np.eye(4), model.H, model.R, model.adjacency)
    with pytest.raises(ValueError, match="invertible F"):
        fusion_links.track_messages([fusion.ConsensusOnInformationFilter(singular, 1, "N")], np.zeros(4), np.eye(4),
                                    np.zeros((1, 8)), latency=1)
    with pytest.raises(ValueError, match="send_delta must be"):
        fusion_links.track_messages([fusion.ConsensusOnInformationFilter(model, 1)], np.zeros(4), np.eye(4),
                                    np.zeros((1, 8)), send_delta=-1.0)
    with pytest.raises(ValueError, match="loss must be"):
        fusion_links.lossy_graphs(graphs.ring_graph(4), -0.1, 3, 0)


def test_a_lost_link_is_an_absent_edge_with_the_weights_renormalized_over_what_arrived():
    """The step's CI weights are the Metropolis weights of the delivered graph: zero on lost links, rows of one."""
    from mascore import sensor_network

    model = compare.target_model(8)
    G = fusion_links.lossy_graphs(model.adjacency, 0.3, 50, 9)
    k = int(np.argmax(G.sum(axis=(1, 2)) < model.adjacency.sum()))          # a step that lost a link
    step = compare.target_filter("ci-L1", sensor_network.SensorNetworkModel(model.F, model.Q, model.H, model.R, G[k]))
    W = step.round_weights
    lost = (model.adjacency > 0) & (G[k] == 0)
    assert lost.any() and (W[lost] == 0).all() and np.allclose(W.sum(1), 1) and np.allclose(W, W.T)
    degree = (G[k] > 0).sum(1)
    i, j = np.argwhere(G[k] > 0)[0]
    assert W[i, j] == pytest.approx(1 / (1 + max(degree[i], degree[j])))       # Xiao, Boyd and Lall's rule


def test_lossy_graphs_per_direction_independent_nested_per_run_and_at_the_rate():
    """Each message j -> i is lost alone with probability p: a binomial count, both directions lost together p^2."""
    A = graphs.ring_graph(8)
    K, R = 200, 6
    D1 = fusion_links.lossy_graphs(A, 0.1, K, np.random.default_rng(3), per_direction=True, n_runs=R)
    D3 = fusion_links.lossy_graphs(A, 0.3, K, np.random.default_rng(3), per_direction=True, n_runs=R)
    assert D3.shape == (K, R, 8, 8) and not (D3 > A).any()       # only the graph's links, never a new one
    assert not ((D3 > 0) & (D1 == 0)).any()                      # nested in p
    messages = K * R * 16                                        # directed link-steps of the runs
    for p, D in ((0.1, D1), (0.3, D3)):
        lost = (A > 0) & (D == 0)
        assert abs(lost.sum() - p * messages) < 4 * np.sqrt(messages * p * (1 - p))     # binomial, 4 sigma
        both = (lost & np.swapaxes(lost, -1, -2)).sum() / 2                             # i->j and j->i lost
        pairs = messages / 2
        assert abs(both - p * p * pairs) < 4 * np.sqrt(pairs * p * p * (1 - p * p))    # independent directions
    assert not (D3 == np.swapaxes(D3, -1, -2)).all()             # not symmetric
    assert not (D3[:, 0] == D3[:, 1]).all()                      # one pattern per run
    again = fusion_links.lossy_graphs(A, 0.3, K, np.random.default_rng(3), per_direction=True, n_runs=R)
    assert again.tobytes() == D3.tobytes()
    assert fusion_links.lossy_graphs(A, 0.0, 5, 0, per_direction=True, n_runs=2).tobytes() \
        == np.broadcast_to(A, (5, 2, 8, 8)).tobytes()


def test_delivered_weights_keep_rows_convex_and_give_the_lost_weight_to_the_receiver():
    model = compare.target_model(8)
    W = fusion.ConsensusOnInformationFilter(model, 1).round_weights
    D = fusion_links.lossy_graphs(model.adjacency, 0.5, 3, 1, per_direction=True, n_runs=4)
    Wd = fusion_links.delivered_weights(W, D)
    assert Wd.shape == (3, 4, 8, 8) and np.allclose(Wd.sum(-1), 1.0) and (Wd >= 0).all()
    lost = (model.adjacency > 0) & (D == 0)
    assert lost.any() and (Wd[lost] == 0).all()
    kept = (D > 0)
    assert (Wd[kept] == np.broadcast_to(W, D.shape)[kept]).all()
    np.testing.assert_allclose(np.diagonal(Wd, axis1=-2, axis2=-1) - np.diag(W),
                               np.where(lost, W, 0.0).sum(-1))   # the lost weight, on the receiver's own pair
    np.testing.assert_allclose(fusion_links.delivered_weights(W, model.adjacency), W, rtol=0, atol=1e-15)


def test_per_direction_loss_zero_is_ideal_links_and_the_kernels_are_the_filters():
    """p = 0: the cells bit for bit; every message delivered: the masked kernels give the filters' own runs."""
    for method in ("forwarding", "ci-L1", "icf-L1"):
        plain = compare.simulate_target(method, 8, 3, runs=10)
        zero = compare.simulate_target(method, 8, 3, runs=10, loss=0.0, loss_model="direction")
        assert all(plain[k].tobytes() == zero[k].tobytes() for k in ("rmse_own", "nees_own"))
    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), np.eye(4), 60, rng=2, n_runs=5)
    every = np.broadcast_to(model.adjacency, (60, 5, 8, 8))
    xr, Pr = fusion.MeasurementForwardingFilter(model).run(np.zeros(4), np.eye(4), z)
    x, P = fusion_links.track_forwarding(model, np.zeros(4), np.eye(4), z, every)
    np.testing.assert_allclose(x, xr, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(P, np.broadcast_to(Pr[:, None], P.shape), rtol=1e-10, atol=1e-14)
    for filt in (fusion.ConsensusOnInformationFilter(model, 1), fusion.InformationConsensusFilter(model, 1)):
        for latency in (0, 1):
            xr, Pr, _ = fusion_links.track_messages([filt] * 60, np.zeros(4), np.eye(4), z, latency=latency)
            x, P, _ = fusion_links.track_messages([filt] * 60, np.zeros(4), np.eye(4), z, latency=latency,
                                                  delivered=every)
            np.testing.assert_allclose(x, xr, rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(P, np.broadcast_to(Pr if Pr.ndim == P.ndim else Pr[:, None], P.shape),
                                       rtol=1e-10, atol=1e-14)


def test_track_forwarding_on_symmetric_losses_is_forwarding_on_the_step_graphs():
    """Two computations: the masked kernel on a symmetric pattern, and the method's own filter of each step's graph."""
    s = compare.SETTINGS
    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), s.p0 * np.eye(4), 80, np.random.default_rng(6), n_runs=4)
    G = fusion_links.lossy_graphs(model.adjacency, 0.3, 80, 8)
    for latency in (0, 1):
        x, P, _, _ = _filter_links("forwarding", model, "target", G, z, s.p0 * np.eye(4), latency, None)
        xm, Pm = fusion_links.track_forwarding(model, np.zeros(4), s.p0 * np.eye(4), z, G, latency=latency)
        np.testing.assert_allclose(xm, x, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(Pm, np.broadcast_to(P if P.ndim == Pm.ndim else P[:, None], Pm.shape),
                                   rtol=1e-9, atol=1e-12)


def test_forwarding_under_one_way_loss_stays_consistent():
    """A Kalman filter on the measurements that arrived: its ANEES inside the chi-square bounds of its runs."""
    m = compare.simulate_target("forwarding", 8, 11, runs=100, loss=0.3, loss_model="direction")
    lo, hi = anees_bounds(100, NEES_DIMENSION["target"])
    assert lo <= m["nees_own"].mean() <= hi
    both = compare.simulate_target("forwarding", 8, 11, runs=100, loss=0.3)
    assert not np.array_equal(m["rmse_own"], both["rmse_own"])   # another loss pattern, the same data


def test_bad_per_direction_arguments_are_named():
    with pytest.raises(ValueError, match="loss_model must be"):
        compare.simulate_target("ci-L1", 8, 0, runs=2, loss=0.1, loss_model="both")
    with pytest.raises(ValueError, match="loss_model='direction': method"):
        compare.simulate_target("ci-L5", 8, 0, runs=2, loss=0.1, loss_model="direction")
    with pytest.raises(ValueError, match="send_delta needs a fixed graph"):
        compare.simulate_target("ci-L1", 8, 0, runs=2, loss=0.1, send_delta=1.0)   # both directions: not modelled
    model = compare.target_model(8)
    with pytest.raises(ValueError, match="delivered must be"):
        fusion_links.track_messages([fusion.ConsensusOnInformationFilter(model, 1)], np.zeros(4), np.eye(4),
                                    np.zeros((1, 8)), delivered=np.ones((2, 8, 8)))
    with pytest.raises(ValueError, match="delivered must be"):
        fusion_links.track_forwarding(model, np.zeros(4), np.eye(4), np.zeros((1, 8)), np.ones((1, 7, 7)))
    with pytest.raises(ValueError, match="n_runs"):
        fusion_links.lossy_graphs(graphs.ring_graph(4), 0.1, 3, 0, per_direction=True, n_runs=0)


def test_link_claims_are_decided_on_blocks_they_were_not_written_from():
    """A link claim names blocks 0-1 as written from; with blocks 2-3 in the table it reads those only."""
    import dataclasses

    few = dataclasses.replace(compare.SETTINGS, runs=4, n_steps=60, steady_from=20)
    cells = [(study, m, p) for study, p in (("latency", 0.0), ("loss", 0.3))
             for m in ("centralized", "forwarding", "ci-L1", "icf-L1")]   # the data of links-latency-costs-more
    rows = []
    for block in range(4):
        for study, method, p in cells:
            cell = _cell(study, method, dropout=p, block=block)
            rows += [{**r, **cell, "cell": str(sorted(cell.items()))} for r in grid.run_cell(cell, settings=few)]
    table = pd.DataFrame(rows)
    phi = {"Phi = 1": 1.0, "Phi = 2": 1.0}
    key = "compare/links-latency-costs-more"
    held = {c.id: c for c in compare.compare_claims(table, phi=phi)}[key]
    assert held.written_from == "seed blocks 0-1" and held.decided_on == "seed blocks 2-3 (held out)"
    written = {c.id: c for c in compare.compare_claims(table[table["block"] < 2], phi=phi)}[key]
    assert written.decided_on.startswith("seed blocks 0-1")            # no held-out block: it says so
    assert written.value != held.value                                 # and the held-out runs were what decided it
    only_held = {c.id: c for c in compare.compare_claims(table[table["block"] >= 2], phi=phi)}[key]
    assert only_held.value == held.value                               # blocks 0-1 took no part


def test_send_on_delta_over_one_way_loss():
    """Every message delivered: the copies of each receiver are the sender's last send, so the plain send-on-delta
    numbers; with loss the sends are counted as sent and the receivers fuse what they hold."""
    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), np.eye(4), 80, rng=2, n_runs=5)
    every = np.broadcast_to(model.adjacency, (80, 5, 8, 8))
    for filt in (fusion.ConsensusOnInformationFilter(model, 1), fusion.InformationConsensusFilter(model, 1)):
        xr, Pr, sr = fusion_links.track_messages([filt] * 80, np.zeros(4), np.eye(4), z, send_delta=0.7)
        x, P, s = fusion_links.track_messages([filt] * 80, np.zeros(4), np.eye(4), z, send_delta=0.7, delivered=every)
        assert (s == sr).all() and 0 < s.mean() < 1
        np.testing.assert_allclose(x, xr, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(P, Pr, rtol=1e-12, atol=1e-14)
    lossy = compare.simulate_target("ci-L1", 8, 4, runs=20, loss=0.3, loss_model="direction", send_delta=0.5)
    clean = compare.simulate_target("ci-L1", 8, 4, runs=20, send_delta=0.5)
    assert (lossy["floats"] > 0).all() and (lossy["floats"] < compare.target_cost("ci-L1", 8, 2)[0]).all()
    assert not np.array_equal(lossy["rmse_own"], clean["rmse_own"])
    lo, hi = anees_bounds(20, NEES_DIMENSION["target"])
    assert lossy["nees_own"].mean() < hi                  # CI fuses consistent (predicted) densities: never overconfident
    with pytest.raises(ValueError, match="send_delta needs a fixed graph"):  # the link model changes the graph
        compare.simulate_target("ci-L1", 8, 0, runs=2, loss=0.1, send_delta=0.5, latency=1)


# --------------------------------------------------------------------------------------------
# latency for every fusion method (consensus on pairs, rounds pipelined; forwarded measurements, behind)

def _late_reference(model, kind, L, w, z, x0, P0):
    """Late consensus on pairs, agent by agent, from the module's text: round l fuses the own pairs after round
    l - 1 with the neighbours' pairs after round l - 1 of the step before, predicted one step (a density
    through F, Q; a measurement's information by Woodbury, Q invertible); nothing arrives at the first step."""
    F, Q, W, N, n = model.F, model.Q, model.weights, model.n_agents, model.n_states
    if kind == "icf":
        W = fusion.InformationConsensusFilter(model, L).round_weights
    Fi = np.linalg.inv(F)
    infos = [model.H[i].T @ np.linalg.inv(model.R[i]) @ model.H[i] for i in range(N)]

    def late(pair, scale):
        Om, q = pair
        if scale is None:  # information of the next state: M - M (Q^-1 + M)^-1 M
            M = Fi.T @ Om @ Fi
            G = np.eye(n) - M @ np.linalg.inv(np.linalg.inv(Q) + M)
            return G @ M, G @ Fi.T @ q
        C = np.linalg.inv(scale * Om)
        m = C @ q * scale
        C = F @ C @ F.T + Q
        return np.linalg.inv(C) / scale, np.linalg.inv(C) @ (F @ m) / scale

    scales = {"ci": (1.0,), "hcmci": (1.0, None), "icf": (float(N),)}[kind]
    x, P = [x0.copy() for _ in range(N)], [P0.copy() for _ in range(N)]
    before, out = None, []
    for k in range(len(z)):
        pairs = []
        for i in range(N):
            xp, Pp = F @ x[i], F @ P[i] @ F.T + Q
            J = np.linalg.inv(Pp)
            zi = z[k][model._slices[i]]
            iv = model.H[i].T @ np.linalg.solve(model.R[i], zi)
            pairs.append({"ci": [(J + infos[i], J @ xp + iv)], "hcmci": [(J, J @ xp), (infos[i], iv)],
                          "icf": [(J / N + infos[i], J @ xp / N + iv)]}[kind])
        sent = []
        for r in range(L):
            sent.append(pairs)
            if before is not None:
                pairs = [[(W[i, i] * pairs[i][p][0] + sum(W[i, j] * late(before[r][j][p], scales[p])[0]
                                                          for j in range(N) if j != i and W[i, j]),
                           W[i, i] * pairs[i][p][1] + sum(W[i, j] * late(before[r][j][p], scales[p])[1]
                                                          for j in range(N) if j != i and W[i, j]))
                          for p in range(len(scales))] for i in range(N)]
        before = sent
        for i in range(N):
            if kind == "hcmci":
                Om, q = pairs[i][0][0] + w * pairs[i][1][0], pairs[i][0][1] + w * pairs[i][1][1]
            else:
                Om, q = pairs[i][0]
            P[i] = np.linalg.inv(Om) / (N if kind == "icf" else 1)
            x[i] = np.linalg.solve(Om, q)
        out.append((np.stack(x), np.stack(P)))
    return np.stack([o[0] for o in out]), np.stack([o[1] for o in out])


@pytest.mark.parametrize("kind, L", [("ci", 2), ("hcmci", 1), ("hcmci", 2), ("icf", 2)])
def test_late_rounds_fuse_the_pairs_sent_the_step_before_predicted(kind, L):
    """An independent agent-by-agent computation of the pipelined late rounds gives the same numbers."""
    model = compare.target_model(4)
    _, z = model.simulate(np.zeros(4), np.eye(4), 6, rng=11)
    filt = {"ci": fusion.ConsensusOnInformationFilter(model, L), "icf": fusion.InformationConsensusFilter(model, L),
            "hcmci": fusion.ConsensusOnInformationFilter(model, L, novelty_weight="N")}[kind]
    x, P, sent = fusion_links.track_messages([filt] * 6, np.zeros(4), np.eye(4), z, latency=1)
    xr, Pr = _late_reference(model, kind, L, 4.0, z, np.zeros(4), np.eye(4))
    np.testing.assert_allclose(x, xr, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(P, Pr, rtol=1e-8, atol=1e-12)
    assert sent.all()


def test_a_late_measurement_information_is_the_measurement_of_the_next_state_with_the_process_noise():
    """HCMCI's late novelty pair: ``(I + M Q)^-1 M`` is ``H'^T R'^-1 H'``, ``H' = H F^-1``, ``R' = R + H' Q H'^T``."""
    model = compare.target_model(4)
    H, R = model.H[0], model.R[0]
    z = np.array([0.7])
    Om, q = fusion_links._predict_information(model, H.T @ np.linalg.solve(R, H), H.T @ np.linalg.solve(R, z))
    Hp = H @ np.linalg.inv(model.F)
    Rp = R + Hp @ model.Q @ Hp.T
    np.testing.assert_allclose(Om, Hp.T @ np.linalg.solve(Rp, Hp), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(q, Hp.T @ np.linalg.solve(Rp, z), rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("L, w", [(5, 1.0), (1, "N"), (5, "N")])
def test_rounds_on_ideal_timing_are_the_filter(L, w):
    """Latency 0: L rounds applied one after the other are the filter's own update with W^L."""
    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), np.eye(4), 40, rng=3, n_runs=3)
    for filt in (fusion.ConsensusOnInformationFilter(model, L, novelty_weight=w), fusion.InformationConsensusFilter(model, L)):
        xr, Pr = filt.run(np.zeros(4), np.eye(4), z)
        x, P, _ = fusion_links.track_messages([filt] * 40, np.zeros(4), np.eye(4), z)
        np.testing.assert_allclose(x, xr, rtol=1e-8, atol=1e-9)
        np.testing.assert_allclose(P, Pr, rtol=1e-8, atol=1e-12)


def _behind_filters(model):
    from mascore.fusion_forwarding import KalmanConsensusNetworkFilter, SetMembershipForwardingFilter

    return {"forwarding": fusion.MeasurementForwardingFilter(model), "kcf": KalmanConsensusNetworkFilter(model),
            "diffusion": fusion.DiffusionKalmanFilter(model), "ci-diffusion": fusion.CovarianceIntersectionFilter(model),
            "sm-forwarding": SetMembershipForwardingFilter(model)}


@pytest.mark.parametrize("task", ["target", "localization"])
def test_behind_is_the_filter_of_d_steps_before_then_own_measurements(task):
    """The filter behind is the method's own filter, bit for bit, D = its exchanges steps before; then each agent's own
    update (Kalman; the set update for the set-membership filter) on its measurements of the last D steps."""
    model = (compare.target_model if task == "target" else compare.localization_model)(8)
    n = model.n_states
    _, z = model.simulate(np.zeros(n), np.eye(n), 12, rng=5, n_runs=2)
    for name, filt in _behind_filters(model).items():
        P0 = filt.initial_shape(np.eye(n)) if name == "sm-forwarding" else np.eye(n)
        x, P = fusion_links.track_behind([filt] * 12, np.zeros(n), P0, z)
        xr, Pr = filt.run(np.zeros(n), P0, z)
        own = (type(filt)(model.on_graph(np.zeros((8, 8))), filt.confidence) if name == "sm-forwarding"
               else fusion.ConsensusOnInformationFilter(model, 0))
        D = filt.exchanges
        assert D == (2 if "diffusion" in name else 1)
        for k in (0, D, 11):
            xo, Po = model.check_state(np.zeros(n), P0, per_agent=True) if k < D else (xr[k - D], Pr[k - D])
            for j in range(max(0, k - D + 1), k + 1):
                xo, Po = own.update(*own.predict(xo, Po), z[j])
            assert np.array_equal(x[k], np.broadcast_to(xo, x[k].shape)), (name, k)
            assert np.array_equal(P[k], Po), (name, k)
        assert np.all(np.linalg.eigvalsh(P) > 0), name


def test_late_kcf_at_eps_0_is_late_forwarding():
    from mascore.fusion_forwarding import KalmanConsensusNetworkFilter

    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), np.eye(4), 30, rng=8, n_runs=4)
    xf, Pf = fusion_links.track_behind([fusion.MeasurementForwardingFilter(model)] * 30, np.zeros(4), np.eye(4), z)
    xk, Pk = fusion_links.track_behind([KalmanConsensusNetworkFilter(model, eps=0.0)] * 30, np.zeros(4), np.eye(4), z)
    assert xk.tobytes() == xf.tobytes() and Pk.tobytes() == Pf.tobytes()


def test_every_method_late_has_positive_definite_covariances_and_ci_stays_consistent():
    """Every filter of the tables takes latency; CI at any number of rounds stays consistent (ANEES below the bound)."""
    lo, hi = anees_bounds(100, NEES_DIMENSION["target"])
    for method in ("ci-L1", "ci-L5"):
        assert compare.simulate_target(method, 8, 21, runs=100, latency=1)["nees_own"].mean() < hi, method
    book = {"centralized", "local", "forwarding", "ci-L1", "ci-L5", "hcmci-L1", "hcmci-L5", "icf-L1", "icf-L5",
            "diffusion", "ci-diffusion", "kcf", "sm-forwarding"}  # the methods of the book's tables: all modelled
    assert book <= set(LATENCY_METHODS) and not book & set(compare.LATENCY_NOT_MODELLED)
    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), np.eye(4), 60, rng=1, n_runs=2)
    for method in LATENCY_METHODS:
        if method in ("centralized", "local"):
            continue
        filt = compare.target_filter(method, model)
        if hasattr(filt, "message_pairs"):
            _, P, _ = fusion_links.track_messages([filt] * 60, np.zeros(4), np.eye(4), z, latency=1)
        else:
            P0 = filt.initial_shape(np.eye(4)) if hasattr(filt, "initial_shape") else np.eye(4)
            _, P = fusion_links.track_behind([filt] * 60, np.zeros(4), P0, z)
        assert np.all(np.linalg.eigvalsh(P) > 0), method


def test_send_on_delta_with_latency():
    """delta = 0 late is latency alone; every message delivered is no loss; a threshold sends fewer floats."""
    model = compare.target_model(8)
    _, z = model.simulate(np.zeros(4), np.eye(4), 80, rng=6, n_runs=5)
    for filt in (fusion.ConsensusOnInformationFilter(model, 1), fusion.InformationConsensusFilter(model, 1)):
        xl, Pl, _ = fusion_links.track_messages([filt] * 80, np.zeros(4), np.eye(4), z, latency=1)
        x0, P0, sent0 = fusion_links.track_messages([filt] * 80, np.zeros(4), np.eye(4), z, latency=1, send_delta=0.0)
        assert sent0.all()
        np.testing.assert_allclose(x0, xl, rtol=1e-9, atol=1e-10)
        x1, P1, sent1 = fusion_links.track_messages([filt] * 80, np.zeros(4), np.eye(4), z, latency=1, send_delta=1.0)
        assert 0 < sent1.mean() < 1
        every = np.ones((80, 8, 8))
        xd, Pd, sentd = fusion_links.track_messages([filt] * 80, np.zeros(4), np.eye(4), z, latency=1, send_delta=1.0,
                                                    delivered=every)
        assert np.array_equal(sentd, sent1)
        np.testing.assert_allclose(xd, x1, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(Pd, P1, rtol=1e-9, atol=1e-12)
    m = compare.simulate_target("ci-L1", 8, 7, runs=20, latency=1, send_delta=1.0)
    assert (m["floats"] < compare.target_cost("ci-L1", 8, 2)[0]).all()
    lossy = compare.simulate_target("ci-L1", 8, 7, runs=20, latency=1, send_delta=0.5, loss=0.3, loss_model="direction")
    assert np.all(np.isfinite(lossy["rmse_own"])) and (lossy["floats"] > 0).all()


def test_latency_model_names_the_treatment_simulate_target_runs():
    model = compare.target_model(8)
    for task in ("target", "localization"):
        for method in LATENCY_METHODS:
            text = compare.latency_model(method, task)
            if method in ("centralized", "local"):
                assert text in ("the bound: ideal links", "sends nothing")
                continue
            pairs = hasattr(compare.target_filter(method, model), "message_pairs")
            assert ("predicted one step" in text) == pairs and ("behind" in text) != pairs, (method, text)
    assert "two steps behind" in compare.latency_model("ci-diffusion") and "5 rounds" in compare.latency_model("icf-L5")
