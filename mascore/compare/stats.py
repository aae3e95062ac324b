"""The comparison's statistics: RMS-error ratios with paired bootstrap intervals, ANEES with chi-square bounds.

A referee's two questions of an estimator against the centralized one, answered on the
runs of a sweep cell (each run one seed; the methods of a cell share their seeds):

- **accuracy**: the ratio of RMS errors, ``sqrt(mean_r e_r^2 / mean_r c_r^2)`` over the
  cell's runs ``r`` (``e_r``, ``c_r``: the per-run RMS errors of the method and of the
  centre), with a 95 % *paired* percentile bootstrap interval (:func:`rms_ratio`). Unlike
  the mean of run-by-run ratios, it has a finite variance when the centre's error is
  chi-distributed (``E[1/c^2]`` is infinite for two degrees of freedom), and it is the
  quantity the exact error covariance gives (``sqrt(tr C_method / tr C_centre)``);
- **consistency**: the average NEES per degree of freedom (ANEES) with the two-sided 95 %
  chi-square bounds of a consistent filter (:func:`anees_bounds`).

Every resample is drawn from ``numpy.random.default_rng(BOOTSTRAP_SEED)``: the same runs give
the same interval, byte for byte, in any process or thread.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["BOOTSTRAP_RESAMPLES", "BOOTSTRAP_SEED", "NEES_DIMENSION", "Interval", "anees_bounds",
           "mean_interval", "resample_indices", "rms_ratio"]

#: Bootstrap resamples per interval.
BOOTSTRAP_RESAMPLES = 2000

#: The seed of every bootstrap (``numpy.random.default_rng(BOOTSTRAP_SEED)``): intervals are deterministic.
BOOTSTRAP_SEED = 0

#: Dimension of the state whose NEES a task's cells record (then divide by): the own state ``[p, v]`` (4),
#: the shared 2-D quantity, the common target's whole state (4), an agent's own position in localization (2).
NEES_DIMENSION = {"team": 4, "shared": 2, "target": 4, "localization": 2}


class Interval(NamedTuple):
    """A point estimate with its 95 % interval.

    Attributes
    ----------
    value : float
        The estimate (NaN without data).
    lo, hi : float
        The ends of its 95 % interval (NaN with fewer than 2 runs).
    """

    value: float
    lo: float
    hi: float


def resample_indices(n_runs: int, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED) -> np.ndarray:
    """The bootstrap's resamples of ``n_runs`` runs: indices drawn with replacement.

    Parameters
    ----------
    n_runs : int
        Runs in the sample, >= 1.
    resamples : int
        Number of resamples B, >= 1.
    seed : int
        Seed of ``numpy.random.default_rng``.

    Returns
    -------
    (B, n_runs) ndarray of int
        Row b: the runs of resample b (the same rows for the method and the centre: paired).

    Examples
    --------
    >>> from mascore.compare.stats import resample_indices
    >>> resample_indices(5, 3).shape
    (3, 5)
    """
    for name, v in (("n_runs", n_runs), ("resamples", resamples)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
    return np.random.default_rng(seed).integers(0, n_runs, size=(int(resamples), int(n_runs)))


def rms_ratio(err: np.ndarray, ref: np.ndarray, *, resamples: int = BOOTSTRAP_RESAMPLES,
              seed: int = BOOTSTRAP_SEED, memo: dict | None = None) -> Interval:
    """Ratio of RMS errors over runs, with its 95 % paired percentile bootstrap interval.

    ``value = sqrt(mean(err^2) / mean(ref^2))``; each resample draws runs with replacement,
    the same runs for `err` and `ref` (they share their seeds), so the interval keeps the
    common random numbers' correlation. Runs where either error is not finite are left out.

    Parameters
    ----------
    err : (R,) array_like
        The method's per-run RMS error (m; squared, the run's mean squared error).
    ref : (R,) array_like
        The reference's (the centralized filter's) per-run RMS error on the same runs (m).
    resamples : int
        Bootstrap resamples.
    seed : int
        The bootstrap's seed.
    memo : dict, optional
        The caller's store of resamples, to draw them once per sample size over many calls
        (the same indices as without it; the caller owns it, nothing is kept between calls).

    Returns
    -------
    Interval
        The ratio (dimensionless) and the 2.5 % and 97.5 % percentiles of its resamples.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.compare.stats import rms_ratio
    >>> r = rms_ratio(np.array([2.0, 2.0, 4.0]), np.array([1.0, 1.0, 2.0]))
    >>> float(r.value), float(r.lo), float(r.hi)
    (2.0, 2.0, 2.0)
    """
    e, c = _paired(err, ref)
    if e.size == 0:
        return Interval(float("nan"), float("nan"), float("nan"))
    e2, c2 = e * e, c * c
    value = float(np.sqrt(e2.mean() / c2.mean()))
    if e.size < 2:
        return Interval(value, float("nan"), float("nan"))
    idx = _draws(e.size, resamples, seed, memo)
    boot = np.sqrt(e2[idx].mean(axis=1) / c2[idx].mean(axis=1))
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return Interval(value, float(lo), float(hi))


def mean_interval(x: np.ndarray, *, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED,
                  memo: dict | None = None) -> Interval:
    """Mean over runs with its 95 % percentile bootstrap interval (non-finite runs left out).

    Parameters
    ----------
    x : (R,) array_like
        One value per run (any unit).
    resamples : int
        Bootstrap resamples.
    seed : int
        The bootstrap's seed.
    memo : dict, optional
        The caller's store of resamples (see :func:`rms_ratio`).

    Returns
    -------
    Interval
        The mean and the 2.5 % and 97.5 % percentiles of the resampled means (same unit as `x`).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.compare.stats import mean_interval
    >>> float(mean_interval(np.array([1.0, 1.0, 1.0])).hi)
    1.0
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"x must be one value per run, shape (R,); got shape {x.shape}")
    x = x[np.isfinite(x)]
    if x.size == 0:
        return Interval(float("nan"), float("nan"), float("nan"))
    if x.size < 2:
        return Interval(float(x.mean()), float("nan"), float("nan"))
    boot = x[_draws(x.size, resamples, seed, memo)].mean(axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return Interval(float(x.mean()), float(lo), float(hi))


def anees_bounds(n_runs: int, dimension: int) -> tuple[float, float]:
    """Two-sided 95 % chi-square bounds of the ANEES per degree of freedom of a consistent filter.

    A consistent filter's NEES at one step of one run is chi-square with ``d`` (the state's
    dimension) degrees of freedom; over ``R`` independent runs the sum is chi-square with
    ``R d``, so the ANEES per dof lies in ``chi2.ppf([0.025, 0.975], R d) / (R d)`` with
    probability 0.95 (Bar-Shalom, Li and Kirubarajan, sec. 5.4). We use ``R d`` degrees of
    freedom, **not** ``R d K N`` for the ``K`` steps and ``N`` agents the cells average over:
    within a run the steps and agents share the target, the team and the noise, so their
    NEES are correlated and only the runs are independent. An average of correlated
    chi-square variables varies less than one of them, so these bounds are wide (a
    consistent filter falls inside them at least about 95 % of the time): an ANEES outside
    them is inconsistent beyond doubt.

    Parameters
    ----------
    n_runs : int
        Independent runs R >= 1.
    dimension : int
        Dimension d >= 1 of the state whose NEES is recorded (:data:`NEES_DIMENSION`).

    Returns
    -------
    (float, float)
        Lower and upper bound on the ANEES per degree of freedom (dimensionless).

    Examples
    --------
    >>> from mascore.compare.stats import anees_bounds
    >>> lo, hi = anees_bounds(100, 4)
    >>> round(lo, 3), round(hi, 3)
    (0.866, 1.143)
    """
    from scipy.special import gammaincinv  # chi2.ppf(q, k) = 2 gammaincinv(k / 2, q), without scipy.stats' import

    for name, v in (("n_runs", n_runs), ("dimension", dimension)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
    dof = int(n_runs) * int(dimension)
    lo, hi = 2.0 * gammaincinv(dof / 2.0, np.array([0.025, 0.975])) / dof
    return float(lo), float(hi)


def _draws(n_runs: int, resamples: int, seed: int, memo: dict | None) -> np.ndarray:
    """:func:`resample_indices`, looked up in (and added to) the caller's `memo` when given."""
    if memo is None:
        return resample_indices(n_runs, resamples, seed)
    key = (int(n_runs), int(resamples), int(seed))
    if key not in memo:
        memo[key] = resample_indices(n_runs, resamples, seed)
    return memo[key]


def _paired(err: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The runs where both errors are finite, as two float arrays of one shape (R,)."""
    e, c = np.asarray(err, dtype=float), np.asarray(ref, dtype=float)
    if e.ndim != 1 or e.shape != c.shape:
        raise ValueError(f"err and ref must be one RMS error per run on the same runs, shape (R,); "
                         f"got {e.shape} and {c.shape}")
    keep = np.isfinite(e) & np.isfinite(c)
    return e[keep], c[keep]
