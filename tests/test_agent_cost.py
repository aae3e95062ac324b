"""One agent's step (mascore.agent_cost): agreement with the team-wide filters, analytic counts, bad input.

No wall-clock assertion: the timings are reported by the benchmark, never tested.
"""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mascore import agent_cost

ONE_AGENT = [(task, m) for task in agent_cost.AGENT_TASKS for m in agent_cost.AGENT_METHODS[task]
             if (task, m) not in agent_cost.WHOLE_FILTER]
SNAPSHOT = Path(__file__).parents[1] / "benchmarks" / "data" / "agent_cost.csv"


@pytest.mark.parametrize(("task", "method"), ONE_AGENT)
@pytest.mark.parametrize(("n_agents", "agent"), [(5, 3), (6, 0)])
def test_one_agent_step_equals_its_row_of_the_team_filter(task, method, n_agents, agent):
    # the cut-down step (own prediction, correction, each consensus round with the neighbours' messages
    # as given arrays) gives agent i's numbers of the team-wide filter on the same state
    step = agent_cost.agent_step(task, method, n_agents, agent=agent, seed=3)
    assert step.scope == "one agent" and step.agent == agent and step.degree == 2
    out, ref = step.run(), step.reference()
    assert len(out) == len(ref)
    for a, b in zip(out, ref):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-11)


def test_repeated_calls_do_the_same_work():
    step = agent_cost.agent_step("target", "hcmci-L5", 6, agent=1)
    first, second = step.run(), step.run()
    for a, b in zip(first, second):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(("task", "method"), sorted(agent_cost.WHOLE_FILTER))
def test_whole_filter_steps_run_the_team_filter(task, method):
    step = agent_cost.agent_step(task, method, 5)
    assert step.scope == "whole filter" and step.reference is None
    out = step.run()
    assert all(np.all(np.isfinite(a)) for a in out)


@pytest.mark.parametrize(("task", "method", "ratio"), [
    ("team", "local", 1.0), ("team", "forwarding", 1.0), ("team", "vlahakis", 1.0), ("team", "set-membership", 1.0),
    ("team", "centralized", 2.0), ("team", "song-mb", 8.0), ("team", "song-eb", 64.0),
    ("target", "local", 1.0), ("target", "ci-L5", 1.0), ("target", "hcmci-L5", 1.0), ("target", "icf-L5", 1.0),
    ("target", "diffusion", 1.0), ("target", "centralized", 2.0),
    ("localization", "local", 8.0), ("localization", "ci-L5", 8.0), ("localization", "forwarding", 8.0),
    ("localization", "centralized", 8.0),
])
def test_analytic_flops_grow_as_the_stated_order(task, method, ratio):
    # flops(2N) / flops(N) tends to 2^p for O(N^p): at N = 4096 the lower-order terms are within 2 %
    r = agent_cost.agent_flops(task, method, 8192) / agent_cost.agent_flops(task, method, 4096)
    assert r == pytest.approx(ratio, rel=0.02)
    order = agent_cost._order(task, method)[0]
    p = round(np.log2(ratio))
    linear = "N q" in order or "N n" in order  # O(N q^2 + n^3) at the target's centre, O(N n^3) at the team's
    assert (f"N^{p}" in order) if p > 1 else ("N" not in order.split(":")[0] if p == 0 else linear)


@pytest.mark.parametrize(("task", "method", "ratio"), [
    ("team", "song-eb", 16.0), ("team", "song-mb", 4.0), ("team", "centralized", 2.0), ("team", "local", 1.0),
    ("localization", "ci-L1", 4.0), ("target", "ci-L1", 1.0),
])
def test_analytic_memory_grows_as_the_stated_order(task, method, ratio):
    r = agent_cost.agent_memory(task, method, 512) / agent_cost.agent_memory(task, method, 256)
    assert r == pytest.approx(ratio, rel=0.02)


def test_every_method_has_an_order_and_counts():
    for task in agent_cost.AGENT_TASKS:
        for m in agent_cost.AGENT_METHODS[task]:
            assert (task, m) in agent_cost.AGENT_ORDER
            assert agent_cost.agent_flops(task, m, 8) > 0 and agent_cost.agent_memory(task, m, 8) > 0


def test_consensus_rounds_cost_flops_and_time_scale_with_l():
    # five rounds mix five times the pairs of one round (the analytic count), and the step holds 5 rounds
    f1, f5 = (agent_cost.agent_flops("target", m, 8) for m in ("ci-L1", "ci-L5"))
    base = agent_cost.agent_flops("target", "local", 8)
    assert f5 - base == pytest.approx(5 * (f1 - base))


def test_table_stops_where_memory_stops(monkeypatch):
    limits = {"song-eb": (4, "too big for the test")}
    monkeypatch.setattr(agent_cost.estimation, "agent_limits", lambda task, step=False: limits if step else {})
    t = agent_cost.agent_costs((4, 8), ("team",), ("song-eb", "vlahakis"), repeats=1, min_time=0.0)
    eb = t[t["method"] == "song-eb"].set_index("n_agents")
    assert eb.loc[4, "us_per_step"] > 0 and np.isnan(eb.loc[8, "us_per_step"])
    assert set(eb["stops_at"]) == {4} and set(eb["why"]) == {"too big for the test"}
    assert (t[t["method"] == "vlahakis"]["us_per_step"] > 0).all()
    assert set(t["scope"]) == {"whole filter", "one agent"}


def test_slopes_of_power_laws():
    t = pd.DataFrame({"task": "t", "method": "m", "n_agents": [4, 8, 16, 32],
                      "us_per_step": [2.0, 16.0, 128.0, np.nan], "flops": [1.0, 2.0, 4.0, 8.0]})
    s = agent_cost.slopes(t).loc[("t", "m")]
    assert s["slope"] == pytest.approx(3.0) and s["flops_slope"] == pytest.approx(1.0)
    assert s["measured_to"] == 16
    assert agent_cost.slopes(t, top=2).loc[("t", "m"), "slope"] == pytest.approx(3.0)


@pytest.mark.parametrize(("kwargs", "match"), [
    (dict(task="swarm", method="local", n_agents=8), "task"),
    (dict(task="team", method="ci-L1", n_agents=8), "method"),
    (dict(task="target", method="vlahakis", n_agents=8), "method"),
    (dict(task="team", method="local", n_agents=2), "n_agents"),
    (dict(task="team", method="local", n_agents=8, agent=8), "agent"),
    (dict(task="team", method="local", n_agents=8, agent=-1), "agent"),
    (dict(task="team", method="local", n_agents=8, seed=-1), "seed"),
])
def test_bad_input_is_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        agent_cost.agent_step(**kwargs)


def test_bad_timing_and_count_arguments_are_refused():
    with pytest.raises(ValueError, match="repeats"):
        agent_cost.agent_step_cost("team", "local", 4, repeats=0)
    with pytest.raises(ValueError, match="min_time"):
        agent_cost.agent_step_cost("team", "local", 4, min_time=-1.0)
    with pytest.raises(ValueError, match="method"):
        agent_cost.agent_flops("team", "diffusion", 8)
    with pytest.raises(ValueError, match="task"):
        agent_cost.agent_memory("shared", "local", 8)
    with pytest.raises(ValueError, match="tasks"):
        agent_cost.agent_costs((4,), ("shared",))


def test_blas_pinning_is_reported():
    assert agent_cost.blas_pinned().startswith(("threadpoolctl", "OMP_NUM_THREADS="))


def test_snapshot_covers_every_method_and_stops_where_stated():
    t = pd.read_csv(SNAPSHOT)
    for task in agent_cost.AGENT_TASKS:
        for m in agent_cost.AGENT_METHODS[task]:
            rows = t[(t["task"] == task) & (t["method"] == m)].set_index("n_agents")
            assert len(rows), (f"{task} {m}: not in the snapshot the cost tables show (their CPU column reads '-' "
                               "for it): measure it again, python -m benchmarks.bench_agent_cost --snapshot")
            limit = agent_cost.MAX_AGENTS.get((task, m), (128, ""))[0]
            assert sorted(rows.index) == [4, 8, 16, 32, 64, 128]
            assert (rows.loc[rows.index <= limit, "us_per_step"] > 0).all()
            assert rows.loc[rows.index > limit, "us_per_step"].isna().all()
            # the analytic columns are the functions' values
            np.testing.assert_allclose(rows["flops"], [agent_cost.agent_flops(task, m, n) for n in rows.index],
                                       rtol=1e-5)


def test_max_deviation_is_nan_for_a_whole_filter_and_refuses_other_objects():
    assert np.isnan(agent_cost.max_deviation(agent_cost.agent_step("team", "centralized", 4)))
    assert agent_cost.max_deviation(agent_cost.agent_step("localization", "icf-L5", 5, agent=2)) < 1e-9
    with pytest.raises(TypeError, match="step"):
        agent_cost.max_deviation("local")
