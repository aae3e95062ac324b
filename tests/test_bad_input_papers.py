"""Bad input to the paper scenarios: clear errors naming the argument, and no unbounded retry loop."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mascore.papers import song2023 as rdv
from mascore.papers import song2023_flocking as flock


def test_flocking_initial_states_gives_up_with_a_clear_error_instead_of_hanging():
    """Issue 'Nothing silent': a sensing range that never connects the team used to loop forever."""
    tiny = dataclasses.replace(flock.SETTINGS, sensing_range=1e-3)
    with pytest.raises(ValueError, match="sensing_range"):
        flock.initial_states(np.random.default_rng(0), 1, tiny, max_tries=50)


@pytest.mark.parametrize("kwargs,name,error", [
    (dict(n_runs=0), "n_runs", ValueError),
    (dict(n_runs=1.5), "n_runs", TypeError),
    (dict(rng=-1), "rng", ValueError),
    (dict(settings="settings"), "settings", TypeError),
])
def test_flocking_initial_states_names_bad_arguments(kwargs, name, error):
    args = dict(rng=np.random.default_rng(0), n_runs=1) | kwargs
    with pytest.raises(error, match=name):
        flock.initial_states(**args)


def test_flocking_settings_refuse_an_empty_team_when_built():
    with pytest.raises(ValueError, match="n_agents"):
        dataclasses.replace(flock.SETTINGS, n_agents=0)


def test_rendezvous_initial_states_take_a_seed_and_name_bad_arguments():
    s = rdv.setup()
    x0_a, A_a = rdv.random_initial_states(5, s)
    x0_b, A_b = rdv.random_initial_states(np.random.default_rng(5), s)
    assert np.array_equal(x0_a, x0_b) and np.array_equal(A_a, A_b)
    with pytest.raises(ValueError, match="rng"):
        rdv.random_initial_states(-1, s)
    with pytest.raises(TypeError, match="RendezvousSetup"):
        rdv.random_initial_states(5, 3)
    with pytest.raises(ValueError, match="max_tries"):
        rdv.random_initial_states(5, s, max_tries=0)


# ---------------------------------------------------------------- issue "Hostile inputs": the confirmed defects

from dataclasses import replace  # noqa: E402

import pandas as pd  # noqa: E402

from mascore import compare  # noqa: E402
from mascore.ledger import Claim, format_number  # noqa: E402
from mascore.papers import bhattacharjee2021 as sm  # noqa: E402
from mascore.papers import ren2005 as ren  # noqa: E402
from mascore.papers import vlahakis as vl  # noqa: E402


def test_ren2005_refuses_negative_variance_and_an_agent_out_of_the_team():
    with pytest.raises(ValueError, match=r"KalmanConsensusSettings\.P_equal must be a finite number > 0 h²"):
        ren.fig1_initial(True, replace(ren.SETTINGS, P_equal=-1.0))
    with pytest.raises(ValueError, match=r"KalmanConsensusSettings\.confident_agent"):
        replace(ren.SETTINGS, confident_agent=-1)  # used to make agent 9 the confident one
    with pytest.raises(ValueError, match=r"KalmanConsensusSettings\.confident_agent must be an agent 1\.\.n_agents"):
        replace(ren.SETTINGS, confident_agent=11)
    with pytest.raises(ValueError, match=r"KalmanConsensusSettings\.xi0 must hold one initial time per agent"):
        replace(ren.SETTINGS, n_agents=4)


def test_song2023_settings_refuse_negative_times_and_box():
    with pytest.raises(ValueError, match=r"RendezvousSettings\.converged_from"):
        rdv.fig2(0, n_runs=1, horizon=1.0, settings=replace(rdv.SETTINGS, converged_from=-1.0))
    with pytest.raises(ValueError, match=r"RendezvousSettings\.box must be a finite number > 0 m"):
        replace(rdv.SETTINGS, box=-400.0)  # used to fail in NumPy with 'high - low < 0'


def test_requests_that_cannot_fit_are_refused_up_front():
    with pytest.raises(ValueError, match="n_runs asks for too much"):
        rdv.fig3(0, n_runs=10**12, horizon=2.0)
    with pytest.raises(ValueError, match="repeat"):
        flock.ekf_step_seconds(repeat=10**12)
    with pytest.raises(ValueError, match="repeat must be an integer in"):
        flock.ekf_step_seconds(repeat=flock.MAX_REPEAT + 1)
    with pytest.raises(ValueError, match="plain_repeat"):
        rdv.estimator_step_seconds(4, repeat=1, plain_repeat=10**12)
    with pytest.raises(ValueError, match="n_runs asks for too much"):
        sm.draw(1, n_runs=10**12)


def test_flocking_refuses_a_negative_team():
    with pytest.raises(ValueError, match=r"FlockingSettings\.n_agents must be an integer >= 2"):
        flock.run(replace(flock.SETTINGS, n_agents=-1))  # used to fail with 'negative dimensions'
    with pytest.raises(ValueError, match=r"FlockingSettings\.observer must be an agent"):
        replace(flock.SETTINGS, observer=9)


def test_vlahakis_refuses_a_negative_weight():
    with pytest.raises(ValueError, match=r"ObserverSettings\.Q1 must be a finite number > 0"):
        vl.as_printed_phi_interval(5.0, settings=replace(vl.SETTINGS, Q1=-10.0))  # used to return (nan, nan)
    with pytest.raises(ValueError, match=r"ObserverSettings\.graph must be one of"):
        replace(vl.SETTINGS, graph="torus")
    with pytest.raises(ValueError, match=r"ObserverSettings\.phi_grid"):
        replace(vl.SETTINGS, phi_grid=(1.0, 0.0, 5))
    with pytest.raises(ValueError, match=r"ObserverSettings\.Bbar must have one row per state"):
        replace(vl.SETTINGS, Bbar=((1.0,),))


def test_bhattacharjee2021_refuses_nan_box_and_an_empty_horizon():
    with pytest.raises(ValueError, match=r"SetMembershipSettings\.x0_box must be a finite number >= 0"):
        sm.draw(1, 2, scenario=replace(sm.SETTINGS, x0_box=np.nan))  # used to draw NaN states
    with pytest.raises(ValueError, match=r"SetMembershipSettings\.t_f must be an integer >= 1"):
        replace(sm.SETTINGS, t_f=0)  # used to fail with 'need at least one array to stack'
    with pytest.raises(ValueError, match=r"SetMembershipSettings\.figure_method must be one of 'sdp', 'closed_form'"):
        replace(sm.SETTINGS, figure_method="lmi")
    with pytest.raises(ValueError, match=r"SetMembershipSettings\.P0 must be a symmetric positive definite"):
        replace(sm.SETTINGS, P0=((1.0, 0.0), (0.0, -1.0)))
    with pytest.raises(ValueError, match=r"SetMembershipSettings\.pinning must have one row per agent"):
        replace(sm.SETTINGS, pinning=(1.0, 0.0))
    with pytest.raises(TypeError, match="scenario must be a SetMembershipSettings"):
        sm.draw(1, 2, scenario="scenario")


def test_compare_refuses_bad_settings_cells_and_tables():
    with pytest.raises(ValueError, match=r"BenchmarkSettings\.n_steps must be an integer (>= 1|in \[1, )"):
        compare.simulate_team("local", 4, 0, runs=3, settings=replace(compare.SETTINGS, n_steps=-1))
    with pytest.raises(ValueError, match=r"BenchmarkSettings\.init_pos must be a finite number in \[0, 1e\+06\] m"):
        replace(compare.SETTINGS, init_pos=1e300)  # used to give an RMSE of 0
    with pytest.raises(ValueError, match=r"BenchmarkSettings\.steady_from must be a step before n_steps"):
        replace(compare.SETTINGS, n_steps=50)
    cell = {"task": "team", "method": "song-eb", "n_agents": -8, "noise": "gaussian", "dropout": 0.0, "q_scale": 1.0}
    with pytest.raises(ValueError, match=r"cell\['n_agents'\] must be an integer >= 3"):
        compare.cell_cost(cell)  # used to return 4096
    with pytest.raises(TypeError, match=r"cell\['n_agents'\] must be an integer"):
        compare.run_cell({**cell, "n_agents": 4.5})
    with pytest.raises(ValueError, match=r"cell\['method'\]"):
        compare.cell_cost({**cell, "n_agents": 4, "method": "kalman"})
    with pytest.raises(TypeError, match="table must be a pandas DataFrame"):
        compare.summarize(None)  # used to raise AttributeError
    with pytest.raises(ValueError, match="table lacks the columns"):
        compare.summarize(pd.DataFrame({"task": ["team"]}))
    with pytest.raises(TypeError, match="settings must be a BenchmarkSettings"):
        compare.simulate_team("local", 4, 0, runs=3, settings="settings")


def test_ledger_refuses_bad_claims_and_digits_by_name():
    with pytest.raises(TypeError, match="labels must be a sequence of strings"):
        Claim("ren2005/x", "Fig. 1", "A number.", 1.0, 1.0, {"abs": 1}, labels=5)  # was 'int is not iterable'
    with pytest.raises(TypeError, match="where must be a string"):
        Claim("ren2005/x", 1, "A number.", 1.0, 1.0, {"abs": 1})
    with pytest.raises(TypeError, match=r"tolerance\['abs'\] must be a finite number"):
        Claim("ren2005/x", "Fig. 1", "A number.", 1.0, 1.0, {"abs": "1"})
    with pytest.raises(TypeError, match="paper_value must be a number"):
        Claim("ren2005/x", "Fig. 1", "A number.", "1", 1.0, {"abs": 1})
    with pytest.raises(TypeError, match="tolerance must be a dict"):
        Claim("ren2005/x", "Fig. 1", "A number.", 1.0, 1.0, 0.1)
    assert Claim("ren2005/x", "Fig. 1", "A number.", [1.0, 2], [1, 2.0], {"rel": 0.1}).verdict == "reproduces"
    with pytest.raises(TypeError, match="digits must be an integer >= 1"):
        format_number(1.0, digits=2.5)  # used to fail inside a format string
    with pytest.raises(ValueError, match="digits must be an integer >= 1"):
        format_number(1.0, digits=-1)  # used to be accepted
    with pytest.raises(TypeError, match="x must be a real number"):
        format_number("1.0")
    assert format_number(np.float64(0.076812)) == "0.07681"


def test_compare_and_ledger_helpers_name_their_arguments(tmp_path):
    from mascore import ledger, report
    from mascore.registry import all_figures, paper_registry, write_study

    with pytest.raises(ValueError, match="degree"):
        compare.floats_per_step("centralized", 8, degree=np.nan)
    with pytest.raises(ValueError, match="seed"):
        compare.simulate_team("local", 4, -1, runs=2)
    with pytest.raises(ValueError, match="seed"):
        compare.simulate_shared("no-fusion", 4, -1, runs=2)
    claim = Claim("vlahakis/a", "w", "s", 2.0, 2.0, {"abs": 0.1})
    with pytest.raises(ValueError, match="seed"):
        ledger.write_claims([claim], tmp_path / "claims.json", "vlahakis", -1, "cmd")
    with pytest.raises(TypeError, match="claims must be a sequence of Claim"):
        ledger.write_claims(["a"], tmp_path / "claims.json", "vlahakis", 1, "cmd")
    with pytest.raises(TypeError, match="digits"):
        ledger.format_value(1.5, digits=2.5)
    with pytest.raises(ValueError, match="max_items"):
        ledger.format_value([1.0, 2.0], max_items=0)
    with pytest.raises(ValueError, match="key 3"):
        paper_registry(3)
    with pytest.raises(TypeError, match="papers must be a sequence"):
        all_figures("ren2005")
    with pytest.raises(TypeError, match="paper must be a PaperRegistry"):
        write_study("ren2005", ren.STUDY, None, tmp_path)
    with pytest.raises(TypeError, match="records must be a sequence"):
        report.verdict_summary(None)
    with pytest.raises(ValueError, match=r"records\[0\]\['verdict'\]"):
        report.attention_list([{"paper": "ren2005", "verdict": "maybe", "where": "w", "statement": "s"}])
    with pytest.raises(TypeError, match="papers must be a sequence"):
        report.errata_list("ren2005")


def test_rendezvous_setup_checks_itself():
    s = rdv.setup()
    with pytest.raises(ValueError, match=r"RendezvousSetup\.box"):
        dataclasses.replace(s, box=-400.0)
    with pytest.raises(ValueError, match=r"RendezvousSetup\.A must have shape \(4, 4\)"):
        dataclasses.replace(s, A=np.eye(3))
    with pytest.raises(ValueError, match=r"RendezvousSetup\.K contains NaN"):
        dataclasses.replace(s, K=np.full((2, 4), np.nan))


def test_disturbance_setting_checks_itself():
    row = sm.SETTINGS.rows[0]
    with pytest.raises(ValueError, match=r"DisturbanceSetting\.q must be a finite number > 0"):
        dataclasses.replace(row, q=-0.1)
    with pytest.raises(ValueError, match=r"DisturbanceSetting\.alpha_w"):
        dataclasses.replace(row, alpha_w=np.nan)
