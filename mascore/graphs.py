"""Graphs of interacting agents: adjacency, Laplacians and connectivity.

Convention used throughout mascore: for an adjacency matrix ``A`` of shape
``(N, N)``, ``A[i, j] > 0`` means that agent ``i`` *receives* information from
agent ``j`` (the directed edge ``j -> i``). An undirected graph has a symmetric
``A``. The (in-degree) Laplacian is ``L = diag(A @ 1) - A``; its rows sum to
zero. This is the convention of Ren, Beard and Kingston (2005) and of most of
the consensus literature.

networkx graphs: every mascore argument that expects an adjacency matrix (here and in
every other module) also accepts a networkx graph, read by :func:`from_networkx` (node
``i`` of ``sorted(G.nodes)`` is agent ``i``; an edge ``j -> i`` with weight ``w`` gives
``A[i, j] = w``; an undirected edge both entries); a list of graphs is read as a stack.
So the networkx generators (``nx.erdos_renyi_graph``, ``nx.random_regular_graph``,
``nx.connected_watts_strogatz_graph``, ...) give random graphs directly;
:func:`to_networkx` goes the other way.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ._validation import check_adjacency, check_fits_in_memory, check_laplacian, check_positive, check_positive_int
from ._validation import float_array as _float_array

if TYPE_CHECKING:
    import networkx as nx

__all__ = [
    "adjacency_from_edges",
    "complete_graph",
    "connected_components",
    "from_networkx",
    "graph_union",
    "has_spanning_tree",
    "is_connected",
    "laplacian",
    "laplacian_spectrum",
    "path_graph",
    "proximity_graph",
    "require_connected",
    "ring_graph",
    "spanning_tree_roots",
    "star_graph",
    "to_networkx",
    "unions_over_windows",
]


def adjacency_from_edges(
    n_agents: int,
    edges: Iterable[tuple[int, int]] | Iterable[tuple[int, int, float]],
    directed: bool = False,
) -> np.ndarray:
    """Build an adjacency matrix from an edge list.

    Parameters
    ----------
    n_agents : int
        Number of agents N.
    edges : iterable of (j, i) or (j, i, weight)
        Edge ``j -> i`` (agent ``i`` hears agent ``j``), optionally weighted.
    directed : bool
        If False every edge is added in both directions.

    Returns
    -------
    A : (N, N) ndarray
        Weighted adjacency matrix with zero diagonal, ``A[i, j]`` the weight of ``j -> i``.

    Raises
    ------
    ValueError
        An agent index outside ``0..N-1``, a self-loop or a non-positive weight.

    Examples
    --------
    >>> from mascore import graphs
    >>> graphs.adjacency_from_edges(3, [(0, 1), (1, 2, 0.5)], directed=True)
    array([[0. , 0. , 0. ],
           [1. , 0. , 0. ],
           [0. , 0.5, 0. ]])
    """
    n_agents = _check_n(n_agents)
    if isinstance(edges, (str, bytes)):
        raise TypeError(f"edges must be an iterable of (j, i) or (j, i, weight) tuples; got {edges!r}")
    try:
        edge_list = list(edges)
    except TypeError:
        raise TypeError(
            f"edges must be an iterable of (j, i) or (j, i, weight) tuples; got {type(edges).__name__}"
        ) from None
    A = np.zeros((n_agents, n_agents))
    for edge in edge_list:
        if isinstance(edge, (str, bytes)) or not hasattr(edge, "__len__") or len(edge) not in (2, 3):
            raise ValueError(f"edges must hold (j, i) or (j, i, weight) tuples; got {edge!r}")
        for end in edge[:2]:
            if isinstance(end, bool) or not isinstance(end, (int, np.integer)):
                raise TypeError(f"edges must name agents by integer index; edge {edge!r} holds {end!r}")
        j, i = int(edge[0]), int(edge[1])
        if len(edge) == 3:
            w = edge[2]
            if isinstance(w, bool) or not isinstance(w, (int, float, np.integer, np.floating)):
                raise TypeError(f"edges: the weight of edge {edge!r} must be a real number; got {w!r}")
            w = float(w)
        else:
            w = 1.0
        if not (0 <= i < n_agents and 0 <= j < n_agents):
            raise ValueError(f"edges: edge {edge!r} names an agent outside 0..{n_agents - 1}")
        if i == j:
            raise ValueError(f"edges: edge {edge!r} is a self-loop; adjacency has a zero diagonal")
        if not np.isfinite(w) or w <= 0:
            raise ValueError(f"edges: edge {edge!r} must have a finite positive weight")
        A[i, j] = w
        if not directed:
            A[j, i] = w
    return A


def laplacian(A: ArrayLike) -> np.ndarray:
    """Graph Laplacian ``L = diag(A 1) - A`` (in-degree for directed graphs).

    The one Laplacian builder of the package: every module that needs ``L`` calls it.

    Parameters
    ----------
    A : (N, N) or (..., N, N) array_like
        Non-negative adjacency matrix, ``A[i, j]`` the weight of ``j -> i``, or a stack of
        them (time steps, Monte Carlo runs), each checked.

    Returns
    -------
    L : (N, N) or (..., N, N) ndarray
        Rows sum to zero; symmetric positive semidefinite when `A` is symmetric.

    Raises
    ------
    ValueError
        A matrix that is not an adjacency (negative weights, self-loops; a Laplacian passed by
        mistake is named as such).

    Examples
    --------
    >>> from mascore import graphs
    >>> graphs.laplacian(graphs.path_graph(3))
    array([[ 1., -1.,  0.],
           [-1.,  2., -1.],
           [ 0., -1.,  1.]])
    """
    arr = _float_array(A, "A")
    if arr.ndim > 2:
        for idx in np.ndindex(*arr.shape[:-2]):
            _check_adjacency(arr[idx], f"A[{', '.join(map(str, idx))}]")
    else:
        arr = _check_adjacency(arr)
    return np.eye(arr.shape[-1]) * arr.sum(axis=-1)[..., None] - arr



#: Why the network designs need an undirected graph (quoted in their errors).
WHY_UNDIRECTED = ("the network designs split the loop into modes by the orthogonal eigenvectors of a "
                  "symmetric Laplacian, which a directed graph does not have")


def laplacian_spectrum(laplacian: ArrayLike, name: str = "laplacian") -> tuple[np.ndarray, np.ndarray]:
    """Eigen-decomposition ``Lap = V diag(lam) V^T`` of a connected undirected graph's Laplacian.

    The network designs (Vlahakis and Halikias) split the loop into one mode per eigenvalue.

    Parameters
    ----------
    laplacian : (N, N) array_like
        Symmetric Laplacian (rows sum to zero, non-positive off-diagonal).
    name : str
        Argument name used in the error messages (a caller that built the Laplacian from an
        adjacency passes ``"adjacency"``).

    Returns
    -------
    lam : (N,) ndarray
        Eigenvalues in increasing order; ``lam[0]`` is set to exactly 0.
    V : (N, N) ndarray
        Orthonormal eigenvectors (columns).

    Raises
    ------
    ValueError
        If the matrix is not a symmetric Laplacian (a directed one, or an adjacency matrix
        passed by mistake) or the graph is disconnected.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs
    >>> lam, V = graphs.laplacian_spectrum(graphs.laplacian(graphs.ring_graph(4)))
    >>> lam.round(6).tolist()
    [0.0, 2.0, 2.0, 4.0]
    """
    Lap = check_laplacian(laplacian, name, undirected=True, why=WHY_UNDIRECTED)
    N = Lap.shape[0]
    scale = max(1.0, float(np.abs(Lap).max()))
    lam, V = np.linalg.eigh(Lap)
    if N > 1 and lam[1] <= 1e-9 * scale:
        raise ValueError(
            f"{name} describes a disconnected graph (second-smallest Laplacian eigenvalue {lam[1]:.2g}); "
            "the network designs need a connected undirected graph"
        )
    lam[0] = 0.0
    return lam, V

def ring_graph(n_agents: int) -> np.ndarray:
    """Undirected cycle 0-1-...-(N-1)-0.

    Parameters
    ----------
    n_agents : int
        Number of agents N >= 3.

    Returns
    -------
    A : (N, N) ndarray
        0/1 symmetric adjacency; every agent has two neighbours.

    Examples
    --------
    >>> from mascore import graphs
    >>> graphs.ring_graph(4).sum(axis=1)
    array([2., 2., 2., 2.])
    """
    n_agents = _check_n(n_agents, minimum=3)
    idx = np.arange(n_agents)
    return adjacency_from_edges(n_agents, zip(idx, (idx + 1) % n_agents))


def path_graph(n_agents: int) -> np.ndarray:
    """Undirected path 0-1-...-(N-1).

    Parameters
    ----------
    n_agents : int
        Number of agents N >= 1.

    Returns
    -------
    A : (N, N) ndarray
        0/1 symmetric adjacency; the two ends have one neighbour.

    Examples
    --------
    >>> from mascore import graphs
    >>> graphs.path_graph(4).sum(axis=1)
    array([1., 2., 2., 1.])
    """
    n_agents = _check_n(n_agents)
    idx = np.arange(n_agents - 1)
    return adjacency_from_edges(n_agents, zip(idx, idx + 1))


def complete_graph(n_agents: int) -> np.ndarray:
    """Undirected complete graph on N agents.

    Parameters
    ----------
    n_agents : int
        Number of agents N >= 1.

    Returns
    -------
    A : (N, N) ndarray
        Ones off the diagonal, zeros on it.

    Examples
    --------
    >>> from mascore import graphs
    >>> int(graphs.complete_graph(5).sum())
    20
    """
    n_agents = _check_n(n_agents)
    return np.ones((n_agents, n_agents)) - np.eye(n_agents)


def star_graph(n_agents: int, center: int = 0) -> np.ndarray:
    """Undirected star with hub `center`.

    Parameters
    ----------
    n_agents : int
        Number of agents N >= 2.
    center : int
        Index of the hub, linked to every other agent.

    Returns
    -------
    A : (N, N) ndarray
        0/1 symmetric adjacency.

    Examples
    --------
    >>> from mascore import graphs
    >>> graphs.star_graph(4).sum(axis=1)
    array([3., 1., 1., 1.])
    """
    n_agents = _check_n(n_agents)
    if isinstance(center, bool) or not isinstance(center, (int, np.integer)):
        raise TypeError(f"center must be an agent index (an int); got {type(center).__name__} {center!r}")
    if not 0 <= center < n_agents:
        raise ValueError(f"center must be in 0..{n_agents - 1}; got {center}")
    return adjacency_from_edges(n_agents, ((center, i) for i in range(n_agents) if i != center))


def proximity_graph(positions: ArrayLike, sensing_range: float) -> np.ndarray:
    """Undirected disk graph: agents closer than `sensing_range` are neighbours.

    Parameters
    ----------
    positions : (N, n) or (..., N, n) array_like
        Agent positions (m); leading axes (time, Monte Carlo runs) are kept.
    sensing_range : float
        Range r (m); ``||p_i - p_j|| <= r`` makes ``i`` and ``j`` neighbours.

    Returns
    -------
    A : (N, N) or (..., N, N) ndarray of float
        0/1 adjacency with zero diagonal.

    Examples
    --------
    >>> from mascore import graphs
    >>> graphs.proximity_graph([[0.0, 0.0], [100.0, 0.0], [400.0, 0.0]], sensing_range=150.0)
    array([[0., 1., 0.],
           [1., 0., 0.],
           [0., 0., 0.]])
    """
    p = _float_array(positions, "positions")
    if p.ndim < 2 or p.shape[-1] == 0:
        raise ValueError(f"positions must have shape (..., N, n) with n >= 1; got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("positions contains NaN or infinite entries")
    check_positive(sensing_range, "sensing_range", "(the range r, in the unit of the positions)")
    diff = p[..., :, None, :] - p[..., None, :, :]
    dist = np.linalg.norm(diff, axis=-1)
    A = (dist <= sensing_range).astype(float)
    n_agents = p.shape[-2]
    A[..., np.arange(n_agents), np.arange(n_agents)] = 0.0
    return A


def spanning_tree_roots(A: ArrayLike) -> np.ndarray:
    """Agents from which every other agent can be reached along directed edges.

    The graph contains a directed spanning tree iff this set is non-empty.

    Parameters
    ----------
    A : (N, N) array_like
        Adjacency, ``A[i, j] > 0`` when information flows ``j -> i``.

    Returns
    -------
    roots : (k,) ndarray of int
        Indices of all possible roots (sorted).

    Examples
    --------
    >>> from mascore import graphs
    >>> chain = graphs.adjacency_from_edges(3, [(0, 1), (1, 2)], directed=True)   # 0 -> 1 -> 2
    >>> graphs.spanning_tree_roots(chain)
    array([0])
    """
    A = _check_adjacency(A)
    n_agents = A.shape[0]
    # out-neighbours of j: agents i with A[i, j] > 0 (information flows j -> i)
    out = [np.flatnonzero(A[:, j] > 0) for j in range(n_agents)]
    roots = [r for r in range(n_agents) if _reach_count(out, r) == n_agents]
    return np.array(roots, dtype=int)


def has_spanning_tree(A: ArrayLike) -> bool:
    """Whether the directed graph of `A` contains a directed spanning tree.

    The condition of the consensus theorems (Ren et al. 2005, Theorems 3.2 and 3.9).

    Parameters
    ----------
    A : (N, N) array_like
        Adjacency, ``A[i, j] > 0`` when information flows ``j -> i``.

    Returns
    -------
    bool
        True if some agent reaches every other agent.

    Examples
    --------
    >>> from mascore import graphs
    >>> graphs.has_spanning_tree(graphs.adjacency_from_edges(3, [(0, 1), (0, 2)], directed=True))
    True
    >>> graphs.has_spanning_tree(graphs.adjacency_from_edges(3, [(0, 1), (2, 1)], directed=True))
    False
    """
    return spanning_tree_roots(A).size > 0


def is_connected(A: ArrayLike) -> bool:
    """Whether the undirected graph of ``A + A.T`` is connected.

    Parameters
    ----------
    A : (N, N) array_like
        Adjacency (directions are ignored).

    Returns
    -------
    bool
        True if every agent is reachable from every other ignoring directions.

    Examples
    --------
    >>> from mascore import graphs
    >>> graphs.is_connected(graphs.path_graph(4)), graphs.is_connected(graphs.proximity_graph([[0.0], [9.0]], 1.0))
    (True, False)
    """
    A = _check_adjacency(A)
    S = A + A.T  # undirected: connected exactly when one search from agent 0 reaches every agent
    return _reach_count([np.flatnonzero(S[:, j] > 0) for j in range(S.shape[0])], 0) == S.shape[0]


def connected_components(A: ArrayLike) -> list[np.ndarray]:
    """The connected components of the undirected graph of ``A + A.T`` (directions ignored).

    Parameters
    ----------
    A : (N, N) array_like or networkx graph
        Adjacency, ``A[i, j] > 0`` when information flows ``j -> i``.

    Returns
    -------
    list of ndarray of int
        The agents of each component (sorted), in order of their smallest agent; one
        component iff :func:`is_connected`.

    Examples
    --------
    >>> import networkx as nx
    >>> from mascore import graphs
    >>> [c.tolist() for c in graphs.connected_components(nx.union(nx.path_graph(2), nx.path_graph([2, 3, 4])))]
    [[0, 1], [2, 3, 4]]
    """
    A = _check_adjacency(A)
    S = (A + A.T) > 0
    out = [np.flatnonzero(S[:, j]) for j in range(A.shape[0])]
    seen = np.zeros(A.shape[0], bool)
    comps = []
    for root in range(A.shape[0]):
        if seen[root]:
            continue
        comp = {root}
        queue = deque([root])
        while queue:
            for nxt in out[queue.popleft()]:
                if int(nxt) not in comp:
                    comp.add(int(nxt))
                    queue.append(int(nxt))
        idx = np.array(sorted(comp), dtype=int)
        seen[idx] = True
        comps.append(idx)
    return comps


def require_connected(A: ArrayLike, why: str, name: str = "adjacency") -> None:
    """Raise ``ValueError`` naming the components if the graph of `A` is not connected.

    Parameters
    ----------
    A : (N, N) array_like or networkx graph
        Adjacency (directions ignored).
    why : str
        What needs the connected graph; it goes into the message.
    name : str
        Argument name used in the message.

    Examples
    --------
    >>> import networkx as nx
    >>> from mascore import graphs
    >>> try:
    ...     graphs.require_connected(nx.union(nx.path_graph(2), nx.path_graph([2, 3])), "rendezvous")
    ... except ValueError as exc:
    ...     print(exc)
    adjacency is a disconnected graph (2 components: [[0, 1], [2, 3]]); rendezvous needs a connected one
    """
    comps = connected_components(A)
    if len(comps) > 1:
        shown = [c.tolist() for c in comps[:6]]
        more = ", ..." if len(comps) > 6 else ""
        raise ValueError(f"{name} is a disconnected graph ({len(comps)} components: {str(shown)[:-1]}{more}]); "
                         f"{why} needs a connected one")


def graph_union(adjacencies: Sequence[ArrayLike] | np.ndarray) -> np.ndarray:
    """Union of graphs: the edge weights summed over the sequence.

    Parameters
    ----------
    adjacencies : sequence of (N, N) array_like, or (T, N, N) array
        The graphs to unite; all of the same size.

    Returns
    -------
    A : (N, N) ndarray
        Sum of the adjacency matrices (an edge is present if present once).

    Examples
    --------
    >>> from mascore import graphs
    >>> a = graphs.adjacency_from_edges(3, [(0, 1)], directed=True)
    >>> b = graphs.adjacency_from_edges(3, [(1, 2)], directed=True)
    >>> graphs.has_spanning_tree(a), graphs.has_spanning_tree(graphs.graph_union([a, b]))
    (False, True)
    """
    return _adjacency_stack(adjacencies).sum(axis=0)


def unions_over_windows(adjacencies: Sequence[ArrayLike] | np.ndarray, window: int) -> np.ndarray:
    """Unions over consecutive, non-overlapping windows of `window` graphs.

    Parameters
    ----------
    adjacencies : sequence of (N, N) array_like, or (T, N, N) array
        One graph per step.
    window : int
        Number of consecutive graphs in each union (the last window may be shorter).

    Returns
    -------
    unions : (ceil(T / window), N, N) ndarray
        The union of each window.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs
    >>> steps = np.stack([graphs.path_graph(3)] * 5)
    >>> graphs.unions_over_windows(steps, 2).shape
    (3, 3, 3)
    """
    window = check_positive_int(window, "window")
    stack = _adjacency_stack(adjacencies)
    return np.stack([stack[k : k + window].sum(axis=0) for k in range(0, len(stack), window)])


def to_networkx(A: ArrayLike, directed: bool | None = None) -> nx.Graph:
    """Convert an adjacency matrix to a networkx graph for drawing.

    Edges point in the direction information flows (``j -> i`` for ``A[i, j] > 0``).
    networkx is imported only here.

    Parameters
    ----------
    A : (N, N) array_like
        Adjacency matrix.
    directed : bool or None
        Build a ``DiGraph`` (True) or a ``Graph`` (False); default: whether `A` is asymmetric.

    Returns
    -------
    networkx.Graph or networkx.DiGraph
        Nodes ``0..N-1`` and weighted edges.

    Examples
    --------
    >>> from mascore import graphs
    >>> G = graphs.to_networkx(graphs.ring_graph(5))
    >>> G.number_of_nodes(), G.number_of_edges()
    (5, 5)
    """
    A = _check_adjacency(A)
    if directed is not None and not isinstance(directed, (bool, np.bool_)):
        raise TypeError(f"directed must be True, False or None; got {directed!r}")
    if directed is None:
        directed = not np.allclose(A, A.T)
    import networkx as nx  # only this converter needs networkx

    G = nx.DiGraph() if directed else nx.Graph()
    G.add_nodes_from(range(A.shape[0]))
    for i, j in zip(*np.nonzero(A)):
        G.add_edge(int(j), int(i), weight=float(A[i, j]))
    return G


def from_networkx(graph: nx.Graph | Sequence[nx.Graph]) -> np.ndarray:
    """The adjacency matrix of a networkx graph, in mascore's convention (the inverse of :func:`to_networkx`).

    Every function that takes an adjacency calls this on a networkx graph itself; call it to see
    or change the matrix.

    Parameters
    ----------
    graph : networkx.Graph or networkx.DiGraph, or a list of them
        Node ``i`` of ``sorted(graph.nodes)`` is agent ``i``; edge attribute ``weight``
        (default 1) is the weight.

    Returns
    -------
    (N, N) or (T, N, N) ndarray
        ``A[i, j] > 0`` iff agent ``i`` receives from agent ``j`` (edge ``j -> i``).

    Examples
    --------
    >>> import networkx as nx
    >>> from mascore import graphs
    >>> graphs.from_networkx(nx.path_graph(3))
    array([[0., 1., 0.],
           [1., 0., 1.],
           [0., 1., 0.]])
    """
    from ._validation import graph_adjacency, is_graph

    if not (is_graph(graph) or (isinstance(graph, (list, tuple)) and graph and all(map(is_graph, graph)))):
        raise TypeError(f"graph must be a networkx graph or a list of them; got {type(graph).__name__}")
    return _check_adjacency(graph_adjacency(graph), "graph") if is_graph(graph) else _adjacency_stack(
        graph_adjacency(graph))


def _reach_count(out: list[np.ndarray], root: int) -> int:
    seen = {root}
    queue = deque([root])
    while queue:
        for nxt in out[queue.popleft()]:
            if nxt not in seen:
                seen.add(int(nxt))
                queue.append(int(nxt))
    return len(seen)


def _check_adjacency(A: ArrayLike, name: str = "A") -> np.ndarray:
    """A weighted adjacency matrix (square, finite, non-negative, zero diagonal); a Laplacian is named."""
    A = check_adjacency(_float_array(A, name), name)
    if A.shape[0] == 0:
        raise ValueError(f"{name} must describe at least one agent; got shape {A.shape}")
    return A


def _check_n(n_agents: int, minimum: int = 1) -> int:
    n_agents = check_positive_int(n_agents, "n_agents", minimum)
    check_fits_in_memory(8.0 * n_agents**2, "n_agents", f"the ({n_agents}, {n_agents}) adjacency matrix")
    return n_agents


def _adjacency_stack(adjacencies: Sequence[ArrayLike] | np.ndarray) -> np.ndarray:
    """A non-empty (T, N, N) stack of adjacency matrices, each checked (named ``adjacencies[k]``)."""
    stack = _float_array(adjacencies, "adjacencies")
    if stack.ndim != 3 or stack.shape[1] != stack.shape[2] or stack.shape[0] == 0:
        raise ValueError(
            f"adjacencies must be a non-empty sequence of (N, N) matrices; got shape {stack.shape}"
        )
    for k, A in enumerate(stack):
        _check_adjacency(A, f"adjacencies[{k}]")
    return stack
