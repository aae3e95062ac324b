"""Team sensing model of Song et al. (2023), eqs. (2)-(3).

Every agent ``i`` measures the full state of itself and of each neighbour in
its *closed* neighbourhood ``N̄_i = N_i ∪ {i}``::

    z_{i,x_j}[k] = x_j[k] + nu_ij[k],   j in N̄_i          (eq. (2))
    z_i[k] = H_i[k] (X[k] + nu_i[k])                         (eq. (3))

``X = [x_1; ...; x_N]`` stacks the ``m``-dimensional agent states (``m = 2n``
for the double integrator) and ``H_i`` (``m |N̄_i| x m N``) selects the blocks
of the agents in ``N̄_i`` in increasing index order.

Two equivalent representations are offered:

* the paper's: a list of selection matrices ``H_i`` and stacked vectors
  ``z_i`` of varying length (:func:`selection_matrix`,
  :func:`selection_matrices`, :func:`stacked_measurement`);
* a fixed-shape, batched one used by the filters: a boolean *sensing mask*
  ``S[..., i, j]`` (true when ``i`` senses ``j``, diagonal true) and a
  measurement tensor ``Z[..., i, j, :]`` (:func:`sensing_mask`,
  :func:`measure`). ``H_i^T H_i = diag(S[i]) ⊗ I_m``, so masks replace the
  selection matrices without ragged arrays, and the adjacency may change at
  every step and differ between Monte Carlo runs.

Adjacency convention (as in :mod:`mascore.graphs`): ``A[i, j] > 0`` means
``i`` receives from (senses) ``j``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ._sensing_kernels import masked_measurement, team_noise
from ._systems import output_matrices
from ._validation import (
    check_adjacency_stack,
    check_covariance,
    check_flag,
    check_generator,
    check_mask_values,
    check_positive_int,
    sample_shape,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .exceptions import IsolatedAgentError

__all__ = [
    "sensing_mask",
    "neighbor_sets",
    "selection_matrix",
    "selection_matrices",
    "team_noise_covariance",
    "measurement_noise",
    "measure",
    "stacked_measurement",
]


def sensing_mask(adjacency: ArrayLike, allow_isolated: bool = False) -> np.ndarray:
    """Closed-neighbourhood mask ``S = (A > 0) + I``.

    Parameters
    ----------
    adjacency : (N, N) or (..., N, N) array_like
        Adjacency matrices, ``A[..., i, j] > 0`` when ``i`` senses ``j``;
        leading axes (time steps, Monte Carlo runs) are kept.
    allow_isolated : bool
        If false (default), an agent without any neighbour raises
        :class:`~mascore.exceptions.IsolatedAgentError` naming the agent.

    Returns
    -------
    S : (..., N, N) ndarray of bool
        ``S[..., i, j]`` is true iff ``j`` is in ``N̄_i`` (diagonal true).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, sensing
    >>> sensing.sensing_mask(graphs.path_graph(3)).astype(int)
    array([[1, 1, 0],
           [1, 1, 1],
           [0, 1, 1]])
    """
    A = check_adjacency_stack(adjacency)
    check_flag(allow_isolated, "allow_isolated")
    S = A > 0
    if not allow_isolated:
        isolated = ~np.any(S, axis=-1)
        if np.any(isolated):
            where = np.argwhere(isolated)
            first = tuple(int(v) for v in where[0])
            agent = first[-1]
            batch = f" (at batch index {first[:-1]})" if len(first) > 1 else ""
            raise IsolatedAgentError(
                f"agent {agent} has no neighbour{batch}: with this adjacency / sensing range "
                f"it senses only itself ({int(isolated.sum())} isolated agent-slot(s) in total)"
            )
    S = S.copy()
    n = S.shape[-1]
    S[..., np.arange(n), np.arange(n)] = True
    return S


def neighbor_sets(adjacency: ArrayLike, allow_isolated: bool = False) -> list[np.ndarray]:
    """Closed neighbour sets ``N̄_i`` (sorted agent indices) of one graph.

    Parameters
    ----------
    adjacency : (N, N) array_like
        Who senses whom, ``A[i, j] > 0`` when ``i`` senses ``j``.
    allow_isolated : bool
        See :func:`sensing_mask`.

    Returns
    -------
    list of N int arrays
        ``out[i]`` lists ``N̄_i = N_i ∪ {i}`` in increasing order.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, sensing
    >>> [s.tolist() for s in sensing.neighbor_sets(graphs.path_graph(3))]
    [[0, 1], [0, 1, 2], [1, 2]]
    """
    S = sensing_mask(adjacency, allow_isolated=allow_isolated)
    if S.ndim != 2:
        raise ValueError(f"adjacency must be a single (N, N) matrix here; got shape {S.shape}")
    return [np.flatnonzero(row) for row in S]


def selection_matrix(neighbors: ArrayLike, n_agents: int, m: int) -> np.ndarray:
    """The paper's ``H_i`` (eq. (3)) for one closed neighbour set.

    Parameters
    ----------
    neighbors : (d,) array_like of int
        The agents ``N̄_i`` measured by agent ``i``, in the order they are
        stacked in ``z_i``.
    n_agents : int
        N.
    m : int
        Agent state dimension (``2n``).

    Returns
    -------
    H : (m d, m N) ndarray
        Block ``(l, j)`` is ``I_m`` if ``j = neighbors[l]``, else ``0``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, sensing
    >>> sensing.selection_matrix([1], n_agents=2, m=1)
    array([[0., 1.]])
    """
    n_agents = check_positive_int(n_agents, "n_agents")
    m = check_positive_int(m, "m")
    if isinstance(neighbors, (str, bytes)):
        raise TypeError(f"neighbors must be a 1-D array of agent indices (ints); got {neighbors!r}")
    idx = np.asarray(neighbors)
    if idx.ndim != 1 or idx.size == 0:
        raise ValueError(f"neighbors must be a non-empty 1-D array of agent indices; got {neighbors!r}")
    if not np.issubdtype(idx.dtype, np.integer):
        raise TypeError(f"neighbors must hold agent indices (ints); got dtype {idx.dtype}: {neighbors!r}")
    if np.any(idx < 0) or np.any(idx >= n_agents) or len(set(idx.tolist())) != idx.size:
        raise ValueError(f"neighbors must be distinct indices in [0, {n_agents}); got {idx.tolist()}")
    sel = np.zeros((idx.size, n_agents))
    sel[np.arange(idx.size), idx] = 1.0
    return np.kron(sel, np.eye(m))


def selection_matrices(adjacency: ArrayLike, m: int, allow_isolated: bool = False) -> list[np.ndarray]:
    """``[H_1, ..., H_N]`` for one graph (eq. (3)), self included.

    Parameters
    ----------
    adjacency : (N, N) array_like
        Who senses whom.
    m : int
        Agent state dimension (``2n``).
    allow_isolated : bool
        See :func:`sensing_mask`.

    Returns
    -------
    list of N ndarrays
        ``H_i`` of shape ``(m |N̄_i|, m N)``.

    Examples
    --------
    >>> from mascore import graphs, sensing
    >>> [H.shape for H in sensing.selection_matrices(graphs.path_graph(3), 2)]
    [(4, 6), (6, 6), (4, 6)]
    """
    m = check_positive_int(m, "m")
    sets = neighbor_sets(adjacency, allow_isolated=allow_isolated)
    n_agents = len(sets)
    return [selection_matrix(s, n_agents, m) for s in sets]


def team_noise_covariance(R: ArrayLike, n_agents: int, m: int) -> np.ndarray:
    """Full ``(m N, m N)`` covariance of ``nu_i`` (one observer's noise vector).

    Parameters
    ----------
    R : (m, m) or (m N, m N) array_like
        Either the covariance per measured agent (the team covariance is then
        ``I_N ⊗ R``) or the full covariance of ``nu_i`` as in the paper, where
        ``nu_i ~ N(0, R)`` with ``R`` of size ``2nN``. Symmetric PSD.
    n_agents : int
        Team size N.
    m : int
        Agent state dimension.

    Returns
    -------
    (m N, m N) ndarray
        The team covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, sensing
    >>> sensing.team_noise_covariance(np.eye(2), n_agents=3, m=2).shape
    (6, 6)
    """
    n_agents = check_positive_int(n_agents, "n_agents")
    m = check_positive_int(m, "m")
    R = _float_array(R, "R")
    if R.ndim == 2 and R.shape == (m, m):
        check_covariance(R, "R", size=m)
        return np.kron(np.eye(n_agents), R)
    if R.ndim == 2 and R.shape == (m * n_agents, m * n_agents):
        return check_covariance(R, "R", size=m * n_agents)
    raise ValueError(
        f"Incompatible dimensions of R; expected ({m}, {m}) per measured agent or "
        f"({m * n_agents}, {m * n_agents}) for the team, but found {R.shape}"
    )


def measurement_noise(
    rng: np.random.Generator | int, R: ArrayLike, shape: tuple[int, ...], n_agents: int, m: int
) -> np.ndarray:
    """Draw ``nu_i`` for every observer: shape ``(shape..., N, N, m)``.

    ``out[..., i, j, :]`` is ``nu_ij``, agent ``i``'s noise on agent ``j``.
    Noise is drawn for every pair (sensed or not) so that a realization does
    not depend on the topology (common random numbers across variants).

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of the noise.
    R : (m, m) or (m N, m N) array_like
        Measurement-noise covariance (see :func:`team_noise_covariance`).
    shape : tuple of int
        Leading shape (e.g. ``(runs,)``).
    n_agents : int
        Team size N.
    m : int
        Agent state dimension.

    Returns
    -------
    (shape..., N, N, m) ndarray
        One noise vector per observer and observed agent.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, sensing
    >>> sensing.measurement_noise(np.random.default_rng(0), np.eye(2), (5,), 3, 2).shape
    (5, 3, 3, 2)
    """
    rng = check_generator(rng)
    shape = sample_shape(shape, "shape")
    R_team = team_noise_covariance(R, n_agents, m)
    return team_noise(rng, R_team, shape, n_agents, m)


def measure(
    rng: np.random.Generator | int,
    states: ArrayLike,
    adjacency: ArrayLike,
    R: ArrayLike,
    allow_isolated: bool = False,
    *,
    C: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Noisy sensing of the closed neighbourhoods, batched (eq. (2), or outputs ``C_j x_j`` with `C`).

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of the noise.
    states : (..., N, m) array_like
        True agent states ``x_j`` (leading axes: Monte Carlo runs).
    adjacency : (N, N) or (..., N, N) array_like
        Who senses whom; broadcast against the leading axes of `states`
        (one graph for all runs, or one per run).
    R : (p, p) or (p N, p N) array_like
        Measurement-noise covariance (see :func:`team_noise_covariance`); ``p = m`` without `C`.
    allow_isolated : bool
        See :func:`sensing_mask`.
    C : (p, m) or (N, p, m) array_like, optional
        Output matrix, one for every agent or one per agent: ``z_ij = C_j x_j + nu_ij``
        (e.g. positions only). Default: full states.

    Returns
    -------
    Z : (..., N, N, p) ndarray
        ``Z[..., i, j, :] = C_j x_j + nu_ij`` (``x_j + nu_ij`` without `C`) where ``i`` senses
        ``j``, and ``0`` elsewhere (never NaN, so it is safe in masked matrix products).
    S : (..., N, N) ndarray of bool
        The sensing mask used.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, sensing
    >>> x = np.zeros((3, 2))
    >>> Z, S = sensing.measure(np.random.default_rng(0), x, graphs.path_graph(3), 0.01 * np.eye(2))
    >>> Z.shape, bool(np.all(Z[~S] == 0))                    # unsensed entries hold zeros
    ((3, 3, 2), True)
    """
    rng = check_generator(rng)
    x = _float_array(states, "states")
    if x.ndim < 2 or x.shape[-1] == 0 or x.shape[-2] == 0:
        raise ValueError(f"states must have shape (..., N, m) with N, m >= 1; got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("states contains NaN or infinite entries")
    n_agents, m = x.shape[-2:]
    S = sensing_mask(adjacency, allow_isolated=allow_isolated)
    if S.shape[-1] != n_agents:
        raise ValueError(
            f"adjacency is for {S.shape[-1]} agents but states has {n_agents} agents (shape {x.shape})"
        )
    try:
        np.broadcast_shapes(x.shape[:-2], S.shape[:-2])
    except ValueError:
        raise ValueError(
            f"the leading (batch) axes of states {x.shape} and adjacency {S.shape} do not broadcast"
        ) from None
    if C is None:
        return masked_measurement(rng, x, S, team_noise_covariance(R, n_agents, m))
    Cs = output_matrices(C, m, n_agents)
    y = np.einsum("...jm,jpm->...jp", x, Cs)  # every agent's outputs C_j x_j
    return masked_measurement(rng, y, S, team_noise_covariance(R, n_agents, Cs.shape[1]))


def stacked_measurement(Z: ArrayLike, mask: ArrayLike, agent: int) -> np.ndarray:
    """Agent ``i``'s stacked vector ``z_i`` of eq. (3) from the tensor form.

    Parameters
    ----------
    Z : (N, N, m) array_like
        Output of :func:`measure` for one run.
    mask : (N, N) array_like of bool
        The sensing mask.
    agent : int
        Index ``i``.

    Returns
    -------
    z_i : (m d_i,) ndarray
        ``[z_{i,x_j}]`` for ``j`` in ``N̄_i`` (``d_i`` agents) in increasing order; equals
        ``H_i (X + nu_i)`` with ``H_i`` from :func:`selection_matrix`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, sensing
    >>> x = np.arange(6.0).reshape(3, 2)
    >>> Z, S = sensing.measure(np.random.default_rng(0), x, graphs.path_graph(3), 0.0 * np.eye(2))
    >>> sensing.stacked_measurement(Z, S, agent=0)              # agents 0 and 1, no noise
    array([0., 1., 2., 3.])
    """
    Z = _finite(_float_array(Z, "Z"), "Z")
    mask = check_mask_values(mask, "mask")
    if Z.ndim != 3 or Z.shape[0] != Z.shape[1]:
        raise ValueError(f"Z must have shape (N, N, m); got {Z.shape}")
    if mask.shape != Z.shape[:2]:
        raise ValueError(f"Incompatible dimensions of mask; expected {Z.shape[:2]} but found {mask.shape}")
    if isinstance(agent, bool) or not isinstance(agent, (int, np.integer)):
        raise TypeError(f"agent must be an agent index (an int); got {type(agent).__name__} {agent!r}")
    if not 0 <= agent < Z.shape[0]:
        raise ValueError(f"agent must be in 0..{Z.shape[0] - 1}; got {agent}")
    return Z[agent, mask[agent]].reshape(-1)
