"""Floats sent and flops per agent per step of the fusion filters (:mod:`mascore.fusion`), as formulas.

:func:`filter_cost` gives the leading-order counts of each method of :mod:`mascore.fusion`
as formulas of the state size n, the measurement size q, the degree d, the number of
consensus steps L and the team size N, with their values; :class:`FilterCost` holds them.
"""

from __future__ import annotations

from dataclasses import dataclass

from ._validation import (
    check_positive_int,
)

__all__ = [
    "FilterCost",
    "filter_cost",
    "kalman_step_flops",
]


# --------------------------------------------------------------------------------------------
# cost model


@dataclass(frozen=True)
class FilterCost:
    """Floats sent and flops per agent per step of one filter, with the formulas.

    Parameters
    ----------
    method : str
        The filter.
    floats_sent : float
        Numbers each agent broadcasts per step (a broadcast reaches every neighbour).
    flops : float
        Floating-point operations per agent per step (leading terms; a multiply-add is 2).
    floats_formula, flops_formula : str
        The same as formulas of n, q, d (degree), L (iterations), N.
    note : str
        What the count assumes.

    Examples
    --------
    >>> from mascore.fusion_cost import filter_cost
    >>> filter_cost("measurement-forwarding", n=4, q=2, degree=2).floats_sent
    2.0
    """

    method: str
    floats_sent: float
    flops: float
    floats_formula: str
    flops_formula: str
    note: str = ""


#: The methods :func:`filter_cost` knows.
_COST_METHODS = ("centralized", "measurement-forwarding", "consensus-on-information", "hcmci",
                 "information-consensus", "diffusion-kf", "covariance-intersection")


def filter_cost(method: str, n: int, q: int, degree: int, iterations: int = 1, n_agents: int = 1) -> FilterCost:
    """Floats sent and flops per agent per step of a filter, as formulas of (n, q, d, L, N).

    Leading-order counts for a time-invariant model (``H_j^T R_j^{-1} H_j`` and
    ``R_j^{-1}`` computed once): a matrix product ``2 n^3``, an inverse of a
    symmetric positive definite matrix ``n^3``, a solve with n right-hand sides
    ``8/3 n^3``; a symmetric matrix is sent as its ``n (n + 1) / 2`` distinct
    entries. Per step: the prediction ``4 n^3``; the local information vector
    ``2 q^2 + 2 q n``; a consensus step mixes ``d + 1`` pairs.

    Parameters
    ----------
    method : str
        ``"centralized"`` (floats: sent to the centre; flops: the centre's),
        ``"measurement-forwarding"``, ``"consensus-on-information"`` (CI),
        ``"hcmci"``, ``"information-consensus"`` (ICF), ``"diffusion-kf"``,
        ``"covariance-intersection"`` (:class:`~mascore.fusion.CovarianceIntersectionFilter`:
        ``iterations`` = evaluations of the weight search).
    n : int
        State dimension.
    q : int
        Measurement dimension per agent (0 allowed).
    degree : int
        d, neighbours per agent.
    iterations : int
        L (or K): consensus steps per update (evaluations of the weight search for
        covariance intersection).
    n_agents : int
        N (used by the centralized count only).

    Returns
    -------
    FilterCost
        The counts and formulas.

    Examples
    --------
    >>> from mascore.fusion_cost import filter_cost
    >>> c = filter_cost("consensus-on-information", n=4, q=2, degree=2, iterations=3)
    >>> c.floats_sent, c.floats_formula
    (42.0, 'L (n (n + 1) / 2 + n)')
    """
    if method not in _COST_METHODS:
        raise ValueError(f"method must be one of {_COST_METHODS}; got {method!r}")
    n = check_positive_int(n, "n")
    q = check_positive_int(q, "q", minimum=0)
    d = check_positive_int(degree, "degree", minimum=0)
    L = check_positive_int(iterations, "iterations", minimum=0)
    N = check_positive_int(n_agents, "n_agents")
    pair = n * (n + 1) / 2 + n  # a symmetric matrix and a vector
    predict = 4 * n**3 + 2 * n**2
    local = 2 * q**2 + 2 * q * n
    info_update = 2 * n**3 + 8 / 3 * n**3 + 6 * n**2  # P S, solve (I + P S) X = P, the mean
    to_info = n**3 + 2 * n**2  # Omega = P^{-1}, q = Omega x
    from_info = n**3 + 2 * n**2  # P = Omega^{-1}, x = P q
    mix = 2 * (d + 1) * pair
    if method == "centralized":
        return FilterCost(method, float(q), N * local + predict + info_update, "q",
                          "N (2 q^2 + 2 q n) + 26/3 n^3 + 8 n^2",
                          "floats: each agent to the centre; flops: the centre's, information form")
    if method == "measurement-forwarding":
        return FilterCost(method, float(q), (d + 1) * local + (d + 1) * n + predict + info_update, "q",
                          "(d + 1) (2 q^2 + 2 q n + n) + 26/3 n^3 + 8 n^2")
    if method == "diffusion-kf":
        return FilterCost(method, float(q + n), (d + 1) * local + (d + 1) * n + predict + info_update
                          + 2 * (d + 1) * n, "q + n", "(d + 1) (2 q^2 + 2 q n + 3 n) + 26/3 n^3 + 8 n^2",
                          "measurements for the incremental step, then psi_i for the diffusion")
    if method in ("consensus-on-information", "information-consensus"):
        return FilterCost(method, L * pair, predict + to_info + local + L * mix + from_info,
                          "L (n (n + 1) / 2 + n)",
                          "6 n^3 + 2 q^2 + 2 q n + 2 L (d + 1) (n (n + 1) / 2 + n) + 6 n^2")
    if method == "hcmci":
        return FilterCost(method, 2 * L * pair, predict + to_info + local + 2 * L * mix + from_info,
                          "2 L (n (n + 1) / 2 + n)",
                          "6 n^3 + 2 q^2 + 2 q n + 4 L (d + 1) (n (n + 1) / 2 + n) + 6 n^2",
                          "the prior and the novelty pairs, each L steps")
    # CovarianceIntersectionFilter: incremental update with the neighbourhood's measurements, then one covariance
    # intersection of the d + 1 neighbourhood estimates (each sent as an information pair)
    incremental = (d + 1) * local + (d + 1) * n + predict + info_update
    fuse = to_info + L * (2 * (d + 1) * n**2 + n**3) + 2 * (d + 1) * pair + from_info
    return FilterCost(method, q + pair, incremental + fuse, "q + n (n + 1) / 2 + n",
                      "(d + 1) (2 q^2 + 2 q n + n) + 32/3 n^3 + 12 n^2 + L (2 (d + 1) n^2 + n^3) "
                      "+ 2 (d + 1) (n (n + 1) / 2 + n)",
                      "measurements, then the information pair; L = evaluations of the weight search (about 10-30)")


def kalman_step_flops(n: int) -> float:
    """Flops of one Kalman step of an agent on its own state of size n: the prediction and an information update.

    ``4 n^3 + 2 n^2`` (prediction) ``+ 26/3 n^3 + 8 n^2`` (update; the counts of :func:`filter_cost`).

    Parameters
    ----------
    n : int
        State size.

    Returns
    -------
    float
        Flops per step.

    Examples
    --------
    >>> from mascore.fusion_cost import kalman_step_flops
    >>> round(kalman_step_flops(4), 2)
    970.67
    """
    n = check_positive_int(n, "n")
    return float(4 * n**3 + 2 * n**2 + 26 / 3 * n**3 + 8 * n**2)
