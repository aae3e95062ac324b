"""Issue 31 item 7, second probe: the public methods added for the links and the per-step sensing.

The consensus filters' message and pair methods (what :mod:`mascore.fusion_links` calls per step),
``SensorNetworkModel.information_vectors``, ``LinearGaussianModel.with_measurement`` and
``agent_inputs`` returned NaN, or took an infinite covariance as zero information, or failed deep
inside numpy. One test per class of finding: a NaN, an infinite covariance, an indefinite or
singular matrix, a wrong shape; each refused by name, before any work. Then the findings of the whole
probe run after those fixes (modules it had not covered, public names added since the last full probe).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from mascore import compare, fusion, fusion_forwarding, fusion_links, graphs, kalman, noise, sensor_network
from mascore.consensus_filters import KalmanConsensusFilter

N, n = 3, 2
MODEL = sensor_network.SensorNetworkModel(np.eye(n), 0.1 * np.eye(n), [np.eye(n)] * N, [np.eye(n)] * N,
                                          graphs.ring_graph(N))
CI = fusion.ConsensusOnInformationFilter(MODEL, 1)
HCMCI = fusion.ConsensusOnInformationFilter(MODEL, 1, novelty_weight="N")
ICF = fusion.InformationConsensusFilter(MODEL, 1)
KF = kalman.LinearGaussianModel(np.eye(n), 0.1 * np.eye(n), [[1.0, 0.0]], [[1.0]])
KCF, KCF_G = KalmanConsensusFilter(0.0, 0.0), np.stack([graphs.path_graph(3)] * 5)


def _state():
    return np.zeros((N, n)), np.stack([np.eye(n)] * N), np.ones(N * n)


def _spoiled(arg, value):
    x, P, z = _state()
    {"x": x, "P": P, "z": z}[arg].flat[0] = value
    return x, P, z


MESSAGES = [CI.message_pair, CI.message_pairs, HCMCI.message_pairs, ICF.message_pair, ICF.message_pairs]


@pytest.mark.parametrize("method", MESSAGES)
@pytest.mark.parametrize("arg", ["x", "P", "z"])
def test_a_nan_in_a_message_is_refused_by_name(method, arg):
    with pytest.raises(ValueError, match=rf"^{arg} contains NaN or infinite entries"):
        method(*_spoiled(arg, np.nan))


@pytest.mark.parametrize("method", MESSAGES)
def test_an_infinite_covariance_is_not_sent_as_zero_information(method):
    x, P, z = _spoiled("P", np.inf)
    with pytest.raises(ValueError, match=r"^P contains NaN or infinite entries"):
        method(x, P, z)


@pytest.mark.parametrize("filt,names", [(CI, ("Om", "q")), (ICF, ("V", "v"))])
@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_a_non_finite_pair_is_refused_by_name(filt, names, value):
    Om, q = np.stack([np.eye(n)] * N), np.ones((N, n))
    for k, name in enumerate(names):
        pair = [Om.copy(), q.copy()]
        pair[k].flat[0] = value
        with pytest.raises(ValueError, match=rf"^{name} contains NaN or infinite entries"):
            filt.pair_estimate(*pair)
    with pytest.raises(ValueError, match=r"^pairs\[1\]\[0\] contains NaN"):
        HCMCI.pairs_estimate([(Om, q), (np.full_like(Om, value), q)])


@pytest.mark.parametrize("filt,name", [(CI, "Om"), (ICF, "V")])
def test_a_singular_information_matrix_is_refused_by_name(filt, name):
    with pytest.raises(ValueError, match=rf"^{name} must be positive definite \(invertible\)"):
        filt.pair_estimate(np.zeros((N, n, n)), np.ones((N, n)))


@pytest.mark.parametrize("R,match", [
    ([[np.nan]], r"^R contains NaN"), ([[np.inf]], r"^R contains NaN"),
    ([[-1.0]], r"^R must be positive definite"), ([[0.0]], r"^R must be positive definite"),
    (np.eye(2), r"^Incompatible dimensions of R \(2, 2\) for H \(1, 2\)"),
])
def test_a_new_measurement_noise_is_checked_in_full(R, match):
    with pytest.raises(ValueError, match=match):
        KF.with_measurement([[1.0, 0.0]], R)


@pytest.mark.parametrize("H,match", [([[np.nan, 0.0]], r"^H contains NaN"), ([[np.inf, 0.0]], r"^H contains NaN"),
                                     ([[1.0, 0.0, 0.0]], r"^Incompatible dimensions of H")])
def test_a_new_measurement_matrix_is_checked_in_full(H, match):
    with pytest.raises(ValueError, match=match):
        KF.with_measurement(H, [[1.0]])


def test_no_trusted_flag_skips_the_checks():
    with pytest.raises(TypeError, match="check"):
        KF.with_measurement([[1.0, 0.0]], [[np.nan]], check=False)
    with pytest.raises(TypeError, match="check"):
        MODEL.information_vectors(np.full(N * n, np.nan), check=False)
    with pytest.raises(ValueError, match=r"^z contains NaN"):
        MODEL.information_vectors(np.full(N * n, np.nan))


def test_an_indefinite_covariance_is_refused_by_agent_inputs():
    x, P, z = _state()
    P[1] = -np.eye(n)
    with pytest.raises(ValueError, match=r"^P must be positive definite"):
        fusion.CovarianceIntersectionFilter(MODEL).agent_inputs(x, P, z, 0)
    with pytest.raises(ValueError, match=r"^P must be positive semidefinite"):
        KF.agent_inputs(np.zeros((N, n)), -np.eye(n), np.ones((N, 1)), None, 0)


@pytest.mark.parametrize("call,name", [
    (lambda: CI.pair_estimate(np.stack([np.eye(n)] * (N - 1)), np.ones((N, n))), "Om"),
    (lambda: ICF.pair_estimate(np.stack([np.eye(n)] * N), np.ones((N - 1, n))), "v"),
    (lambda: CI.pair_estimate(np.stack([np.eye(n)] * N), "q"), "q"),
    (lambda: fusion.CovarianceIntersectionFilter(MODEL).agent_inputs(np.zeros((N, n)), np.ones((1, N, n, n)),
                                                                     np.ones(N * n), 0), "P"),
    (lambda: KF.agent_inputs(np.zeros((1, n)), np.eye(n), np.ones((N, 1)), None, 1), "x"),
    (lambda: KF.agent_inputs(np.zeros((N, n)), np.ones((1, n, n)), np.ones((N, 1)), None, 1), "P"),
    (lambda: kalman.run_filter(np.zeros((1, 1, 1)), [[1.0]], np.ones((3, 1)), [[1.0]], [[0.0]], [[1.0]], [[1.0]]),
     "x0"),
    (lambda: kalman.LinearGaussianModel(np.eye(n), np.eye(n), np.ones((3, n)), np.eye(2)), "H"),
    (lambda: MODEL.information_vectors(np.ones(N * n - 1)), "z"),
])
def test_a_wrong_shape_is_refused_naming_the_argument(call, name):
    with pytest.raises((ValueError, TypeError)) as info:
        call()
    assert re.search(rf"\b{name}\b", str(info.value)), str(info.value)


def test_the_checked_methods_give_the_numbers_of_the_filters_update():
    x, P, z = _state()
    for filt in (CI, ICF):
        W = filt.round_weights
        Om, q = filt.message_pair(x, P, z)
        mixed = filt.pair_estimate(np.einsum("ij,jab->iab", W, Om), W @ q)
        for a, b in zip(mixed, filt.update(x, P, z)):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=0)


# the links' module (not probed before: it is imported by name, not listed in mascore.__all__)


@pytest.mark.parametrize("call,match", [
    (lambda: fusion_links.delivered_weights(np.full((N, N), np.nan), np.ones((N, N))), r"^W contains NaN"),
    (lambda: fusion_links.delivered_weights(CI.round_weights, np.full((N, N), np.inf)), r"^delivered contains NaN"),
    (lambda: fusion_links.track_forwarding(MODEL, np.zeros(n), np.eye(n), np.ones((2, N * n)),
                                           np.full((2, N, N), np.nan)), r"^delivered contains NaN"),
    (lambda: fusion_links.track_messages([CI] * 2, np.zeros(n), np.eye(n), np.ones((2, N * n)), send_delta="0.5"),
     r"^send_delta must be a real number"),
    (lambda: fusion_links.track_messages([CI] * 2, np.zeros(n), np.eye(n), np.ones((2, N * n)), send_delta=1e300),
     r"^send_delta must be a distance from 0 to 1e150"),
    (lambda: fusion_links.lossy_graphs(MODEL.adjacency, "0.1", 3, 0), r"^loss must be a real number"),
    (lambda: fusion_links.lossy_graphs(MODEL.adjacency, 1.0, 3, 0), r"^loss must be a probability in \[0, 1\)"),
    (lambda: fusion_links.lossy_graphs(MODEL.adjacency, 0.1, 3, None), r"^rng must be a numpy.random.Generator"),
    (lambda: fusion_links.lossy_graphs(MODEL.adjacency, 0.1, 3, -1), r"^rng must be a numpy.random.Generator"),
    (lambda: fusion_links.lossy_graphs(MODEL.adjacency, 0.1, 10**12, 0), r"^n_steps = 1000000000000 is more than"),
    (lambda: fusion_forwarding.SetMembershipForwardingFilter(MODEL).predict(*_spoiled("P", np.nan)[:2]),
     r"^P contains NaN"),
])
def test_the_links_refuse_bad_input_by_name(call, match):
    with pytest.raises((ValueError, TypeError), match=match):
        call()


def test_the_lossy_graphs_of_a_seed_and_of_its_generator_are_the_same():
    a = fusion_links.lossy_graphs(MODEL.adjacency, 0.3, 20, 4, per_direction=True, n_runs=3)
    b = fusion_links.lossy_graphs(MODEL.adjacency, 0.3, 20, np.random.default_rng(4), per_direction=True, n_runs=3)
    assert a.tobytes() == b.tobytes() and 0 < (a == 0).sum() < a.size


# the rest of the whole probe: a trusted flag of the samplers, names of a run's arguments, a task's inputs


@pytest.mark.parametrize("call,match", [
    (lambda: noise.psd_factor(np.array([[np.nan, 0.0], [0.0, 1.0]])), r"^M contains NaN"),
    (lambda: noise.psd_factor(np.array([[np.inf, 0.0], [0.0, 1.0]]), cholesky_first=True), r"^M contains NaN"),
    (lambda: noise.psd_factor(np.eye(2), check=False), r"check"),
    (lambda: noise.gaussian(np.random.default_rng(0), np.eye(2), size=10**12), r"^size asks for too much"),
    (lambda: noise.uniform_box(np.random.default_rng(0), [0.0, 0.0], [1.0, 1.0], size=10**12),
     r"^size asks for too much"),
    (lambda: KCF.fuse(np.array([[0.0], [np.nan], [4.0]]), np.ones((3, 1, 1)), KCF_G), r"^xi contains NaN"),
    (lambda: KCF.fuse(np.array([[0.0], [2.0], [4.0]]), np.ones((2, 1, 1)), KCF_G), r"^P must have shape"),
    (lambda: KCF.fuse(np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1)), KCF_G[0]), r"^G must have shape"),
    (lambda: KCF.fuse(np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1)), KCF_G + np.eye(3)),
     r"^G must have a zero diagonal"),
    (lambda: compare.team_setup(4, "gaussian", np.nan, compare.SETTINGS), r"^q_scale must be a finite number"),
    (lambda: compare.make_estimator("local", compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS),
                                    np.full((1, 4, 4), np.inf)), r"^x_hat0 contains NaN"),
    (lambda: compare.make_estimator("local", compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS),
                                    np.zeros((4, 4))), r"^x_hat0 must have shape \(R, N, n\)"),
])
def test_the_rest_of_the_api_refuses_bad_input_by_name(call, match):
    with pytest.raises((ValueError, TypeError), match=match):
        call()


def test_the_sampler_factor_is_the_checked_one_for_stacks_and_singular_matrices():
    rng = np.random.default_rng(2)
    G = rng.standard_normal((3, 2, 2))
    for M in (G @ np.swapaxes(G, -1, -2), np.outer([1.0, 2.0], [1.0, 2.0])):
        F = noise.psd_factor(M)
        np.testing.assert_allclose(F @ np.swapaxes(F, -1, -2), M, atol=1e-12)
