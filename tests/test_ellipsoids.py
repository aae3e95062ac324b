"""Tests of mascore.ellipsoids: geometry identities, outer-bound guarantees, brute-force optima."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mascore import _ellipsoid_kernels as kernels
from mascore import ellipsoids as el


def random_spd(rng, n, floor=0.05):
    M = rng.standard_normal((n, n))
    return M @ M.T + floor * np.eye(n)


def test_ellipsoid_rejects_non_pd_shape():
    with pytest.raises(ValueError, match="positive definite"):
        el.Ellipsoid(np.zeros(2), np.diag([1.0, -1.0]))
    with pytest.raises(ValueError, match="center"):
        el.Ellipsoid(np.zeros(3), np.eye(2))


def test_volume_and_trace_known_values():
    """Unit disk has area pi; E(0, diag(4, 9)) has area 6 pi; unit ball in R^3 has volume 4 pi / 3."""
    assert el.Ellipsoid(np.zeros(2), np.eye(2)).volume == pytest.approx(math.pi)
    assert el.Ellipsoid(np.zeros(2), np.diag([4.0, 9.0])).volume == pytest.approx(6 * math.pi)
    assert el.volume(np.eye(3)) == pytest.approx(4 * math.pi / 3)
    assert el.Ellipsoid(np.zeros(2), np.diag([4.0, 9.0])).trace == pytest.approx(13.0)


def test_volume_rejects_indefinite_and_handles_flat():
    with pytest.raises(ValueError, match="positive semidefinite"):
        el.volume(np.diag([1.0, -1.0]))  # det < 0
    with pytest.raises(ValueError, match="positive semidefinite"):
        el.volume(-np.eye(2))  # det > 0 but negative definite
    assert el.volume(np.diag([1.0, 0.0])) == 0.0
    assert np.allclose(el.volume(np.stack([np.eye(2), 4 * np.eye(2)])), [math.pi, 4 * math.pi])


def test_samples_on_boundary_and_inside():
    rng = np.random.default_rng(0)
    P = random_spd(rng, 3)
    E = el.Ellipsoid(np.array([1.0, -2.0, 0.5]), P)
    b = E.sample_boundary(rng, 500)
    assert np.allclose(el.mahalanobis_sq(b, E.center, E.shape), 1.0)
    inner = E.sample_interior(rng, 2000)
    q = el.mahalanobis_sq(inner, E.center, E.shape)
    assert np.all(q <= 1.0 + 1e-12)
    # uniform in volume: P(q <= s^2) = s^3 in R^3
    assert np.mean(q <= 0.25) == pytest.approx(0.5**3, abs=0.03)
    assert not E.contains(E.center + 1.01 * (b[0] - E.center))


def test_sampling_is_reproducible():
    P = np.diag([2.0, 0.5])
    a = el.sample_boundary(np.random.default_rng(3), [0, 0], P, 10)
    b = el.sample_boundary(np.random.default_rng(3), [0, 0], P, 10)
    assert np.array_equal(a, b)


def test_affine_image_maps_boundary_to_boundary():
    rng = np.random.default_rng(1)
    E = el.Ellipsoid(rng.standard_normal(3), random_spd(rng, 3))
    M = rng.standard_normal((3, 3))
    b = rng.standard_normal(3)
    img = E.affine_image(M, b)
    pts = E.sample_boundary(rng, 200) @ M.T + b
    assert np.allclose(el.mahalanobis_sq(pts, img.center, img.shape), 1.0)


def test_minkowski_min_trace_closed_form_matches_grid():
    rng = np.random.default_rng(2)
    P1, P2 = random_spd(rng, 3), random_spd(rng, 3)
    _, P, beta = el.minkowski_sum_min_trace(np.zeros(3), P1, np.zeros(3), P2)
    grid = np.linspace(1e-4, 1 - 1e-4, 20001)
    traces = np.trace(P1) / (1 - grid) + np.trace(P2) / grid
    assert np.trace(P) == pytest.approx(traces.min(), rel=1e-7)
    assert np.trace(P) == pytest.approx((np.sqrt(np.trace(P1)) + np.sqrt(np.trace(P2))) ** 2)
    _, Pb = el.minkowski_sum(np.zeros(3), P1, np.zeros(3), P2, beta)
    assert np.allclose(P, Pb)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 4))
def test_minkowski_sum_contains_true_sum(seed, n):
    """Every p1 + p2 with p1 in E1, p2 in E2 (boundary points: the hardest) lies in the outer ellipsoid."""
    rng = np.random.default_rng(seed)
    E1 = el.Ellipsoid(rng.standard_normal(n), random_spd(rng, n))
    E2 = el.Ellipsoid(rng.standard_normal(n), random_spd(rng, n))
    S = E1 + E2
    pts = E1.sample_boundary(rng, 300) + E2.sample_boundary(rng, 300)
    assert np.all(S.contains(pts, rtol=1e-9))


def test_minkowski_sum_degenerate_second_term():
    P1 = np.eye(2)
    _, P, beta = el.minkowski_sum_min_trace(np.zeros(2), P1, np.zeros(2), np.zeros((2, 2)))
    assert np.allclose(P, P1) and beta == 0


def _family_traces(c, P, C, y, W, shrink):
    ts = np.linspace(1e-4, 1 - 1e-4, 20001)
    n, p = c.size, y.size
    _, Ps, _ = el.intersection_gain_form(np.broadcast_to(c, (ts.size, n)), np.broadcast_to(P, (ts.size, n, n)),
                                         C, np.broadcast_to(y, (ts.size, p)), W, ts, shrink=shrink)
    return el.trace(Ps)


@pytest.mark.parametrize("n,p", [(2, 1), (3, 1), (3, 2), (4, 3)])
@pytest.mark.parametrize("shrink", [False, True])
def test_intersection_min_trace_matches_grid(n, p, shrink):
    rng = np.random.default_rng(10 * n + p)
    P = random_spd(rng, n)
    C = rng.standard_normal((p, n))
    W = random_spd(rng, p, 0.2)
    c = rng.standard_normal(n)
    y = C @ c + 0.2 * rng.standard_normal(p)
    _, Pm, _, _ = el.intersection_min_trace(c, P, C, y, W, shrink=shrink)
    assert np.trace(Pm) == pytest.approx(_family_traces(c, P, C, y, W, shrink).min(), rel=1e-6)
    assert np.trace(Pm) <= _family_traces(c, P, C, y, W, shrink).min() * (1 + 1e-9)


def test_one_measurement_closed_form_matches_newton_search():
    """The analytic t* for p = 1 against the general eigen-profile Newton search (two computations)."""
    rng = np.random.default_rng(4)
    for _ in range(50):
        n = int(rng.integers(2, 6))
        P = random_spd(rng, n)
        C = rng.standard_normal((1, n))
        W = np.array([[rng.uniform(0.01, 3.0)]])
        c = rng.standard_normal(n)
        _, Pa, _, _ = el.intersection_min_trace(c, P, C, C @ c, W)
        h, m = kernels.trace_profile(P, C, W)
        t = kernels.newton_trace(h, m, 1e-13, 100)
        assert np.trace(Pa) == pytest.approx(np.sum(h / (1 + t * (m - 1))), rel=1e-9)


@pytest.mark.parametrize("shrink", [False, True])
def test_intersection_outer_bound_contains_true_intersection(shrink):
    rng = np.random.default_rng(5)
    n, p = 3, 1
    prior = el.Ellipsoid(rng.standard_normal(n), random_spd(rng, n))
    C = rng.standard_normal((p, n))
    W = np.array([[0.3]])
    y = C @ prior.center + 0.4
    cands = np.concatenate([prior.sample_interior(rng, 40_000), prior.sample_boundary(rng, 20_000)])
    r = y - cands @ C.T
    inside = cands[np.einsum("ij,ij->i", r, r @ np.linalg.inv(W)) <= 1.0]
    assert inside.shape[0] > 100
    c, P, _, _ = el.intersection_min_trace(prior.center, prior.shape, C, y, W, shrink=shrink)
    assert np.all(el.contains(inside, c, P, rtol=1e-9))
    for t in (0.1, 0.5, 0.9):  # every member of the family is an outer bound
        c2, P2 = el.intersection_family(prior.center, prior.shape, C, y, W, t)
        assert np.all(el.contains(inside, c2, P2, rtol=1e-9))


def test_shrunk_member_is_tighter():
    P, C, W = np.eye(2), np.array([[1.0, 0.0]]), np.array([[0.5]])
    _, P1, _, _ = el.intersection_min_trace(np.zeros(2), P, C, np.array([0.8]), W)
    _, P2, _, _ = el.intersection_min_trace(np.zeros(2), P, C, np.array([0.8]), W, shrink=True)
    assert np.trace(P2) < np.trace(P1)


def test_empty_intersection_detection_scalar_is_the_strip_test():
    """p = 1: empty iff |y - C c| > sqrt(W) + sqrt(C P C^T) (the strip misses the projected ellipsoid)."""
    P, C, W = np.diag([4.0, 1.0]), np.array([[1.0, 0.0]]), np.array([[0.25]])
    edge = 2.0 + 0.5
    assert not el.intersection_is_empty(np.zeros(2), P, C, np.array([edge - 1e-6]), W)
    assert el.intersection_is_empty(np.zeros(2), P, C, np.array([edge + 1e-6]), W)


def test_max_innovation_form_general_matches_grid():
    rng = np.random.default_rng(6)
    n, p = 3, 2
    P, C, W = random_spd(rng, n), rng.standard_normal((p, n)), random_spd(rng, p, 0.2)
    c, y = rng.standard_normal(n), rng.standard_normal(p)
    ts = np.linspace(1e-5, 1 - 1e-5, 100001)
    nu = y - C @ c
    S = W[None] / ts[:, None, None] + (C @ P @ C.T)[None] / (1 - ts[:, None, None])
    g = np.einsum("i,kij,j->k", nu, np.linalg.inv(S), nu)
    assert el.max_innovation_form(c, P, C, y, W) == pytest.approx(g.max(), rel=1e-6)


def test_newton_trace_of_one_problem_is_the_batched_search_bit_for_bit():
    """The 1-D search of one problem (on floats) gives the batch's t exactly (a batch of that problem, as every
    agent and run of the set-membership filter share one), at the edge t -> 1 and inside."""
    from mascore._ellipsoid_kernels import newton_trace

    rng = np.random.default_rng(5)
    h = rng.uniform(0.1, 2.0, (40, 4))
    m = np.concatenate([rng.uniform(1.1, 100.0, (20, 4)), rng.uniform(0.0, 3.0, (20, 4))])  # edge, and inside
    one = np.array([newton_trace(hi, mi, 1e-13, 100) for hi, mi in zip(h, m)])
    batch = np.array([newton_trace(np.broadcast_to(hi, (3, 5, 4)), np.broadcast_to(mi, (3, 5, 4)), 1e-13, 100)
                      for hi, mi in zip(h, m)])
    assert (batch == batch[:, :1, :1]).all()
    assert one.tobytes() == batch[:, 0, 0].tobytes()
    assert (one[:20] > 1 - 1e-12).all() and (one[20:] < 1 - 1e-6).any()
