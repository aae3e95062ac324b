"""The design functions' one reading of a system: ``(A, B)`` arrays or an LTIAgent / python-control StateSpace."""

from __future__ import annotations

import numpy as np

from ._validation import float_array, require_finite
from .agents import check_sampling_time, is_system, system_matrices

__all__ = ["design_args", "output_matrices", "full_state_only"]


def design_args(fname: str, A, B, rest: dict, dt, time: str | None = None, bname: str = "B"):
    """``(A, B, rest, dt)`` of a design: ``dt`` 0.0 in continuous time, else the sampling time (or True).

    `rest` maps the names of the arguments after B to their values, in the signature's order;
    they come back as a tuple, in that order.

    The agent is ``(A, B)`` (continuous time unless `dt` is given) or a system (an LTIAgent or a
    python-control StateSpace) in A's place, python-control's order: the slots after it are shifted.
    An ``A`` sampled by :meth:`mascore.agents.LTIAgent.from_continuous` given as a continuous-time
    matrix (no `dt`) is refused by name, and so is any array ``A`` without `dt` whose every
    eigenvalue has a positive real part (the spectrum of a sampled matrix); ``dt=0`` says that
    ``A`` is continuous time and skips that check.
    """
    names, rest = tuple(rest), tuple(rest.values())
    if is_system(A):
        if B is not None:  # (sys, a, b, ...): the positional values after sys fill the slots from B on
            values = [B, *rest]
            holes = [i for i, v in enumerate(values) if v is None]
            if not holes:
                raise TypeError(f"{fname}(sys, ...): {bname} is the system's B; do not pass it")
            hole = holes[0]
            values[1:hole + 1] = values[:hole]
            B, rest = None, tuple(values[1:])
        A, B, sys_dt = system_matrices(A, time, name="sys", needed_by=fname)
        if dt is not None and not (_is_zero(dt) and sys_dt == 0) and (
                sys_dt == 0 or _is_zero(dt)
                or (sys_dt is not True and not np.isclose(float(dt), sys_dt, rtol=1e-9, atol=0))):
            raise ValueError(f"dt = {dt!r} contradicts the system's own time base (sys.dt = {sys_dt!r}); "
                             "leave dt out: the system carries it")
        dt = sys_dt
    else:
        if B is None:
            raise TypeError(f"{fname}() takes (A, {bname}, ...) or (sys, ...); {bname} is missing")
        tagged = check_sampling_time(A)
        if time == "discrete":  # arrays read as a sampled agent: dt, if any, must agree with A's
            dt = check_sampling_time(A, dt)
            return _complete(fname, A, B, names, rest, True if dt is None else dt)
        if dt is None and tagged is not None:
            raise ValueError(
                f"A is the sampled (discrete-time) matrix of an agent with dt = {tagged:g} s, but {fname} with "
                f"arrays and no dt designs in continuous time: pass the continuous-time (agent.A_c, agent.B_c)"
                + ("" if time == "continuous" else f", or the agent itself (or dt={tagged:g}) for the discrete-time "
                                                   "design"))
        if _is_zero(dt):  # dt=0: the caller says A is continuous time
            return _complete(fname, A, B, names, rest, 0.0)
        if dt is not None and time == "continuous":
            raise ValueError(f"{fname} designs in continuous time only; leave dt out (or dt=0) and pass the "
                             f"continuous-time (A, {bname})")
        if dt is None:
            _refuse_sampled_looking(fname, A, bname, continuous_only=time == "continuous")
        dt = 0.0 if dt is None else check_sampling_time(A, dt)
    return _complete(fname, A, B, names, rest, dt)


def _is_zero(dt) -> bool:
    """Whether `dt` is the number 0 (continuous time, said explicitly)."""
    return isinstance(dt, (int, float, np.integer, np.floating)) and not isinstance(dt, bool) and dt == 0


def _refuse_sampled_looking(fname: str, A, bname: str, continuous_only: bool) -> None:
    """Refuse a plain `A`, read as continuous time, whose every eigenvalue has a positive real part.

    ``A = expm(A_c dt)`` has that spectrum whenever ``|Im(s)| dt < pi / 2`` for every mode s of
    ``A_c`` (integrators give eigenvalues at exactly 1); a continuous-time agent has it only when
    every one of its modes is unstable. ``dt=0`` says that this is meant.
    """
    try:
        M = np.asarray(A, dtype=float)
    except (TypeError, ValueError):
        return  # the design's own checks name what is wrong
    if M.ndim != 2 or M.shape[0] != M.shape[1] or M.size == 0 or not np.all(np.isfinite(M)):
        return
    lam = np.linalg.eigvals(M)
    if np.all(lam.real > 0):
        shown = ", ".join(f"{v:.3g}" for v in np.sort_complex(lam)[:4]) + (", ..." if lam.size > 4 else "")
        remedy = ("pass the continuous-time (A_c, " + bname + ") (agent.A_c, or scipy.linalg.logm(A) / dt)"
                  if continuous_only else
                  f"pass dt=<sampling time in s> (or the agent as an LTIAgent or a python-control StateSpace) for "
                  f"the discrete-time design, or the continuous-time (A_c, {bname})")
        raise ValueError(
            f"A looks like a sampled (discrete-time) matrix: every eigenvalue has a positive real part ({shown}), as "
            f"those of expm(A_c dt) do, while a continuous-time agent has such a spectrum only when all its modes "
            f"are unstable; {fname} reads an array A without dt as continuous time. {remedy[0].upper() + remedy[1:]}; "
            f"if A is continuous time, say so with dt=0")


def _complete(fname: str, A, B, names: tuple, rest: tuple, dt):
    missing = [name for name, value in zip(names, rest) if value is None]
    if missing:
        raise TypeError(f"{fname}() needs {', '.join(missing)}: call it with (A, B, {', '.join(names)}) or "
                        f"(sys, {', '.join(names)})")
    return A, B, rest, dt


def output_matrices(C, m: int, n_agents: int, name: str = "C") -> np.ndarray:
    """The agents' output matrices ``(N, p, m)`` from one ``(p, m)`` for all or one per agent, checked (finite).

    Parameters
    ----------
    C : (p, m) or (N, p, m) array_like
        ``z_ij = C_j x_j + nu_ij``: one output matrix for every agent, or one per agent (same ``p``).
    m : int
        Agent state size.
    n_agents : int
        Team size N.
    name : str
        The argument's name in the messages.

    Returns
    -------
    (N, p, m) ndarray
        A new float array.
    """
    arr = float_array(C, name)
    if arr.ndim == 2:
        arr = np.broadcast_to(arr, (n_agents, *arr.shape))
    if arr.ndim != 3 or arr.shape[0] != n_agents or arr.shape[2] != m or arr.shape[1] == 0:
        raise ValueError(f"Incompatible dimensions of {name}; expected (p, {m}) for every agent or "
                         f"({n_agents}, p, {m}) one per agent (p >= 1 outputs of the m = {m} states), "
                         f"but found {np.shape(C)}")
    return require_finite(np.array(arr, dtype=float), name)


def full_state_only(m: int, shape: tuple) -> str:
    """The message for an R of partial sensing given without an output matrix C."""
    return (f"R must be ({m}, {m}) per sensed agent or (m N, m N) for the team; got {shape}. Measurements of "
            f"fewer than the m = {m} states need an output matrix C of shape (p, {m}) (e.g. positions only, "
            f"C = [I 0]) with R of (p, p): team_model.team_filter_model(..., C=C) and "
            f"rendezvous.RendezvousModel(..., C=C) take it, for Song et al.'s estimation-based whole-team filter "
            f"(song-eb; simulate_rendezvous mode 'estimation') and the centralized team filter. The "
            f"measurement-based loop (song-mb, eq. (5)) needs full states. Other methods with an output matrix: "
            f"mascore.compare's POSITION_METHODS (centralized, local, forwarding, vlahakis, set-membership), "
            f"mascore.fusion's filters with your own H_i (sensor_network.SensorNetworkModel)")
