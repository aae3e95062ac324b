"""The estimator protocol and the method specs: every filter declared once, found by the comparison and the cost table."""

import copy
import sys

import numpy as np
import pandas as pd
import pytest

import mascore
from mascore import agent_cost, compare, estimation, fusion
from mascore.compare.benchmark import check_cells
from mascore.compare.scenario import Scenario
from mascore.compare.tables import anees_verdict, consistency_text

TOY_FILTER = '''
"""A toy filter: each agent's own Kalman filter, written from scratch, with its spec."""

import numpy as np

from mascore import kalman
from mascore.estimation import Message, MethodSpec


class OwnOnlyFilter:
    def __init__(self, model, inflation=1.0):
        self.model, self.inflation = model, inflation

    def predict(self, x, P):
        F, Q = self.model.F, self.inflation * self.model.Q
        return x @ F.T, F @ P @ F.T + Q

    def update(self, x, P, z):
        m = self.model
        out = [kalman.update(x[..., i, :], P[..., i, :, :], m.agent_measurement(z, i), m.H[i], m.R[i])
               for i in range(m.n_agents)]
        return np.stack([a for a, _ in out], -2), np.stack([b for _, b in out], -3)

    def run(self, x0, P0, z):
        x, P = self.model.check_state(x0, P0)
        xs, Ps = [], []
        for zk in z:
            x, P = self.update(*self.predict(x, P), zk)
            xs.append(x)
            Ps.append(P)
        return np.stack(xs), np.stack(Ps)

    def agent_inputs(self, x, P, z, i):
        return {"x": x[i], "P": P[i], "z": self.model.agent_measurement(z, i)}, ()

    def agent_step(self, i, own, messages):
        F, Q, m = self.model.F, self.inflation * self.model.Q, self.model
        return kalman.update(F @ own["x"], F @ own["P"] @ F.T + Q, own["z"], m.H[i], m.R[i])

    def messages(self, i=0):
        return ()


def _spec(name, inflation, position, role):
    return MethodSpec(name, ("target",), lambda model: OwnOnlyFilter(model, inflation),
                      lambda n, q, d, N: (0.0, 12.0 * n**3), {"target": ("O(n^3)", "O(n^2)")},
                      lambda n, q, d, N: float(n**2 + n), position=position, role=role, family="toy-own",
                      setting=inflation, knob="process noise inflation",
                      max_agents={"target": (16, "toy: not beyond 16")})


METHODS = (_spec("toy-own", 1.0, 99, "recipe"), _spec("toy-own-q2", 2.0, 99.5, "knob"))
'''


@pytest.fixture
def toy_module(tmp_path, monkeypatch):
    """``mascore.toyfilter2099``: one class and one spec in one new file, and nothing else touched."""
    (tmp_path / "toyfilter2099.py").write_text(TOY_FILTER)
    monkeypatch.setattr(mascore, "__path__", [*mascore.__path__, str(tmp_path)])
    monkeypatch.delitem(sys.modules, "mascore.toyfilter2099", raising=False)
    yield "toy-own"
    sys.modules.pop("mascore.toyfilter2099", None)
    vars(mascore).pop("toyfilter2099", None)


def test_a_new_filter_is_one_class_and_one_spec_in_one_module(toy_module):
    assert toy_module in compare.target_methods("target")
    assert toy_module not in compare.target_methods("localization")  # its spec says where it applies
    target_cells = [c for c in compare.grid_cells("quick") if c["task"] == "target"]
    assert {c["method"] for c in target_cells} == set(compare.target_methods("target", knobs=True))
    # the sweep: one cell of it and of the bound, the same data; the headline table
    cell = {"study": "target", "task": "target", "n_agents": 8, "graph": "ring", "noise": "gaussian",
            "dropout": 0.0, "q_scale": 1.0, "block": 0}
    rows = [{**r, **cell, "method": m, "cell": m} for m in ("centralized", "local", toy_module)
            for r in compare.run_cell({**cell, "method": m})]
    summary = compare.summarize(pd.DataFrame(rows))
    table = compare.headline(summary, "target")
    assert toy_module in table.index and table.loc[toy_module, "flops/agent/step"] == 12 * 4**3
    # the toy is each agent's own Kalman filter, as is "local" (consensus on information with L = 0)
    s = summary.set_index("method")
    assert s.loc[toy_module, "rmse_own_mean"] == pytest.approx(s.loc["local", "rmse_own_mean"], rel=1e-9)
    # the cost table: its own agent_step, checked against its team-wide update
    assert toy_module in agent_cost.AGENT_METHODS["target"]
    step = agent_cost.agent_step("target", toy_module, 6, agent=2)
    assert agent_cost.max_deviation(step) < 1e-12
    cost = agent_cost.agent_costs((4, 32), ("target",), (toy_module,), repeats=1, min_time=0.0)
    assert cost["method"].tolist() == [toy_module] * 2 and cost["work"].iloc[0] == "O(n^3)"
    # its spec's limit: the cost table stops where the sweeps stop, and says why
    assert cost["us_per_step"].iloc[0] > 0 and np.isnan(cost["us_per_step"].iloc[1])
    assert set(cost["stops_at"]) == {16} and set(cost["why"]) == {"toy: not beyond 16"}
    assert agent_cost.MAX_AGENTS[("target", toy_module)] == (16, "toy: not beyond 16")
    assert max(c["n_agents"] for c in compare.grid_cells("full") if c["method"] == toy_module) == 16
    # its knob (a second spec, role "knob"): swept at N = 8 beside the recipe, a row of the knob table,
    # neither in the headline nor in the cost table
    knob = "toy-own-q2"
    assert knob in compare.FUSION_KNOB_METHODS and knob not in compare.target_methods("target")
    assert {c["n_agents"] for c in target_cells if c["method"] == knob} == {8}
    assert not any(c["method"] == knob for c in compare.grid_cells("quick") if c["task"] == "localization")
    [row] = [k for k in compare.KNOBS if any(m == knob for _, _, m in k.settings)]
    assert row.name == "toy-own: process noise inflation" and row.task == "target" and row.recipe == ("1",)
    assert row.settings == (("1", "target", toy_module), ("2", "target", knob))
    assert knob in compare.knob_variants() and knob not in agent_cost.AGENT_METHODS["target"]


def test_a_new_filter_on_the_protocol_alone_runs_over_lossy_links_and_is_kept_from_late_ones(toy_module):
    # loss: the method's own filter rebuilt on each step's delivered graph, whatever its class
    cell = {"study": "loss", "task": "target", "method": toy_module, "n_agents": 8, "graph": "ring",
            "noise": "gaussian", "dropout": 0.3, "q_scale": 1.0, "block": 0}
    assert np.isfinite([r["rmse_own"] for r in compare.run_cell(cell)]).all()
    # latency: fusion_links takes a network filter's messages late; the toy's are not modelled, and it says why
    assert toy_module not in compare.LATENCY_METHODS
    assert "no treatment of its late messages" in compare.LATENCY_NOT_MODELLED[toy_module]
    with pytest.raises(ValueError, match="no model of late messages"):
        compare.latency_model(toy_module)
    with pytest.raises(ValueError, match="latency: method 'toy-own'"):
        compare.simulate_target(toy_module, 8, 0, runs=2, latency=1)
    # both grids: the toy's cells where its spec and its filter allow, so every cell passes the cell check
    for name in ("quick", "full"):
        cells = compare.grid_cells(name)
        assert len(check_cells(cells)) == len(cells)
        assert not any(c["method"] == toy_module and c.get("study") == "latency" for c in cells)
        assert not any(c["method"] == toy_module and c["task"] == "localization" for c in cells)
        assert any(c["method"] == toy_module and c.get("study") == "loss" for c in cells) == (name == "full")


TOY_TEAM = '''
"""A toy team method: each agent's own Kalman filter, written from scratch, stepping itself, with its spec."""

import numpy as np

from mascore.estimation import Message, MethodSpec


class OwnKalman:
    def __init__(self, team, x_hat0):
        self.A, self.B, self.Q, self.H, self.R = team.A, team.B, team.Q_filter, team.C, team.R
        self.own, self.own_cov = x_hat0.copy(), team.P0.copy()

    def _correct(self, x, P, z):
        K = np.linalg.solve(self.H @ P @ self.H.T + self.R, self.H @ P).T  # P H^T S^-1
        return x + (z - x @ self.H.T) @ K.T, P - K @ self.H @ P

    def update(self, Z, S):
        N = Z.shape[1]
        self.own, self.own_cov = self._correct(self.own, self.own_cov, Z[:, np.arange(N), np.arange(N)])

    def predict(self, U):
        self.own, self.own_cov = self.own @ self.A.T + U @ self.B.T, self.A @ self.own_cov @ self.A.T + self.Q

    def agent_inputs(self, Z, S, U, i):
        return {"x": self.own[0, i], "P": self.own_cov, "z": Z[0, i, i], "u": U[0, i]}, ()

    def agent_step(self, i, own, messages):
        x, P = self._correct(own["x"], own["P"], own["z"])
        return x @ self.A.T + own["u"] @ self.B.T, self.A @ P @ self.A.T + self.Q

    def agent_state(self, i):
        return self.own[0, i], self.own_cov

    def messages(self, i=0):
        return (Message("own estimate", 4.0),)


METHODS = (MethodSpec("toy-team", ("team",), OwnKalman, lambda n, q, d, N: (float(n), 12.0 * n**3),
                      {"team": ("O(n^3)", "O(n^2)")}, lambda n, q, d, N: float(n**2 + n), position=99),)
'''


@pytest.fixture
def toy_team(tmp_path, monkeypatch):
    """``mascore.toyteam2099``: one class and one spec of the team task in one new file, and nothing else touched."""
    (tmp_path / "toyteam2099.py").write_text(TOY_TEAM)
    monkeypatch.setattr(mascore, "__path__", [*mascore.__path__, str(tmp_path)])
    monkeypatch.delitem(sys.modules, "mascore.toyteam2099", raising=False)
    yield "toy-team"
    sys.modules.pop("mascore.toyteam2099", None)
    vars(mascore).pop("toyteam2099", None)


def test_a_new_team_method_is_one_class_and_one_spec_in_one_module(toy_team):
    cells = compare.grid_cells("quick")
    studies = {c["study"] for c in cells if c["method"] == toy_team}
    assert studies == {"scaling", "graph", "dropout", "noise", "wrong-q", "position", "switching"}
    assert compare.floats_per_step(toy_team, 8) == 4.0
    # the sweep and the headline table: the toy is each agent's own Kalman filter, as is "local"
    cell = {"study": "scaling", "task": "team", "n_agents": 8, "graph": "ring", "noise": "gaussian",
            "dropout": 0.0, "q_scale": 1.0, "block": 0}
    rows = [{**r, **cell, "method": m, "cell": m} for m in ("centralized", "local", toy_team)
            for r in compare.run_cell({**cell, "method": m})]
    summary = compare.summarize(pd.DataFrame(rows))
    table = compare.headline(summary, "team")
    assert list(table.index) == ["centralized", "local", toy_team] and table.loc[toy_team, "floats/step"] == 4.0
    s = summary.set_index("method")
    for metric in ("rmse_own_mean", "nees_own_mean", "spread_mean"):
        assert s.loc[toy_team, metric] == pytest.approx(s.loc["local", metric], rel=1e-9)
    position = compare.simulate_team(toy_team, 4, 3, runs=5, sensing="position")  # its filter reads team.C
    assert position["rmse_own"] == pytest.approx(compare.simulate_team("local", 4, 3, runs=5,
                                                                       sensing="position")["rmse_own"], rel=1e-9)
    # the cost table: its own agent_step, checked against its team-wide step
    assert toy_team in agent_cost.AGENT_METHODS["team"]
    assert agent_cost.max_deviation(agent_cost.agent_step("team", toy_team, 6, agent=2)) < 1e-12
    cost = agent_cost.agent_costs((4,), ("team",), (toy_team,), repeats=1, min_time=0.0)
    assert cost["method"].tolist() == [toy_team] and cost["work"].iloc[0] == "O(n^3)"
    assert cost["flops"].iloc[0] == 12 * 4**3


def test_the_toy_team_method_is_gone_with_its_module():
    assert "toy-team" not in compare.TEAM_METHODS and "toy-team" not in agent_cost.AGENT_METHODS["team"]
    assert not any(c["method"] == "toy-team" for c in compare.grid_cells("quick"))


def test_the_toy_is_gone_with_its_module():
    assert "toy-own" not in compare.target_methods()
    assert "toy-own-q2" not in compare.FUSION_KNOB_METHODS and "toy-own-q2" not in compare.knob_variants()


@pytest.mark.parametrize("spec", estimation.method_specs("target"), ids=lambda s: s.name)
def test_every_fusion_filter_implements_the_protocol_and_declares_what_it_sends(spec):
    model = compare.target_model(8)
    filt = spec.build(model)
    assert isinstance(filt, estimation.Estimator)
    declared = sum(m.floats for m in filt.messages())
    floats, _ = spec.cost(4, 1, 2, 8)  # n = 4, one measurement per agent, degree 2
    assert declared == pytest.approx(floats)


@pytest.mark.parametrize("spec", [s for s in estimation.method_specs("localization") if not s.whole_filter],
                         ids=lambda s: s.name)
def test_agent_step_is_the_agents_row_of_the_team_wide_update(spec):
    model = compare.localization_model(6)
    filt = spec.build(model)
    rng = np.random.default_rng(5)
    n = model.n_states
    _, z = model.simulate(np.zeros(n), np.eye(n), 2, rng)
    x, P = model.check_state(rng.standard_normal((6, n)), np.eye(n))
    x, P = filt.update(*filt.predict(x, P), z[0])
    xr, Pr = filt.update(*filt.predict(x, P), z[1])
    for i in (0, 3):
        xi, Pi = filt.agent_step(i, *filt.agent_inputs(x, P, z[1], i))
        np.testing.assert_allclose(xi, xr[i], atol=1e-12 * (1 + np.abs(xr[i]).max()))
        np.testing.assert_allclose(Pi, Pr[i], atol=1e-12 * (1 + np.abs(Pr[i]).max()))


def test_agent_inputs_refuse_a_batch_and_a_bad_agent():
    model = compare.target_model(4)
    filt = fusion.ConsensusOnInformationFilter(model, 2)
    x, P = model.check_state(np.zeros(4), np.eye(4))
    with pytest.raises(ValueError, match="one run"):
        filt.agent_inputs(np.stack([x, x]), P, np.zeros(4), 0)
    with pytest.raises(ValueError, match="agent index below N = 4"):
        filt.agent_inputs(x, P, np.zeros(4), 4)


def test_a_spec_is_checked_when_declared():
    with pytest.raises(ValueError, match="order must give"):
        estimation.MethodSpec("x", ("target",), fusion.CentralizedFilter, lambda *a: (0.0, 0.0), {})
    with pytest.raises(ValueError, match="method must be one of"):
        estimation.method_spec("no-such-method", "target")
    with pytest.raises(ValueError, match="both in tasks and in not_applicable"):
        estimation.MethodSpec("x", ("target",), fusion.CentralizedFilter, lambda *a: (0.0, 0.0),
                              {"target": ("O(1)", "O(1)")}, not_applicable={"target": "why"})


@pytest.mark.parametrize(("limit", "match"), [({"target": 16}, "expected"), ({"target": ("16", "w")}, "expected"),
                                              ({"target": (0, "w")}, "expected"), ({"target": (8, "")}, "expected"),
                                              ({"targett": (8, "w")}, "not one of its tasks")])
def test_a_spec_limit_is_checked_where_it_is_declared(limit, match):
    with pytest.raises(ValueError, match=match):
        estimation.MethodSpec("x", ("target",), fusion.CentralizedFilter, lambda *a: (0.0, 0.0),
                              {"target": ("O(1)", "O(1)")}, max_agents=limit)


def test_a_scenario_names_a_reference_among_its_methods_and_no_taken_name(tmp_path, monkeypatch):
    from mascore.compare.scenario import scenarios

    source = TOY_SCENARIO.replace('reference="centre", ', "")  # the default reference, "centralized", is not its
    (tmp_path / "toyscenario2098.py").write_text(source)
    monkeypatch.setattr(compare, "__path__", [*compare.__path__, str(tmp_path)])
    monkeypatch.delitem(sys.modules, "mascore.compare.toyscenario2098", raising=False)
    try:
        with pytest.raises(ValueError, match="its reference 'centralized'.* is not one of its methods"):
            scenarios()
    finally:
        sys.modules.pop("mascore.compare.toyscenario2098", None)
        vars(compare).pop("toyscenario2098", None)
    for taken in ("position", "switching", "target"):
        with pytest.raises(ValueError, match="new scenario's name"):
            Scenario(taken, lambda: (), lambda *a, **k: {}, lambda *a: 0.0, lambda name: [])


def test_a_spec_is_read_only():
    spec = estimation.method_spec("ci-L5", "target")
    with pytest.raises(TypeError):
        spec.not_applicable["localization"] = "x"
    with pytest.raises(TypeError):
        spec.order["target"] = ("O(1)", "O(1)")
    assert "localization" not in estimation.method_spec("ci-L5", "target").not_applicable
    assert copy.deepcopy(spec) is spec and copy.copy(spec) is spec
    with pytest.raises(TypeError):
        estimation.method_spec("song-eb", "team").max_agents["team"] = (10**6, "x")


TOY_SCENARIO = '''
"""A toy scenario: N agents measure one scalar random walk; each filters alone, or one centre filters all."""

import numpy as np

from mascore.compare.scenario import Scenario


def simulate(method, n_agents, seed, *, noise="gaussian", dropout=0.0, graph="ring", settings=None):
    rng = np.random.default_rng(seed)
    runs, steps = 20, 40
    x, xh, P, sq, nees = np.zeros(runs), np.zeros((runs, n_agents)), 1.0, np.zeros(runs), np.zeros(runs)
    R = 1.0 / n_agents if method == "centre" else 1.0  # the centre: the mean of the N measurements
    for _ in range(steps):
        x = x + 0.1 * rng.standard_normal(runs)
        z = x[:, None] + rng.standard_normal((runs, n_agents))
        if method == "centre":
            z = np.broadcast_to(z.mean(1, keepdims=True), z.shape)
        P = P + 0.01
        K = P / (P + R)
        xh, P = xh + K * (z - xh), (1 - K) * P
        sq += np.mean((xh - x[:, None]) ** 2, 1)
        nees += (xh[:, 0] - x) ** 2 / P  # agent 0's NEES (its state: one scalar)
    return {"rmse_own": np.sqrt(sq / steps), "cpu_s": np.zeros(runs), "nees_own": nees / steps}


def cells(name):
    return [{"study": "toy", "task": "toy-walk", "method": m, "n_agents": 4, "graph": "ring", "noise": "gaussian",
             "dropout": 0.0, "q_scale": 1.0, "block": 0} for m in ("centre", "alone")]


SCENARIO = Scenario("toy-walk", lambda: ("centre", "alone"), simulate,
                    lambda method, n_agents, degree: float(n_agents) if method == "centre" else 0.0, cells,
                    headline={"n_agents": 4, "dropout": 0.0}, reference="centre", nees_dimension=1)
'''


@pytest.fixture
def toy_scenario(tmp_path, monkeypatch):
    """``mascore.compare.toyscenario2099``: one new scenario in one new file, and nothing else touched."""
    (tmp_path / "toyscenario2099.py").write_text(TOY_SCENARIO)
    monkeypatch.setattr(compare, "__path__", [*compare.__path__, str(tmp_path)])
    monkeypatch.delitem(sys.modules, "mascore.compare.toyscenario2099", raising=False)
    yield "toy-walk"
    sys.modules.pop("mascore.compare.toyscenario2099", None)
    vars(compare).pop("toyscenario2099", None)


def test_a_new_scenario_is_one_module(toy_scenario, tmp_path):
    from mascore.compare.gridfile import read_grid
    from mascore.compare.scenario import scenarios

    assert toy_scenario in scenarios()
    with pytest.raises(TypeError):  # shared by every table: read-only
        scenarios()[toy_scenario].headline["n_agents"] = 99
    cells = [c for c in compare.grid_cells("quick") if c["task"] == toy_scenario]  # the sweep has its cells
    assert {c["method"] for c in cells} == {"centre", "alone"}
    rows = [{**r, **c, "cell": c["method"]} for c in cells for r in compare.run_cell(c)]
    table = pd.DataFrame(rows)
    assert set(table["floats"]) == {4.0, 0.0} and np.isnan(table["containment"]).all()
    rmse = table.groupby("method")["rmse_own"].mean()
    # the centre averages N = 4 measurements of the walk: its error is below an agent's alone
    assert rmse["centre"] < 0.8 * rmse["alone"]
    summary = compare.summarize(table)  # the ratios against the reference the scenario names
    ratio = summary.set_index("method").loc["alone", "ratio_mean"]
    assert ratio == pytest.approx(rmse["alone"] / rmse["centre"], rel=0.05)
    table = compare.headline(summary, toy_scenario)  # its own headline table, at its headline cells
    assert list(table.index) == ["centre", "alone"] and list(table["floats/step"]) == [4.0, 0.0]
    assert table.loc["alone", "RMSE ratio [95 %]"].startswith(f"{ratio:.3f}")
    # consistency against the chi-square bounds of its NEES dimension: both are Kalman filters of the walk
    assert table.loc["alone", "consistency"].endswith(", consistent")
    bounds = summary.set_index("method").loc["alone", ["nees_bound_lo", "nees_bound_hi"]].to_numpy(float)
    np.testing.assert_allclose(bounds, compare.anees_bounds(20, 1))
    with pytest.raises(ValueError, match="must be one of"):
        compare.run_cell({**cells[0], "method": "no-such-method"})
    # a grid file of your own names it like a built-in task (its reference first)
    path = tmp_path / "walk.toml"
    path.write_text("runs = 3\n[[study]]\ntask = 'toy-walk'\nmethod = 'alone'\nn_agents = 4\n")
    assert [c["method"] for c in read_grid(path).cells] == ["centre", "alone"]


def test_every_method_builds_an_estimator_of_the_protocol():
    """What every spec builds, on every task's model, implements the protocol (predict, update, the agent's step)."""
    team = compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS, "ring")
    models = {"team": (team, np.zeros((1, 4, 4))), "target": (compare.target_model(4),),
              "localization": (compare.localization_model(4),), "shared": (None,)}
    for task, args in models.items():
        for spec in estimation.method_specs(task):
            assert isinstance(spec.build(*args), estimation.Estimator), (task, spec.name)


def test_no_consistency_verdict_without_bounds():
    row = pd.Series({"nees_own_mean": 50.0, "nees_bound_lo": np.nan, "nees_bound_hi": np.nan,
                     "containment_mean": np.nan})
    assert anees_verdict(row) == "—"
    assert consistency_text(row) == "ANEES 50.00 (no chi-square bounds: no NEES dimension)"
    with pytest.raises(ValueError, match="nees_dimension"):
        Scenario("toy", lambda: (), lambda *a, **k: {}, lambda *a: 0.0, lambda name: [], nees_dimension=0)


def test_the_toy_scenario_is_gone_with_its_module():
    from mascore.compare.scenario import scenarios

    assert "toy-walk" not in scenarios()
    assert not any(c["task"] == "toy-walk" for c in compare.grid_cells("quick"))


def test_the_not_applicable_tables_are_the_specs_one_method_per_key():
    tables = {"target": compare.TARGET_NOT_APPLICABLE, "localization": compare.LOCALIZATION_NOT_APPLICABLE,
              "switching": compare.SWITCHING_NOT_APPLICABLE, "position": compare.POSITION_NOT_APPLICABLE}
    names = {s.name for s in estimation.method_specs()}
    for scenario, table in tables.items():
        assert table and set(table) <= names  # every key is one declared method
        for name, why in table.items():
            assert any(s.name == name and s.not_applicable.get(scenario) == why for s in estimation.method_specs())
    assert list(compare.SWITCHING_NOT_APPLICABLE) == list(compare.VLAHAKIS_PHI)  # every gain of its knob
    assert "song-mb" in compare.TARGET_NOT_APPLICABLE and "song-eb" in compare.TARGET_NOT_APPLICABLE


@pytest.mark.parametrize("spec", estimation.method_specs("team"), ids=lambda s: s.name)
def test_every_team_method_is_built_by_its_spec_and_declares_its_cost(spec):
    team = compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS)
    filt = spec.build(team, np.zeros((1, 4, 4)))
    assert callable(filt.agent_step) and callable(filt.messages)
    floats, flops = spec.cost(4, 4, 2, 4)
    assert floats == compare.floats_per_step(spec.name, 4, 2.0) and flops > 0


@pytest.mark.parametrize("spec", estimation.method_specs("shared"), ids=lambda s: s.name)
def test_a_shared_filters_agent_step_is_its_row_of_the_team_wide_update(spec):
    from mascore import graphs

    filt = spec.build(None)
    rng = np.random.default_rng(3)
    xi, P = rng.standard_normal((6, 2)), np.stack([np.diag(rng.uniform(0.5, 2.0, 2)) for _ in range(6)])
    G = graphs.ring_graph(6)
    if spec.name == "average-consensus":
        xr, Pr = filt.update(xi, G), None
        own, messages = filt.agent_inputs(xi, G, 2)
    else:
        xr, Pr = filt.update(xi, P, G)
        own, messages = filt.agent_inputs(xi, P, G, 2)
    out = filt.agent_step(2, own, messages)
    np.testing.assert_allclose(out[0], xr[2], rtol=1e-12, atol=1e-14)
    if Pr is not None:
        np.testing.assert_allclose(out[1], Pr[2], rtol=1e-12, atol=1e-14)
    assert sum(m.floats for m in filt.messages()) == compare.floats_per_step(spec.name, 6)


def test_the_position_centres_step_is_its_team_wide_step():
    team = compare.team_setup(5, "gaussian", 1.0, compare.SETTINGS, sensing="position")
    est = compare.make_estimator("centralized", team, np.random.default_rng(1).standard_normal((1, 5, 4)))
    rng = np.random.default_rng(2)
    Z, S, U = rng.standard_normal((1, 5, 5, 2)), np.ones((1, 5, 5), bool), rng.standard_normal((1, 5, 2))
    x, P = est.agent_step(0, *est.agent_inputs(Z, S, U, 0))
    est.update(Z, S)
    est.predict(U)
    np.testing.assert_allclose(x, est.own, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P, est.P, rtol=1e-12, atol=1e-14)


def test_the_package_scan_lists_the_modules_pkgutil_lists(tmp_path):
    """The scan's folder listing (one ``os.scandir``) names the modules ``pkgutil.iter_modules`` names, less the
    private, study-layer and sub-package ones; a path entry that is not a folder is listed through pkgutil."""
    import importlib.machinery
    import pkgutil
    import zipfile

    expected = {m.name for m in pkgutil.iter_modules(mascore.__path__)
                if not (m.ispkg or m.name.startswith("_") or m.name in estimation.STUDY_LAYER)}
    listed = estimation._core_modules(mascore.__path__)
    assert set(listed) == expected
    assert all(source.endswith(f"{name}.py") for name, source in listed.items())
    archive = tmp_path / "extra.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("zipped2099.py", "METHODS = ()\n")
        z.writestr("_hidden2099.py", "")
    assert estimation._core_modules([str(archive)]) == {"zipped2099": ""}  # imported to see: not a plain file
    assert estimation._module_name("lqr.py") == "lqr"
    assert estimation._module_name("fast" + importlib.machinery.EXTENSION_SUFFIXES[0]) == "fast"
    assert estimation._module_name("notes.txt") == ""


def test_the_new_names_refuse_bad_input_by_name():
    """The third trial's findings: each refused up front, naming what was wrong."""
    from mascore.compare.scenario import nees_dimension, reference_method

    with pytest.raises(TypeError, match="methods of scenario 'x' must be callable"):
        Scenario("x", ("a",), print, print, print)
    for call in (lambda: reference_method("bogus"), lambda: nees_dimension("bogus"),
                 lambda: estimation.agent_limits("bogus")):
        with pytest.raises(ValueError, match="task must be one of"):
            call()
    with pytest.raises(TypeError, match="step must be True or False"):
        estimation.agent_limits("team", step="yes")
    with pytest.raises(ValueError, match="tasks of method 'x' must be a non-empty tuple"):
        estimation.MethodSpec("x", (), fusion.CentralizedFilter, lambda *a: (0.0, 0.0), {})
    with pytest.raises(ValueError, match="each task's \\(work, memory\\) orders"):
        estimation.MethodSpec("x", ("target",), fusion.CentralizedFilter, lambda *a: (0.0, 0.0), {"target": 5})
    for mean, cov in ((0.0, np.eye(1)), (np.zeros(0), np.zeros((0, 0)))):
        with pytest.raises(ValueError, match="mean must be an array"):
            estimation.GaussianState(mean, cov)
    assert agent_cost.agent_costs(np.array([4]), ("target",), ("local",), repeats=1, min_time=0.0)["n_agents"].tolist() \
        == [4]  # sizes as an array
    assert estimation.SetState(np.zeros((0, 2)), np.zeros((0, 2, 2))).shape.shape == (0, 2, 2)  # an empty batch
    spec = estimation.method_spec("ci-L5", "target")
    assert hash(spec) == hash(estimation.method_spec("ci-L5", "target"))
    for task in ("bogus", None):
        with pytest.raises(ValueError, match="task must be 'target' or 'localization'"):
            compare.latency_methods(task)
    with pytest.raises(ValueError, match="task must be 'target' or 'localization'"):
        compare.latency_model("centralized", "bogus")
    assert "4 rounds" in compare.latency_model("ci-Ldiam")  # the diameter of the latency study's ring of 8
    for cell, error, match in [("x", TypeError, "must be a mapping"),
                               ({"task": "target", "study": "loss"}, ValueError, "lacks the coordinates"),
                               ({"task": "target", "method": "bogus", "n_agents": 8, "dropout": 0.2, "noise": "gaussian",
                                 "study": "loss"}, ValueError, "cell\\['method'\\] of a target cell must be one of")]:
        with pytest.raises(error, match=match):
            compare.check_link_cell(cell)
    for kwargs, error, match in [(dict(sizes=(4,), tasks=("target",), methods=("bogus",)), ValueError, "bogus"),
                                 (dict(sizes=(4,), tasks=("target",), methods="local"), TypeError, "methods"),
                                 (dict(sizes=()), ValueError, "sizes"), (dict(sizes=4), TypeError, "sizes"),
                                 (dict(sizes=(4,), tasks="target"), TypeError, "tasks")]:
        with pytest.raises(error, match=match):
            agent_cost.agent_costs(**kwargs, repeats=1, min_time=0.0)
    with pytest.raises(ValueError, match="table has no rows"):
        compare.summarize(pd.DataFrame(columns=["task", "method", "n_agents", "cell", "block", "run", "rmse_own",
                                                "cpu_s", "floats", "nees_own", "containment", "spread", "study",
                                                "graph", "noise", "dropout", "q_scale"]))


def test_a_diverged_run_is_counted_not_hidden():
    cell = {"study": "target", "task": "target", "n_agents": 4, "graph": "ring", "noise": "gaussian",
            "dropout": 0.0, "q_scale": 1.0, "block": 0}
    rows = [{**r, **cell, "method": m, "cell": m} for m in ("centralized", "local")
            for r in compare.run_cell({**cell, "method": m})]
    table = pd.DataFrame(rows)
    table.loc[table.index[-1], "rmse_own"] = np.inf  # one run of "local" diverged
    s = compare.summarize(table).set_index("method")
    assert s.loc["local", "n_diverged"] == 1 and s.loc["centralized", "n_diverged"] == 0
