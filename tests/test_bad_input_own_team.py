"""Bad input met on a user's own team (issue 31, "Nothing silent in the new API").

Each finding of the hostile sweep is refused up front by name: counts checked against memory
and a step budget before any work, infinite variances in the information filters, python-control
systems with a bad ``dt``, directed graphs where Song et al. assume undirected ones, overflowing
matrices, and the weaker errors of the first hour (the argument that is wrong is the one named).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from mascore import agent_cost, agents, compare, fusion, graphs, kalman, lqr, team_model
from mascore import distributed_ekf as dekf
from mascore import distributed_kf as dk
from mascore import rendezvous as rv
from mascore import set_membership as sm
from mascore.flocking import FlockingGains

HUGE = 10**12
AGENT = agents.double_integrator(2, 0.1)
K_GAIN = rv.rendezvous_gain(0.5, 1.5, 2)


# ----------------------------------------------------------------------------- counts: memory and step budget


@pytest.mark.parametrize("call,name", [
    (lambda: compare.simulate_team("local", 4, 0, runs=1,
                                   settings=dataclasses.replace(compare.SETTINGS, n_steps=HUGE)), "n_steps"),
    (lambda: compare.simulate_team("local", 4, 0, runs=10**7), "runs"),
    (lambda: compare.node_cost("local", 4, n_steps=HUGE), "n_steps"),
    (lambda: compare.node_cost("local", 4, n_steps=10, repeats=HUGE), "repeats"),
    (lambda: compare.node_costs((4, 8), ("local",), n_steps=HUGE), "n_steps"),
    (lambda: compare.node_costs([], ("local",)), "sizes"),
    (lambda: compare.node_costs([4], ("local",)), "sizes"),
    (lambda: compare.target_model(HUGE), "n_agents"),
    (lambda: compare.localization_model(HUGE), "n_agents"),
    (lambda: agent_cost.agent_step("target", "local", HUGE), "n_agents"),
    (lambda: agent_cost.agent_step_cost("target", "local", HUGE), "n_agents"),
    (lambda: agent_cost.agent_step_cost("target", "local", 4, repeats=HUGE), "min_time|repeats"),
    (lambda: agent_cost.agent_step_cost("target", "local", 4, min_time=1e300), "min_time"),
    (lambda: compare.target_model(4).simulate(np.zeros(4), np.eye(4), 3, 0, n_runs=HUGE), "n_runs"),
    (lambda: rv.simulate_rendezvous(1, rv.RendezvousModel(AGENT.A, AGENT.B, K_GAIN, 0.1 * np.eye(4), np.eye(4), 0.1),
                                    np.zeros((1, 3, 4)), graphs.path_graph(3), HUGE, "true"), "n_steps"),
    (lambda: rv.expected_spread(rv.RendezvousModel(AGENT.A, AGENT.B, K_GAIN, 0.1 * np.eye(4), np.eye(4), 0.1),
                                np.zeros((1, 3, 4)), graphs.path_graph(3), HUGE, "true"), "n_steps"),
])
def test_huge_counts_are_refused_up_front_by_name(call, name):
    with pytest.raises(ValueError, match=name):
        call()


def test_a_huge_batch_of_runs_is_refused_before_the_filter_runs():
    model = compare.target_model(4)
    z = np.broadcast_to(np.zeros(4), (3, HUGE, 4))  # no memory: a view
    with pytest.raises(ValueError, match=r"\bz asks for too much"):
        fusion.CentralizedFilter(model).run(np.zeros(4), np.eye(4), z)


def test_slopes_need_two_sizes():
    t = pd.DataFrame({"task": "team", "method": "x", "n_agents": [4, 8], "us_per_step": [1.0, 8.0],
                      "flops": [1.0, 4.0]})
    for top in (0, 1):
        with pytest.raises(ValueError, match="top"):
            agent_cost.slopes(t, top=top)
    assert agent_cost.slopes(t, top=2).loc[("team", "x"), "slope"] == pytest.approx(3.0)


# ----------------------------------------------------------------------------- non-finite input and results


@pytest.mark.parametrize("make", [lambda m: fusion.ConsensusOnInformationFilter(m, 2),
                                  lambda m: fusion.InformationConsensusFilter(m, 2),
                                  fusion.MeasurementForwardingFilter])
def test_information_filters_refuse_an_infinite_variance(make):
    model = compare.target_model(4)
    P = np.stack([np.eye(4)] * 4)
    P[0, 0, 0] = np.inf
    with pytest.raises(ValueError, match=r"\bP contains NaN or infinite"):
        make(model).update(np.zeros((4, 4)), P, np.zeros(4))


def test_team_filter_nees_refuses_an_overflow_by_name():
    model = team_model.team_filter_model(AGENT.A, AGENT.B, K_GAIN, 0.01 * np.eye(4), np.eye(4), 3)
    filt = dk.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 12)), P0=np.eye(4))
    with pytest.raises(ValueError, match=r"X_true: the NEES overflows"):
        filt.nees(np.full((1, 3, 4), 1e300))
    assert np.all(np.isfinite(filt.nees(np.ones((1, 3, 4)))))


@pytest.mark.parametrize("field,match", [("G", r"G \(disturbance matrix\): G Q G\^T overflows"),
                                         ("D", r"D: D R D\^T overflows")])
def test_set_membership_model_refuses_overflowing_noise_maps(field, match):
    kwargs = dict(A=np.eye(2), G=np.eye(2), Q=np.eye(2), C=np.eye(2), D=np.eye(2), R=np.eye(2))
    kwargs[field] = 1e300 * np.eye(2)
    with pytest.raises(ValueError, match=match):
        sm.SetMembershipModel(**kwargs)


# ----------------------------------------------------------------------------- python-control systems


class _System:
    """A state-space object as python-control's StateSpace looks to us (A, B, dt)."""

    def __init__(self, A, B, dt):
        self.A, self.B, self.dt = np.asarray(A, float), np.asarray(B, float), dt


@pytest.mark.parametrize("dt", [-0.1, np.nan, np.inf, "0.1"])
@pytest.mark.parametrize("design", [lqr.lqr, lqr.dlqr])
def test_lqr_refuses_a_bad_sampling_time_of_sys(design, dt):
    with pytest.raises(ValueError, match=r"sys\.dt must be"):
        design(_System(np.eye(2), np.eye(2), dt), np.eye(2), np.eye(2))


def test_lqr_of_an_lti_agent_is_its_discrete_design():
    """An LTIAgent is a sampled system: lqr(agent, ...) is dlqr of its (A, B), as for a discrete StateSpace."""
    K, _, _ = lqr.lqr(AGENT, np.eye(4), np.eye(2))
    K_d, _, _ = lqr.dlqr(AGENT.A, AGENT.B, np.eye(4), np.eye(2))
    np.testing.assert_allclose(K, K_d)


def test_system_matrices_checks_the_time_base_against_the_need():
    cont = _System([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], 0)
    disc = _System(AGENT.A[:2, :2], AGENT.B[:2, :1], 0.1)
    with pytest.raises(ValueError, match=r"sys is a discrete-time system .*top_down_lqr needs continuous"):
        agents.system_matrices(disc, "continuous", needed_by="top_down_lqr")
    with pytest.raises(ValueError, match=r"sys is a continuous-time system .*c2d"):
        agents.system_matrices(cont, "discrete")
    plain = agents.LTIAgent(AGENT.A.copy() @ np.eye(4), AGENT.B)
    with pytest.raises(ValueError, match=r"LTIAgent.from_continuous"):
        agents.system_matrices(plain, "continuous")
    with pytest.raises(TypeError, match=r"sys must be an LTIAgent or a state-space system"):
        agents.system_matrices(np.eye(2))


# ----------------------------------------------------------------------------- graphs and masks


def _directed_laplacian(N=3):
    return graphs.laplacian(graphs.adjacency_from_edges(N, [(0, 1), (1, 2), (2, 0)], directed=True))


@pytest.mark.parametrize("mode", ["eb", "mb"])
def test_team_filter_refuses_a_directed_graph(mode):
    model = team_model.team_filter_model(AGENT.A, AGENT.B, K_GAIN, 0.01 * np.eye(4), np.eye(4), 3)
    with pytest.raises(ValueError, match=r"laplacian must be symmetric .*Song et al."):
        dk.TeamFilter(model, _directed_laplacian(), np.zeros((1, 12)), P0=np.eye(4), mode=mode)
    filt = dk.TeamFilter(model, graphs.laplacian(graphs.ring_graph(3)), np.zeros((1, 12)), P0=np.eye(4), mode=mode)
    with pytest.raises(ValueError, match=r"laplacian must be symmetric"):
        filt.predict(_directed_laplacian())
    if mode == "eb":
        with pytest.raises(ValueError, match=r"laplacian must be symmetric"):
            filt.f2_cross(_directed_laplacian())
        Sig = dk.eb_initial_covariance(model, np.eye(4))
        with pytest.raises(ValueError, match=r"laplacian must be symmetric"):
            dk.f2_cross(model, Sig, _directed_laplacian())


def test_flocking_ekf_step_refuses_an_agent_left_out_of_its_own_neighbourhood():
    gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
    X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])
    model = dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12))
    ekf = dekf.FlockingEKF(model, np.broadcast_to(X, (3, 3, 4)), np.eye(12))
    mask = np.ones((3, 3), bool)
    mask[1, 1] = False
    with pytest.raises(ValueError, match=r"observed must include every agent itself"):
        ekf.step(X + 0.1, mask)


# ----------------------------------------------------------------------------- the weaker errors of the first hour


def test_a_wrong_length_z_is_blamed_not_h():
    with pytest.raises(ValueError, match=r"dimensions of z; expected \(\.\.\., 2\)"):
        kalman.update(np.zeros(4), np.eye(4), np.zeros(3), np.eye(2, 4), np.eye(2))
    with pytest.raises(ValueError, match=r"dimensions of H; expected \(\.\.\., 2, 4\)"):
        kalman.update(np.zeros(4), np.eye(4), np.zeros(2), np.eye(3, 4), np.eye(2))


def _rv_model():
    return rv.RendezvousModel(AGENT.A, AGENT.B, K_GAIN, 0.01 * np.eye(4), 0.5 * np.eye(4), 0.1)


def test_x_hat0_given_per_agent_is_stacked_and_a_bad_one_names_both_forms():
    x0 = np.random.default_rng(0).normal(size=(1, 6, 4))
    A = graphs.ring_graph(6)
    per_agent = rv.simulate_rendezvous(1, _rv_model(), x0, A, 3, "estimation", x_hat0=x0[0], P0=np.eye(4))
    stacked = rv.simulate_rendezvous(1, _rv_model(), x0, A, 3, "estimation", x_hat0=x0.reshape(1, 24),
                                     P0=np.eye(4))
    np.testing.assert_array_equal(per_agent.states, stacked.states)
    with pytest.raises(ValueError, match=r"x_hat0; expected the team estimate \(1, N m\) = \(1, 24\) "
                                         r"\(or one row per agent, \(6, 4\)\)"):
        rv.simulate_rendezvous(1, _rv_model(), x0, A, 3, "estimation", x_hat0=np.zeros((5, 4)), P0=np.eye(4))


def test_the_shape_check_comes_before_the_observability_check():
    x0 = np.zeros((1, 4, 4))
    star = graphs.star_graph(4, center=0)  # a graph that fails observability (system (43))
    with pytest.raises(ValueError, match="x_hat0"):
        rv.simulate_rendezvous(1, _rv_model(), x0, star, 3, "estimation", x_hat0=np.zeros((1, 5)), P0=np.eye(4))


def test_a_dt_contradicting_an_a_from_from_continuous_is_refused():
    fast = agents.double_integrator(2, 0.05)
    with pytest.raises(ValueError, match=r"dt = 0.1 s contradicts A, which was sampled over dt = 0.05 s"):
        agents.LTIAgent(fast.A, fast.B, dt=0.1)
    assert agents.LTIAgent(fast.A, fast.B).dt == 0.05  # taken from A
    oscillator = agents.LTIAgent.from_continuous([[0.0, 1.0], [-4.0, -0.1]], [[0.0], [1.0]], 0.05)
    with pytest.raises(ValueError, match=r"dt = 0.1 s contradicts A"):
        rv.RendezvousModel(oscillator.A, oscillator.B, [[1.0, 1.0]], np.eye(2), np.eye(2), 0.1)
    rv.RendezvousModel(oscillator.A, oscillator.B, [[1.0, 1.0]], np.eye(2), np.eye(2), 0.05)  # the right dt


# ----------------------------------------------------------------------------- errors that say what to do


def test_lemma2_failure_names_the_remedy_and_scaling_q_does_not_change_r():
    from mascore import synchronization as sync

    A, B = np.array([[1.05, 0.1], [0.0, 1.0]]), np.array([[0.0], [1.0]])  # r = 0.47
    path = graphs.path_graph(4)
    pin = np.array([1.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"pin more agents.*add edges.*scaling Q does not change r"):
        sync.design_synchronization(A, B, np.eye(2), path, pin)
    P1, P10 = sync.riccati_like(A, B, np.eye(2)), sync.riccati_like(A, B, 10 * np.eye(2))
    assert sync.lemma2_r(A, B, np.eye(2), P1) == pytest.approx(sync.lemma2_r(A, B, 10 * np.eye(2), P10), rel=1e-8)
    d = sync.design_synchronization(A, B, np.eye(2), path, 3 * np.ones(4))  # pinned harder: r0/c0 = 0.35 < r
    assert d.rho < 1
    with pytest.raises(ValueError, match=r"less unstable A"):  # A unstable (1.05): a shorter sampling time helps
        sync.design_synchronization(A, B, np.eye(2), path, pin)


def test_lemma2_failure_on_a_continuous_time_a_says_to_sample_it_and_on_a_stable_a_not_to_make_it_less_unstable():
    from mascore import synchronization as sync

    A_c, B = np.array([[0.0, 1.0], [-4.0, -0.2]]), np.array([[0.0], [1.0]])  # a damped oscillator, not sampled
    path, pin = graphs.path_graph(4), np.array([1.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"negative real part outside the unit circle .* sample it first") as info:
        sync.design_synchronization(A_c, B, np.eye(2), path, pin)
    assert "less unstable" not in str(info.value)
    sampled = agents.LTIAgent.from_continuous(A_c, B, 0.05)  # |eigenvalues| 0.995: stable, nothing to make less so
    with pytest.raises(ValueError, match=r"scaling Q does not change r \(P scales with it\)$"):
        sync.design_synchronization(sampled.A, sampled.B, np.eye(2), graphs.path_graph(6), np.eye(6)[0])


def test_dask_without_a_main_guard_is_explained_in_one_line(tmp_path):
    """run_sweep and reproduce_paper (both start their workers by sweep.dask_client), in one script without a
    main guard: each says so in one line, and reproduce_paper writes nothing."""
    pytest.importorskip("distributed")
    import os
    import subprocess
    import sys

    script = tmp_path / "my_sweep.py"
    script.write_text(  # a worker process imports it (as __mp_main__) and stops at its first call, as it would
        "import sys\n"
        "from mascore import sweep\n"
        "try:\n"
        f"    sweep.run_sweep([{{'scale': 1.0, 'block': 0}}], sweep.demo_task, {str(tmp_path / 'sweep')!r}, workers=1,\n"
        "                    progress=False)\n"
        "except RuntimeError as exc:\n"
        "    if __name__ != '__main__':\n"
        "        raise\n"
        "    print('run_sweep:', exc, file=sys.stderr)\n"
        "from mascore.reproduce import reproduce_paper\n"
        f"reproduce_paper('ren2005', {str(tmp_path / 'out')!r}, workers=1, progress=False)\n")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    lines = done.stderr.strip().splitlines()
    said = [line for line in lines if line.startswith("run_sweep: ")]
    assert len(said) == 1 and said[0].startswith("run_sweep: local Dask workers could not start"), lines[-20:]
    assert '__name__ == "__main__"' in said[0]
    last = lines[-1]  # reproduce_paper's error, uncaught
    assert done.returncode != 0 and not (tmp_path / "out" / "ren2005").exists()
    assert last.startswith("RuntimeError: local Dask workers could not start") and '__name__ == "__main__"' in last


def test_partial_sensing_for_songs_filters_names_the_methods_that_take_it():
    agent = agents.double_integrator(2, 0.1)
    for call in (lambda: rv.RendezvousModel(agent.A, agent.B, K_GAIN, np.eye(4), 0.01 * np.eye(2), 0.1),
                 lambda: team_model.team_filter_model(agent, K_GAIN, np.eye(4), 0.01 * np.eye(2), 3)):
        with pytest.raises(ValueError, match=r"got \(2, 2\)\. .*team_filter_model\(\.\.\., C=C\).*song-eb.*"
                                             r"POSITION_METHODS .*sensor_network.SensorNetworkModel"):
            call()
