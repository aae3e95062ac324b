"""Discrete time throughout and one notion of a system (issue 31, items 3 and 4).

Every design function takes ``(A, B)`` arrays, an :class:`~mascore.agents.LTIAgent` or a
python-control ``StateSpace``, checks the time base against what it needs, and the network
LQR and the minimum-energy observer design in discrete time as well as continuous.
"""

from __future__ import annotations

import numpy as np
import pytest

from mascore import agents, graphs, kalman, lqr, observers, sensor_network, team_model
from mascore import rendezvous as rv
from mascore import synchronization as sync

control = pytest.importorskip("control")

W = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
A_C, B_C = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])


def test_double_integrator_carries_both_time_bases():
    agent = agents.double_integrator(2, 0.05)
    A, B = agents.zoh(agent.A_c, agent.B_c, agent.dt)
    np.testing.assert_allclose(agent.A, A, atol=1e-15)
    np.testing.assert_allclose(agent.B, B, atol=1e-15)
    A_c, B_c, dt = agents.system_matrices(agent, "continuous")
    assert dt == 0.0 and np.array_equal(A_c, np.kron(A_C, np.eye(2)))


def test_one_agent_network_lqr_in_discrete_time_is_control_dlqr():
    agent = agents.double_integrator(1, 0.1)
    K_ref, S_ref, _ = control.dlqr(agent.A, agent.B, W["Q1"], W["R"])
    K, S, _ = lqr.centralized_network_lqr(agent, **W, laplacian=np.zeros((1, 1)))
    np.testing.assert_allclose(K, K_ref, rtol=1e-10)
    np.testing.assert_allclose(S, S_ref, rtol=1e-10)
    top = lqr.top_down_lqr(agent, **W, adjacency=np.zeros((1, 1)))
    np.testing.assert_allclose(top.K_self, K_ref, rtol=1e-10)
    assert lqr.centralized_network_cost(agent, **W, laplacian=np.zeros((1, 1))) == pytest.approx(np.trace(S_ref))


@pytest.mark.parametrize("N", [2, 3, 5])
def test_discrete_top_down_on_the_complete_graph_is_the_centralized_optimum(N):
    """On the complete graph, N_L = N: the top-down gain is the centralized one and so is its cost."""
    agent = agents.double_integrator(1, 0.1)
    Lap = graphs.laplacian(graphs.complete_graph(N))
    K, P, _ = lqr.centralized_network_lqr(agent, **W, laplacian=Lap)
    top = lqr.top_down_lqr(agent, **W, adjacency=graphs.complete_graph(N))
    np.testing.assert_allclose(lqr.assemble_network_gain(top, Lap), K, atol=1e-10)
    cost = lqr.network_controller_cost(agent, **W, laplacian=Lap, gain=top)
    assert cost == pytest.approx(np.trace(P), rel=1e-9)
    blocks = lqr.borrelli_keviczky_structure(agent, **W, n_agents=N)
    np.testing.assert_allclose(blocks["P_network"], P, atol=1e-9)


def test_discrete_top_down_is_the_sampled_continuous_design_in_the_limit():
    """As dt -> 0 the discrete gains approach the continuous ones (per-step weights scaled by dt)."""
    dt = 1e-3
    agent = agents.LTIAgent.from_continuous(A_C, B_C, dt)
    scaled = {k: v * dt for k, v in W.items()}
    cont = lqr.top_down_lqr(A_C, B_C, **W, adjacency=graphs.ring_graph(5))
    disc = lqr.top_down_lqr(agent, **scaled, adjacency=graphs.ring_graph(5))
    np.testing.assert_allclose(disc.K_self, cont.K_self, rtol=5e-3)
    np.testing.assert_allclose(disc.K_coupling, cont.K_coupling, rtol=5e-3, atol=1e-4)


def test_state_space_and_agent_equal_the_arrays():
    sys_c = control.ss(A_C, B_C, np.eye(2), 0)
    ring = graphs.ring_graph(4)
    ref = lqr.top_down_lqr(A_C, B_C, **W, adjacency=ring)
    for system in (sys_c, agents.LTIAgent.from_continuous(A_C, B_C, 0.1)):
        got = lqr.top_down_lqr(system, **W, adjacency=ring) if system is sys_c else \
            lqr.top_down_lqr(system.A_c, system.B_c, **W, adjacency=ring)
        np.testing.assert_array_equal(got.K_self, ref.K_self)
    sys_d = control.c2d(sys_c, 0.1)
    agent = agents.LTIAgent.from_continuous(A_C, B_C, 0.1)
    np.testing.assert_allclose(lqr.top_down_lqr(sys_d, **W, adjacency=ring).K_self,
                               lqr.top_down_lqr(agent, **W, adjacency=ring).K_self, rtol=1e-9)
    np.testing.assert_allclose(lqr.top_down_lqr(agent.A, agent.B, **W, adjacency=ring, dt=0.1).K_self,
                               lqr.top_down_lqr(agent, **W, adjacency=ring).K_self)
    bottom = lqr.bottom_up_lqr(sys_c, **W, adjacency=ring)
    assert np.allclose(bottom.K_coupling, bottom.Phi @ bottom.K_self)


def test_a_discrete_a_where_a_continuous_one_is_expected_is_refused_by_name():
    agent = agents.double_integrator(1, 0.05)
    with pytest.raises(ValueError, match=r"A is the sampled \(discrete-time\) matrix .*dt = 0.05"):
        lqr.top_down_lqr(agent.A, agent.B, **W, adjacency=graphs.ring_graph(4))
    sys_d = control.c2d(control.ss(A_C, B_C, np.eye(2), 0), 0.1)
    with pytest.raises(ValueError, match=r"sys is a discrete-time system .*bottom_up_lqr needs continuous"):
        lqr.bottom_up_lqr(sys_d, **W, adjacency=graphs.ring_graph(4))
    with pytest.raises(ValueError, match=r"dt = 0.2 contradicts the system's own time base"):
        lqr.top_down_lqr(sys_d, **W, adjacency=graphs.ring_graph(4), dt=0.2)
    with pytest.raises(ValueError, match=r"sys is a discrete-time system .*distributed_observer needs continuous"):
        observers.distributed_observer(sys_d, [[1.0, 0.0]], 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1),
                                       graphs.ring_graph(5))
    with pytest.raises(ValueError, match=r"F is a continuous-time system .*c2d"):
        kalman.LinearGaussianModel(control.ss(A_C, B_C, np.eye(2), 0), np.eye(2), [[1.0, 0.0]], [[1.0]])


def test_discrete_min_energy_observer_is_the_dual_of_control_dlqr():
    A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
    agent = agents.LTIAgent.from_continuous(A, Bbar, 0.1)
    obs = observers.min_energy_observer(agent, C, 2.0 * np.eye(1), np.eye(1))
    K, S, _ = control.dlqr(agent.A.T, C.T, agent.B @ agent.B.T, 0.5 * np.eye(1))
    np.testing.assert_allclose(obs.L, K.T, rtol=1e-9)
    np.testing.assert_allclose(obs.S, S, rtol=1e-9)
    assert np.abs(obs.E).max() < 1
    cont = observers.distributed_observer(control.ss(A, Bbar, C, 0), C, Q1=10.0 * np.eye(1), Q2=5.0 * np.eye(1),
                                          R=np.eye(1), adjacency=graphs.ring_graph(5))
    ref = observers.distributed_observer(A, Bbar, C, Q1=10.0 * np.eye(1), Q2=5.0 * np.eye(1), R=np.eye(1),
                                         adjacency=graphs.ring_graph(5))
    np.testing.assert_array_equal(cont.Phi, ref.Phi)


def test_design_synchronization_takes_a_sampled_state_space():
    A, B, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2)
    ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)
    pin = np.array([1.0, 0.0, 0.0, 0.0])
    ref = sync.design_synchronization(A, B, Q, ring, pin)
    sys_d = control.ss(A, B, np.eye(2), 0, 1.0)
    np.testing.assert_array_equal(sync.design_synchronization(sys_d, Q, ring, pin).K, ref.K)
    np.testing.assert_array_equal(sync.design_synchronization(agents.LTIAgent(A, B), Q, ring, pin).K, ref.K)
    with pytest.raises(ValueError, match=r"A is a continuous-time system .*c2d"):
        sync.design_synchronization(control.ss(A, B, np.eye(2), 0), Q, ring, pin)
    with pytest.raises(TypeError, match=r"^Q must be an array of real numbers; got a StateSpace .*\(Q = sys\.A"):
        sync.design_synchronization(A, B, sys_d, ring, pin)  # the system where a matrix belongs: say how to get one


def test_filter_models_take_a_system():
    agent = agents.double_integrator(1, 0.1)
    gain = rv.rendezvous_gain(0.5, 1.5, 1)
    a = team_model.team_filter_model(agent, gain, np.eye(2), np.eye(2), 3)
    b = team_model.team_filter_model(agent.A, agent.B, gain, np.eye(2), np.eye(2), 3)
    np.testing.assert_array_equal(a.A, b.A)
    model = kalman.LinearGaussianModel(agent, 0.01 * np.eye(2), [[1.0, 0.0]], [[1.0]])
    np.testing.assert_array_equal(model.B, agent.B)
    net = sensor_network.SensorNetworkModel(agent, 0.01 * np.eye(2), [np.eye(2)] * 3, [np.eye(2)] * 3, graphs.ring_graph(3))
    np.testing.assert_array_equal(net.F, agent.A)
    K1, _, _ = lqr.lqr(agent, np.eye(2), np.eye(1))  # a sampled agent: python-control's lqr -> dlqr
    np.testing.assert_allclose(K1, control.dlqr(agent.A, agent.B, np.eye(2), np.eye(1))[0], rtol=1e-10)


def _plain_sampled_oscillator():
    """A lightly damped oscillator sampled by python-control: plain arrays, no trace of its dt."""
    sys_d = control.c2d(control.ss([[0.0, 1.0], [-4.0, -0.1]], [[0.0], [1.0]], [[1.0, 0.0]], 0.0), 0.05)
    return np.asarray(sys_d.A), np.asarray(sys_d.B)


def _designs_reading_continuous_time(A, B):
    """Every design function that reads an array A without dt as continuous time, and can design in discrete time."""
    ring = graphs.ring_graph(4)
    Lap = graphs.laplacian(ring)
    gain = lqr.DistributedGain(np.zeros((1, 2)), np.zeros((1, 2)))
    return {"top_down_lqr": lambda **k: lqr.top_down_lqr(A, B, **W, adjacency=ring, **k),
            "centralized_network_lqr": lambda **k: lqr.centralized_network_lqr(A, B, **W, laplacian=Lap, **k),
            "borrelli_keviczky_structure": lambda **k: lqr.borrelli_keviczky_structure(A, B, **W, n_agents=3, **k),
            "centralized_network_cost": lambda **k: lqr.centralized_network_cost(A, B, **W, laplacian=Lap, **k),
            "network_controller_cost": lambda **k: lqr.network_controller_cost(A, B, **W, laplacian=Lap, gain=gain,
                                                                                **k),
            "min_energy_observer": lambda **k: observers.min_energy_observer(A, B, [[1.0, 0.0]], [[1.0]], [[1.0]],
                                                                             **k)}


def test_a_plain_discrete_A_without_dt_is_refused_where_continuous_time_is_read():
    ring = graphs.ring_graph(4)
    for A, B in (_plain_sampled_oscillator(), (np.array([[1.0, 0.05], [0.0, 1.0]]), np.array([[0.0], [0.05]]))):
        for name, call in _designs_reading_continuous_time(A, B).items():
            with pytest.raises(ValueError, match=rf"A looks like a sampled \(discrete-time\) matrix.*{name} reads an "
                                                 r"array A without dt as continuous time\. Pass dt=.*dt=0"):
                call()
            call(dt=0.05)  # the discrete-time design, as asked
    for call in (lambda: observers.distributed_observer(*_plain_sampled_oscillator(), [[1.0, 0.0]], [[1.0]], [[1.0]],
                                                          [[1.0]], ring),
                 lambda: lqr.bottom_up_lqr(*_plain_sampled_oscillator(), **W, adjacency=ring)):  # continuous only
        with pytest.raises(ValueError, match=r"_(observer|lqr) reads an array A.*continuous-time \(A_c, B.*logm.*dt=0"):
            call()


def test_dt_0_says_continuous_time_and_is_the_default_reading():
    ring = graphs.ring_graph(4)
    for A in (A_C, np.array([[0.0, 1.0], [-4.0, -0.1]])):  # not refused: a mode with Re s <= 0
        default = lqr.top_down_lqr(A, B_C, **W, adjacency=ring)
        said = lqr.top_down_lqr(A, B_C, **W, adjacency=ring, dt=0)
        assert default.K_self.tobytes() == said.K_self.tobytes()
        assert said.spectral_abscissa == default.spectral_abscissa
    unstable = np.array([[0.5, 1.0], [0.0, 0.2]])  # continuous time, every mode unstable: refused unless said
    with pytest.raises(ValueError, match=r"every eigenvalue has a positive real part \(0\.2\+0j, 0\.5\+0j\)"):
        lqr.centralized_network_lqr(unstable, B_C, **W, laplacian=graphs.laplacian(ring))
    K, _, _ = lqr.centralized_network_lqr(unstable, B_C, **W, laplacian=graphs.laplacian(ring), dt=0)
    closed = np.kron(np.eye(4), unstable) - np.kron(np.eye(4), B_C) @ K
    assert np.linalg.eigvals(closed).real.max() < 0  # the continuous-time design, stabilizing
    sys_c = control.ss(A_C, B_C, np.eye(2), 0.0)
    assert lqr.top_down_lqr(sys_c, **W, adjacency=ring, dt=0).K_self.tobytes() == \
        lqr.top_down_lqr(sys_c, **W, adjacency=ring).K_self.tobytes()
    with pytest.raises(ValueError, match=r"contradicts the system's own time base"):
        lqr.top_down_lqr(agents.double_integrator(1, 0.1), **W, adjacency=ring, dt=0)
    with pytest.raises(ValueError, match=r"continuous time only"):
        observers.distributed_observer(A_C, B_C, [[1.0, 0.0]], [[1.0]], [[1.0]], [[1.0]], ring, dt=0.1)


def test_the_rendezvous_model_takes_a_discrete_state_space_as_its_agent():
    """The filters' model constructors take a python-control system like the design functions (a new user's
    `from_agent(sys)` was refused with a TypeError that named only LTIAgent)."""
    agent = agents.double_integrator(2, 0.05)
    K = rv.rendezvous_gain(0.5, 1.0, 2)
    ref = rv.RendezvousModel.from_agent(agent, K, 1e-4 * np.eye(4), 0.04 * np.eye(4))
    sys_d = control.ss(agent.A, agent.B, np.eye(4), 0, 0.05)
    model = rv.RendezvousModel.from_agent(sys_d, K, 1e-4 * np.eye(4), 0.04 * np.eye(4))
    np.testing.assert_array_equal(model.A, ref.A)
    assert model.dt == ref.dt == 0.05
    with pytest.raises(ValueError, match=r"contradicts the agent's sampling time"):
        rv.RendezvousModel.from_agent(sys_d, K, 1e-4 * np.eye(4), 0.04 * np.eye(4), dt=0.1)
    with pytest.raises(ValueError, match=r"continuous-time system .*c2d"):
        rv.RendezvousModel.from_agent(control.ss(agent.A_c, agent.B_c, np.eye(4), 0), K, np.eye(4), np.eye(4))
    with pytest.raises(TypeError, match=r"LTIAgent or a discrete-time python-control StateSpace; got str"):
        rv.RendezvousModel.from_agent("agent", K, np.eye(4), np.eye(4))
