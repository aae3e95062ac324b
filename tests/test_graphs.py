"""Tests of mascore.graphs: Laplacian identities and spanning-tree detection."""

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mascore import graphs

adjacency = st.integers(2, 7).flatmap(
    lambda n: arrays(float, (n, n), elements=st.sampled_from([0.0, 0.0, 1.0, 2.5]))
).map(lambda A: A * (1 - np.eye(A.shape[0])))


@given(adjacency)
@settings(max_examples=60, deadline=None)
def test_laplacian_rows_sum_to_zero(A):
    L = graphs.laplacian(A)
    np.testing.assert_allclose(L.sum(axis=1), 0.0, atol=1e-12)
    np.testing.assert_array_equal(np.diag(L), A.sum(axis=1))


@given(adjacency)
@settings(max_examples=60, deadline=None)
def test_undirected_laplacian_is_psd(A):
    L = graphs.laplacian(A + A.T)
    assert np.linalg.eigvalsh(L).min() > -1e-10


@given(adjacency)
@settings(max_examples=80, deadline=None)
def test_spanning_tree_agrees_with_networkx(A):
    """A directed spanning tree exists iff some node reaches all others (networkx descendants)."""
    G = graphs.to_networkx(A, directed=True)
    n = A.shape[0]
    expected = [r for r in range(n) if len(nx.descendants(G, r)) == n - 1]
    np.testing.assert_array_equal(graphs.spanning_tree_roots(A), expected)
    assert graphs.has_spanning_tree(A) == bool(expected)


@given(adjacency)
@settings(max_examples=60, deadline=None)
def test_spanning_tree_iff_laplacian_rank_n_minus_1(A):
    """Ren and Beard (2005): zero is a simple eigenvalue of L iff there is a spanning tree."""
    rank = np.linalg.matrix_rank(graphs.laplacian(A), tol=1e-8)
    assert graphs.has_spanning_tree(A) == (rank == A.shape[0] - 1)


def test_directed_edge_convention():
    # 0 -> 1 -> 2: agent 0 is the only root
    A = graphs.adjacency_from_edges(3, [(0, 1), (1, 2)], directed=True)
    assert A[1, 0] == 1 and A[0, 1] == 0
    np.testing.assert_array_equal(graphs.spanning_tree_roots(A), [0])
    # two leaders (0 and 2 both only send to 1): no spanning tree
    B = graphs.adjacency_from_edges(3, [(0, 1), (2, 1)], directed=True)
    assert not graphs.has_spanning_tree(B)


@pytest.mark.parametrize("builder,n_edges", [
    (graphs.ring_graph, 6), (graphs.path_graph, 5), (graphs.complete_graph, 15), (graphs.star_graph, 5)])
def test_builders(builder, n_edges):
    A = builder(6)
    np.testing.assert_array_equal(A, A.T)
    assert A.sum() / 2 == n_edges
    assert graphs.is_connected(A)


def test_ring_laplacian_eigenvalues():
    """The cycle C_N has Laplacian eigenvalues 2 - 2 cos(2 pi k / N)."""
    N = 7
    expected = np.sort(2 - 2 * np.cos(2 * np.pi * np.arange(N) / N))
    np.testing.assert_allclose(np.linalg.eigvalsh(graphs.laplacian(graphs.ring_graph(N))), expected, atol=1e-12)


def test_proximity_graph_batched_and_symmetric():
    rng = np.random.default_rng(0)
    p = rng.uniform(0, 100, size=(4, 6, 2))
    A = graphs.proximity_graph(p, 40.0)
    assert A.shape == (4, 6, 6)
    np.testing.assert_array_equal(A, np.swapaxes(A, -1, -2))
    d = np.linalg.norm(p[2, 1] - p[2, 3])
    assert A[2, 1, 3] == float(d <= 40.0)
    np.testing.assert_array_equal(A[1], graphs.proximity_graph(p[1], 40.0))


def test_union_over_windows():
    a = graphs.adjacency_from_edges(3, [(0, 1)], directed=True)
    b = graphs.adjacency_from_edges(3, [(1, 2)], directed=True)
    assert not graphs.has_spanning_tree(a) and not graphs.has_spanning_tree(b)
    assert graphs.has_spanning_tree(graphs.graph_union([a, b]))
    unions = graphs.unions_over_windows([a, b, a, b], window=2)
    assert unions.shape == (2, 3, 3) and all(graphs.has_spanning_tree(U) for U in unions)
    with pytest.raises(ValueError, match="window"):
        graphs.unions_over_windows([a, b], window=0)
    for bad_window in (1.5, True):  # a float or a bool where a count goes is a type error
        with pytest.raises(TypeError, match="window"):
            graphs.unions_over_windows([a, b], window=bad_window)


@pytest.mark.parametrize("bad,match", [
    (np.array([[0, -1], [1, 0]]), "non-negative"),
    (np.eye(2), "zero diagonal"),
    (np.ones((2, 3)), "square"),
    (np.array([[0, np.nan], [1, 0]]), "NaN"),
])
def test_bad_adjacency_is_refused(bad, match):
    with pytest.raises(ValueError, match=match):
        graphs.laplacian(bad)


def test_bad_builder_and_range_inputs():
    with pytest.raises(ValueError, match="n_agents"):
        graphs.ring_graph(2)
    with pytest.raises(ValueError, match="sensing_range"):
        graphs.proximity_graph(np.zeros((3, 2)), -1.0)
    with pytest.raises(ValueError, match="outside"):
        graphs.adjacency_from_edges(3, [(0, 5)])
