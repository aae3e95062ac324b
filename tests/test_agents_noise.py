"""Tests of mascore.agents and mascore.noise."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from mascore import agents, noise


def test_double_integrator_is_exact_discretization():
    """A, B equal the zero-order-hold discretization of p'' = u (matrix exponential)."""
    n, dt = 2, 0.1
    model = agents.double_integrator(n, dt)
    Ac = np.block([[np.zeros((n, n)), np.eye(n)], [np.zeros((n, n)), np.zeros((n, n))]])
    Bc = np.vstack([np.zeros((n, n)), np.eye(n)])
    big = expm(np.block([[Ac, Bc], [np.zeros((n, 3 * n))]]) * dt)
    np.testing.assert_allclose(model.A, big[: 2 * n, : 2 * n], atol=1e-14)
    np.testing.assert_allclose(model.B, big[: 2 * n, 2 * n :], atol=1e-14)


def test_team_stacking_matches_per_agent_steps():
    rng = np.random.default_rng(0)
    model = agents.double_integrator(2, 0.2)
    x, u = rng.standard_normal((5, 4)), rng.standard_normal((5, 2))
    team = model.team(5)
    X_next = team.step(agents.team_state(x), agents.team_state(u))
    np.testing.assert_allclose(agents.agent_states(X_next, 4), model.step(x, u), atol=1e-14)


def test_bad_agent_inputs():
    with pytest.raises(ValueError, match="dt"):
        agents.double_integrator(2, 0.0)
    with pytest.raises(ValueError, match="B"):
        agents.LTIAgent(np.eye(2), np.ones((3, 1)))
    with pytest.raises(ValueError, match="multiple"):
        agents.agent_states(np.zeros(7), 2)


def test_same_seed_same_numbers():
    a = noise.gaussian(np.random.default_rng(7), np.eye(3), 10)
    b = noise.gaussian(np.random.default_rng(7), np.eye(3), 10)
    assert a.tobytes() == b.tobytes()


def test_gaussian_sample_covariance():
    cov = np.array([[2.0, 0.6], [0.6, 1.0]])
    x = noise.gaussian(np.random.default_rng(1), cov, 200_000)
    np.testing.assert_allclose(np.cov(x.T), cov, atol=0.03)


def test_uniform_box_bounds_and_mean():
    x = noise.uniform_box(np.random.default_rng(2), [-1, 0], [1, 4], 50_000)
    assert x.shape == (50_000, 2)
    assert np.all(x >= [-1, 0]) and np.all(x <= [1, 4])
    np.testing.assert_allclose(x.mean(axis=0), [0, 2], atol=0.03)


def test_uniform_ellipsoid_inside_and_fills_it():
    P = np.array([[4.0, 1.0], [1.0, 2.0]])
    c = np.array([1.0, -1.0])
    x = noise.uniform_ellipsoid(np.random.default_rng(3), c, P, 40_000)
    d = x - c
    r2 = np.einsum("ni,ij,nj->n", d, np.linalg.inv(P), d)
    assert r2.max() <= 1 + 1e-12
    # uniform in the ellipsoid: the squared normalized radius is Beta(n/2, 1), mean n/(n+2) = 1/2 in 2-D
    assert abs(r2.mean() - 0.5) < 0.01


def test_noise_requires_generator():
    with pytest.raises(TypeError, match="rng"):
        noise.gaussian(None, np.eye(2))
    with pytest.raises(ValueError, match="positive semidefinite"):
        noise.gaussian(np.random.default_rng(0), -np.eye(2))
    with pytest.raises(ValueError, match="high"):
        noise.uniform_box(np.random.default_rng(0), [1.0], [0.0])


@given(st.integers(1, 4), st.integers(0, 2**31 - 1))
@settings(max_examples=40, deadline=None)
def test_uniform_ellipsoid_samples_stay_inside_any_ellipsoid(dim, seed):
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((dim, dim))
    P = M @ M.T + 1e-3 * np.eye(dim)
    c = rng.standard_normal(dim)
    x = noise.uniform_ellipsoid(rng, c, P, 500)
    d = x - c
    assert np.einsum("ni,ij,nj->n", d, np.linalg.inv(P), d).max() <= 1 + 1e-9


@pytest.mark.parametrize("cholesky_first", [False, True])
def test_psd_factor_reconstructs_definite_singular_and_stacked_matrices(cholesky_first):
    rng = np.random.default_rng(5)
    G = rng.standard_normal((4, 3, 3))
    definite = G @ G.transpose(0, 2, 1) + 0.1 * np.eye(3)
    singular = np.outer([1.0, 2.0, 0.5], [1.0, 2.0, 0.5])
    for M in (definite, definite[0], singular):
        F = noise.psd_factor(M, cholesky_first=cholesky_first)
        np.testing.assert_allclose(F @ np.swapaxes(F, -1, -2), M, atol=1e-12)
    # positive definite + cholesky_first: the lower-triangular Cholesky factor
    F = noise.psd_factor(definite[0], cholesky_first=True)
    np.testing.assert_array_equal(F, np.tril(F))
