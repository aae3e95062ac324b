"""The design functions' one reading of a system: ``(A, B)`` arrays or an LTIAgent / python-control StateSpace."""

from __future__ import annotations

import numpy as np

from .agents import check_sampling_time, is_system, system_matrices

__all__ = ["design_args"]


def design_args(fname: str, A, B, rest: dict, dt, time: str | None = None, bname: str = "B"):
    """``(A, B, rest, dt)`` of a design: ``dt`` 0.0 in continuous time, else the sampling time (or True).

    `rest` maps the names of the arguments after B to their values, in the signature's order;
    they come back as a tuple, in that order.

    The agent is ``(A, B)`` (continuous time unless `dt` is given) or a system (an LTIAgent or a
    python-control StateSpace) in A's place, python-control's order: the slots after it are shifted.
    An ``A`` sampled by :meth:`mascore.agents.LTIAgent.from_continuous` given as a continuous-time
    matrix (no `dt`) is refused by name.
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
        if dt is not None and (sys_dt == 0 or (sys_dt is not True
                                               and not np.isclose(float(dt), sys_dt, rtol=1e-9, atol=0))):
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
        if dt is not None and time == "continuous":
            raise ValueError(f"{fname} designs in continuous time only; leave dt out and pass the continuous-time "
                             f"(A, B)")
        dt = 0.0 if dt is None else check_sampling_time(A, dt)
    return _complete(fname, A, B, names, rest, dt)


def _complete(fname: str, A, B, names: tuple, rest: tuple, dt):
    missing = [name for name, value in zip(names, rest) if value is None]
    if missing:
        raise TypeError(f"{fname}() needs {', '.join(missing)}: call it with (A, B, {', '.join(names)}) or "
                        f"(sys, {', '.join(names)})")
    return A, B, rest, dt


def full_state_only(m: int, shape: tuple) -> str:
    """The message for an R of partial sensing given to Song et al.'s whole-team filters (full-state sensing)."""
    return (f"R must be ({m}, {m}) per sensed agent or (m N, m N) for the team; got {shape}. Song et al.'s "
            f"whole-team filters (song-mb, song-eb) are implemented for full-state sensing only, as eq. (2) "
            f"measures every state of each sensed agent. For partial sensing "
            f"(positions only, a subset of states) use a method that takes an output matrix: mascore.compare's "
            f"POSITION_METHODS (centralized, local, forwarding, vlahakis, set-membership) on the team, or "
            f"mascore.fusion's filters with your own H_i (sensor_network.SensorNetworkModel)")
