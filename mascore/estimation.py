"""One estimator protocol: the state, the steps, the messages, and the spec that declares a method.

Every estimator of the package is one class with the same shape (Stone Soup's
Predictor / Updater over one State; filterpy's one class per filter):

- a **state value**: :class:`GaussianState` (mean and covariance) or
  :class:`SetState` (centre and shape matrix of an ellipsoidal set);
- ``predict(...)`` and ``update(...)``: the team-wide steps, vectorized over
  agents and runs (each filter's own signature: the data it needs);
- ``agent_inputs(...)`` and ``agent_step(i, own_data, messages)``: what **one**
  agent computes at one step, from its own data and the messages its neighbours
  sent it (each round's, in order), with ``messages()`` declaring what an agent
  sends per step and how many floats (:class:`Message`).

A **method** is declared once, beside its filter, by a :class:`MethodSpec`: its
name, how it is built from a scenario's model, the floats it sends and the flops
of one agent, the order of an agent's work and memory, and the scenarios where it
applies (with the reason where it does not). A module of the package declares its
methods in a module-level ``METHODS`` tuple; :func:`method_specs` finds them (a
new filter module is found with nothing listed by hand), and the comparison and
the cost tables read them.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import os
import pkgutil
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ._validation import Frozen, check_covariance, float_array, frozen_copy, require_finite

__all__ = [
    "GaussianState",
    "SetState",
    "Message",
    "Estimator",
    "protocol_docs",
    "MethodSpec",
    "method_specs",
    "method_spec",
    "method_names",
    "agent_limits",
    "knob_settings",
    "not_applicable",
    "ROLES",
    "STUDY_LAYER",
]

#: What a method is in the tables (:attr:`MethodSpec.role`): its recipe, a shown variant of its knob, a knob setting.
ROLES = ("recipe", "variant", "knob")
#: Modules of ``mascore`` above the numerical core (studies, CLI, book tools): never scanned for specs.
STUDY_LAYER = frozenset({"agent_cost", "compare", "ledger", "papers", "plotting", "registry", "report", "reproduce",
                         "sweep"})


@dataclass(frozen=True, eq=False)
class GaussianState(Frozen):
    """A Gaussian estimate: mean ``(..., n)`` and covariance ``(..., n, n)`` (per agent: ``(..., N, n)``).

    Parameters
    ----------
    mean : ndarray
        The mean.
    covariance : ndarray
        The covariance, symmetric positive semidefinite.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.estimation import GaussianState
    >>> GaussianState(np.zeros(2), np.eye(2)).mean.shape
    (2,)
    """

    mean: np.ndarray
    covariance: np.ndarray

    def __post_init__(self) -> None:
        _check_pair(self, ("mean", "covariance"), definite=False)


@dataclass(frozen=True, eq=False)
class SetState(Frozen):
    """A set-membership estimate: the ellipsoid ``{x: (x - c)^T E^-1 (x - c) <= 1}``.

    Parameters
    ----------
    centre : ndarray
        The centre c, ``(..., n)``.
    shape : ndarray
        The shape matrix E, ``(..., n, n)``, positive definite.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.estimation import SetState
    >>> SetState(np.zeros(2), np.eye(2)).shape.shape
    (2, 2)
    """

    centre: np.ndarray
    shape: np.ndarray

    def __post_init__(self) -> None:
        _check_pair(self, ("centre", "shape"), definite=True)


@dataclass(frozen=True)
class Message:
    """What an agent sends per step (to each neighbour by broadcast, or to the centre), and how many floats.

    Parameters
    ----------
    what : str
        The content (e.g. ``"information pair (Omega, q)"``).
    floats : float
        Floats sent per step for it (all rounds together).

    Examples
    --------
    >>> from mascore.estimation import Message
    >>> Message("measurement", 2).floats
    2
    """

    what: str
    floats: float

    def __post_init__(self) -> None:
        f = self.floats
        if isinstance(f, bool) or not isinstance(f, (int, float, np.integer, np.floating)) or not 0 <= f < np.inf:
            raise ValueError(f"floats must be a finite number >= 0 (floats sent per step); got {f!r}")


@runtime_checkable
class Estimator(Protocol):
    """The protocol every estimator implements (a structural type: no base class to inherit).

    ``predict`` and ``update`` are the team-wide steps (their arguments are the
    filter's own: a state and the data it needs); ``agent_inputs`` cuts agent i's
    own data and its neighbours' messages of one step out of a team-wide state;
    ``agent_step(i, own_data, messages)`` is agent i's step alone; ``messages()``
    declares what an agent sends per step. The filters' methods say what is particular
    to them and refer here for the rest.

    Parameters
    ----------
    *args, **kwargs
        None: a protocol is a type to check against (``isinstance``), not a class to build.

    Notes
    -----
    ``agent_inputs(<the filter's team-wide state and data of one step>, i)`` takes one run (no
    batch axis) and returns ``(own, messages)``: a dict of agent i's own data (copies: its
    prior, its measurements, its input) and a sequence, one entry per round of the step, of
    what its neighbours sent it in that round (empty when nothing is sent).

    ``agent_step(i, own, messages)`` computes agent i's step from these alone, with the same
    kernels as the team-wide ``update`` and ``predict``; it returns a tuple of arrays, agent i's
    state after the step (its estimate and covariance, or its set's centre and shape), equal
    to agent i's row of the team-wide step (the tests and :mod:`mascore.agent_cost` check it).
    A centralized filter's "agent" is the centre: its step is the whole filter's.

    ``messages(i=0, ...)`` returns a tuple of :class:`Message`: what agent i sends per step,
    to each neighbour or to the centre, with its floats (all rounds together); the floats of the
    method's spec (:attr:`MethodSpec.cost`) are their sum.

    Examples
    --------
    >>> from mascore import estimation, fusion
    >>> from mascore.compare import target_model
    >>> isinstance(fusion.ConsensusOnInformationFilter(target_model(4), 2), estimation.Estimator)
    True
    """

    predict: Callable[..., Any]
    update: Callable[..., Any]
    agent_inputs: Callable[..., tuple[Any, Sequence[Any]]]

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple:
        """Agent i's step alone, from its own data and its neighbours' messages (the kernels of the team-wide step).

        A filter's method without a docstring of its own takes this one (:func:`~mascore.estimation.protocol_docs`); a
        comment in it says what its step computes.

        Parameters
        ----------
        i : int
            The agent.
        own : dict
            Its own data of the step: the first value of ``agent_inputs``.
        messages : sequence
            What its neighbours sent it, one entry per round: the second value of ``agent_inputs``.

        Returns
        -------
        tuple of ndarray
            Agent i's state after the step (estimate and covariance, or the set's centre and shape):
            its row of the team-wide ``update`` and ``predict``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import kalman
        >>> model = kalman.LinearGaussianModel(np.eye(1), 0.1 * np.eye(1), np.eye(1), np.eye(1))
        >>> x, P = np.zeros((2, 1)), np.eye(1)
        >>> x_1, P_1 = model.agent_step(1, *model.agent_inputs(x, P, [[1.0], [3.0]], None, 1))
        >>> x_ref, _ = kalman.predict(*kalman.update(x, P, [[1.0], [3.0]], model.H, model.R), model.F, model.Q)
        >>> bool(np.allclose(x_1, x_ref[1]))
        True
        """
        raise NotImplementedError

    def messages(self, i: int = 0) -> tuple[Message, ...]:
        """What agent i sends per step (to each neighbour, or to the centre), and how many floats.

        Parameters
        ----------
        i : int
            The agent (the same for all where the graph is regular).

        Returns
        -------
        tuple of Message
            One per kind of message (empty when the filter sends nothing); their floats sum to the
            spec's (:attr:`MethodSpec.cost`).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.network_observer import DiscreteNetworkObserver
        >>> obs = DiscreteNetworkObserver(np.ones((2, 1)), 0.5, np.ones((2, 2)) - np.eye(2), np.eye(2),
        ...                               np.eye(2, 1), np.array([[1.0, 0.0]]))
        >>> obs.messages()[0].floats
        1.0
        """
        raise NotImplementedError


def protocol_docs(estimator_class: type) -> type:
    """Class decorator: the methods ``agent_step`` and ``messages`` defined without a docstring take the protocol's.

    Parameters
    ----------
    estimator_class : type
        An estimator class.

    Returns
    -------
    type
        The class, its methods documented once (by :class:`Estimator`).

    Examples
    --------
    >>> from mascore import kalman
    >>> kalman.LinearGaussianModel.agent_step.__doc__ == Estimator.agent_step.__doc__
    True
    """
    for name in ("agent_step", "messages"):
        method = vars(estimator_class).get(name)
        if method is not None and method.__doc__ is None:
            method.__doc__ = getattr(Estimator, name).__doc__
    return estimator_class


@dataclass(frozen=True)
class MethodSpec:
    """A method, declared once beside its filter: how it is built, what it sends, what it costs, where it applies.

    Parameters
    ----------
    name : str
        The method's name in every table (e.g. ``"ci-L5"``), unique within each task.
    tasks : tuple of str
        The scenarios where it applies (e.g. ``("target", "localization")``).
    build : callable
        ``build(model)``: the estimator on a scenario's model (the target and localization tasks: a
        :class:`~mascore.sensor_network.SensorNetworkModel`; the shared task: ``build(None)``); the team
        task: ``build(team, x_hat0)``, with the scenario's matrices and recipes (``A``, ``B``, ``K``,
        ``Q_filter``, ``R``, ``N``, ``laplacian``, ``adjacency``, ``P0``, ``bound_scale``,
        ``vlahakis_design``) and the initial estimates ``(runs, N, n)``.
    cost : callable
        ``cost(n, q, degree, n_agents)``: ``(floats, flops)`` of one agent per step (the busiest:
        the centre of a centralized filter), for state size n and q measurements per agent.
    order : mapping of str to (str, str)
        Per task, the order of one agent's work and memory per step.
    memory : callable, optional
        ``memory(n, q, degree, n_agents)``: floats one agent holds per step (its estimate, its
        covariance and one round's messages; leading terms).
    not_applicable : mapping of str to str
        Scenario -> why the method does not apply there (the tables show it, :func:`not_applicable`):
        a task (``"target"``, ``"localization"``) or a variant of one (``"position"``, ``"switching"``).
    whole_filter : bool
        The busiest agent runs the whole filter (the centre): timed as the team-wide step.
    position : float
        Rank in the tables (ascending; ties by name).
    role : {"recipe", "variant", "knob"}
        ``"recipe"``: the method at its own paper's settings (every study, figure and cost table);
        ``"variant"``: another setting of its knob shown beside it in the headline tables and at every
        team size; ``"knob"``: a setting swept at N = 8 only (:data:`mascore.compare.KNOBS`).
    family : str
        The method whose knob it sets (``""``: its own name), e.g. ``"ren-kc"`` for ``"ren-kc-q0"``.
    setting : float or None
        The value of that knob (None: the scenario's default), e.g. Ren et al.'s Q.
    knob : str
        The name of that knob in the knob table (e.g. ``"consensus gain eps"``), for a knob the
        comparison does not name itself (:data:`mascore.compare.KNOBS`).
    max_agents : mapping of str to (int, str)
        Task -> the largest team the comparison's sweeps run it at, and why not beyond (its time or
        memory; :func:`agent_limits`). A task not listed: no limit.
    step_max_agents : mapping of str to (int, str), optional
        Task -> the largest team at which one agent's step is timed (:mod:`mascore.agent_cost`), and why.
        None (default): the same as `max_agents`; give it where one step goes further than a sweep
        (a limit of time over many runs and steps, not of memory).

    Examples
    --------
    >>> from mascore.estimation import method_spec
    >>> method_spec("ci-L5", "target").tasks
    ('target', 'localization')
    """

    name: str
    tasks: tuple[str, ...]
    build: Callable[[Any], Any]
    cost: Callable[[int, int, int, int], tuple[float, float]]
    order: Mapping[str, tuple[str, str]]
    memory: Callable[[int, int, int, int], float] | None = None
    not_applicable: Mapping[str, str] = field(default_factory=dict)
    whole_filter: bool = False
    position: float = 0.0
    role: str = "recipe"
    family: str = ""
    setting: float | None = None
    knob: str = ""
    max_agents: Mapping[str, tuple[int, str]] = field(default_factory=dict)
    step_max_agents: Mapping[str, tuple[int, str]] | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.name, str) and self.name):
            raise ValueError(f"name must be a non-empty string; got {self.name!r}")
        if self.role not in ROLES:
            raise ValueError(f"role of method {self.name!r} must be one of {ROLES}; got {self.role!r}")
        object.__setattr__(self, "family", self.family or self.name)
        for attr in ("build", "cost"):
            if not callable(getattr(self, attr)):
                raise TypeError(f"{attr} of method {self.name!r} must be callable")
        if isinstance(self.tasks, str) or not self.tasks or not all(isinstance(t, str) and t for t in self.tasks):
            raise ValueError(f"tasks of method {self.name!r} must be a non-empty tuple of task names; got {self.tasks!r}")
        bad = {t: o for t, o in dict(self.order).items()
               if not (isinstance(o, (tuple, list)) and len(o) == 2 and all(isinstance(w, str) for w in o))}
        if bad:
            raise ValueError(f"order of method {self.name!r}: each task's (work, memory) orders as two strings; "
                             f"got {bad}")
        missing = [t for t in self.tasks if t not in self.order]
        if missing:
            raise ValueError(f"method {self.name!r}: order must give the work and memory of every task; "
                             f"missing {missing}")
        both = sorted(set(self.tasks) & set(self.not_applicable))
        if both:
            raise ValueError(f"method {self.name!r}: {both} both in tasks and in not_applicable; a method applies to "
                             "a task or says why not")
        object.__setattr__(self, "tasks", tuple(self.tasks))
        for attr in ("order", "not_applicable", "max_agents", "step_max_agents"):  # read-only: specs are shared
            value = getattr(self, attr)
            if value is None:
                continue
            value = dict(value)
            if attr.endswith("max_agents"):  # the limits checked where they are declared
                value = {task: _checked_limit(self.name, attr, task, limit, self.tasks) for task, limit in value.items()}
            object.__setattr__(self, attr, MappingProxyType(value))

    def __copy__(self) -> MethodSpec:  # immutable: a copy is itself (its mappings are read-only)
        return self

    def __deepcopy__(self, memo: dict) -> MethodSpec:
        return self

    def __hash__(self) -> int:  # equal specs share their name and tasks
        return hash((self.name, self.tasks))


def _checked_limit(name: str, attr: str, task: object, limit: object, tasks: Sequence[str]) -> tuple[int, str]:
    """A spec's team-size limit of one task: ``(N >= 1, why)`` for a task of the method."""
    if task not in tasks:
        raise ValueError(f"{attr} of method {name!r}: {task!r} is not one of its tasks {tuple(tasks)}")
    ok = (isinstance(limit, (tuple, list)) and len(limit) == 2 and isinstance(limit[0], (int, np.integer))
          and not isinstance(limit[0], bool) and limit[0] >= 1 and isinstance(limit[1], str) and limit[1])
    if not ok:
        raise ValueError(f"{attr} of method {name!r}, task {task!r}: expected (largest N >= 1, why not beyond); "
                         f"got {limit!r}")
    return int(limit[0]), limit[1]


def method_specs(task: str | None = None) -> tuple[MethodSpec, ...]:
    """Every method declared in the package (a module's ``METHODS``), in table order; those of `task` if given.

    Modules of the numerical core are scanned (not the private ones, nor those of
    :data:`STUDY_LAYER`), and those whose source assigns ``METHODS`` imported; a new
    module with a ``METHODS`` tuple is found with nothing listed by hand.

    Parameters
    ----------
    task : str, optional
        Keep the methods that apply to this scenario.

    Returns
    -------
    tuple of MethodSpec
        Sorted by :attr:`MethodSpec.position`.

    Raises
    ------
    ValueError
        Two specs with one name.

    Examples
    --------
    >>> from mascore.estimation import method_specs
    >>> [s.name for s in method_specs("target")][:3]
    ['centralized', 'local', 'forwarding']
    """
    import mascore as package

    found: dict[tuple[str, str], MethodSpec] = {}
    for name, source in _core_modules(package.__path__).items():
        module = sys.modules.get(f"{package.__name__}.{name}")  # imported already: nothing to read
        if module is None:
            if not _declares_methods(source):
                continue
            module = importlib.import_module(f"{package.__name__}.{name}")
        for spec in getattr(module, "METHODS", ()):
            if not isinstance(spec, MethodSpec):
                continue
            for t in spec.tasks:
                if found.get((t, spec.name), spec) is not spec:
                    raise ValueError(f"two methods of task {t!r} are named {spec.name!r} (one in {module.__name__})")
                found[(t, spec.name)] = spec
    specs = sorted({id(s): s for s in found.values()}.values(), key=lambda s: (s.position, s.name))
    return tuple(s for s in specs if task is None or task in s.tasks)


def _core_modules(path: Sequence[str]) -> dict[str, str]:
    """The package's modules that may declare methods: name -> its source file (``""``: not a plain source file).

    Public modules (no leading underscore; ``.py`` or extension modules) outside :data:`STUDY_LAYER`, not
    sub-packages; the first of `path`'s folders that holds a name wins, as for an import. A folder is
    listed with one ``os.scandir`` (a fraction of ``pkgutil.iter_modules``'s time: the comparison looks
    methods up thousands of times); any other entry of `path` (a zip archive) through ``pkgutil``.
    """
    modules: dict[str, str] = {}
    for entry in path:
        try:
            with os.scandir(entry) as files:
                names = {_module_name(f.name): f.path for f in files if f.is_file()}
        except (NotADirectoryError, FileNotFoundError):
            names = {info.name: "" for info in pkgutil.iter_modules([entry]) if not info.ispkg}
        for name, source in names.items():
            if name and not (name.startswith("_") or name in STUDY_LAYER or name in modules):
                modules[name] = source
    return modules


def _module_name(filename: str) -> str:
    """The module a file of a package's folder defines (``""``: none): ``x.py`` or an extension ``x.cpython-....so``."""
    if filename.endswith(".py"):
        return filename[:-3]
    suffix = next((s for s in importlib.machinery.EXTENSION_SUFFIXES if filename.endswith(s)), None)
    return filename[: -len(suffix)] if suffix else ""


def _declares_methods(source: str) -> bool:
    """Whether a module's source assigns ``METHODS`` at its top level (read, not imported: the scan stays cheap).

    `source` is the module's file; not a ``.py`` file (an extension module, ``""``) or a file that
    cannot be read: True (the module is imported to see).
    """
    if not source.endswith(".py"):
        return True
    try:
        with open(source, "rb") as file:
            text = file.read()
    except OSError:
        return True
    return b"METHODS" in text and _METHODS_LINE.search(text) is not None  # the plain search first: fast


_METHODS_LINE = re.compile(rb"^METHODS\s*(?::[^=\n]*)?=", re.M)


def method_names(task: str, roles: Sequence[str] = ROLES) -> tuple[str, ...]:
    """The names of the methods of `task`, in table order (:func:`method_specs`).

    Parameters
    ----------
    task : str
        The scenario.
    roles : sequence of str
        Keep the methods of these roles (:attr:`MethodSpec.role`; default: all).

    Returns
    -------
    tuple of str
        The names.

    Examples
    --------
    >>> from mascore.estimation import method_names
    >>> "ci-diffusion" in method_names("localization")
    True
    >>> method_names("team", ("recipe",))[:3]
    ('centralized', 'local', 'forwarding')
    """
    return tuple(s.name for s in method_specs(task) if s.role in roles)


def knob_settings(family: str, task: str) -> dict[str, float | None]:
    """The methods of `task` that set the knob of method `family`, each with its setting, in table order.

    Parameters
    ----------
    family : str
        The method whose knob (:attr:`MethodSpec.family`).
    task : str
        The scenario.

    Returns
    -------
    dict of str to float or None
        Method name -> :attr:`MethodSpec.setting` (the recipe's own among them).

    Examples
    --------
    >>> from mascore.estimation import knob_settings
    >>> knob_settings("ren-kc", "shared")["ren-kc-q0"]
    0.0
    """
    return {s.name: s.setting for s in method_specs(task) if s.family == family}


def method_spec(name: str, task: str | None = None) -> MethodSpec:
    """The spec of method `name` (of `task`, if given), by name.

    Parameters
    ----------
    name : str
        The method's name.
    task : str, optional
        The scenario (needed when methods of several tasks share the name).

    Returns
    -------
    MethodSpec
        Its spec.

    Raises
    ------
    ValueError
        No such method (for that task), naming the known ones.

    Examples
    --------
    >>> from mascore.estimation import method_spec
    >>> method_spec("centralized", "target").whole_filter
    True
    """
    specs = method_specs(task)
    matches = [spec for spec in specs if spec.name == name]
    if len(matches) > 1:
        raise ValueError(f"method {name!r} names methods of several tasks; give the task")
    if matches:
        return matches[0]
    where = f" for task {task!r}" if task is not None else ""
    raise ValueError(f"method must be one of {tuple(s.name for s in specs)}{where}; got {name!r}")


def agent_limits(task: str, *, step: bool = False) -> dict[str, tuple[int, str]]:
    """The methods of `task` the comparison runs only up to some team size, with the reason their specs give.

    Parameters
    ----------
    task : str
        The scenario (``"target"``, ``"localization"``, ...).
    step : bool
        The limits of timing one agent's step (:attr:`MethodSpec.step_max_agents`) instead of the sweeps'.

    Returns
    -------
    dict of str to (int, str)
        Method name -> (largest N, why not beyond) (:attr:`MethodSpec.max_agents`), in table order.

    Raises
    ------
    ValueError
        A task no method declares.

    Examples
    --------
    >>> from mascore.estimation import agent_limits
    >>> agent_limits("localization")["ci-diffusion"][0], "ci-diffusion" in agent_limits("localization", step=True)
    (32, False)
    """
    if not isinstance(step, bool):
        raise TypeError(f"step must be True or False; got {step!r}")
    specs = method_specs()  # one scan of the package
    tasks = {t for s in specs for t in s.tasks}
    if task not in tasks:
        raise ValueError(f"task must be one of the methods' tasks {tuple(sorted(tasks))}; got {task!r}")
    limits = ((s.name, s.max_agents if not step or s.step_max_agents is None else s.step_max_agents)
              for s in specs if task in s.tasks)
    return {name: limit[task] for name, limit in limits if task in limit}


def not_applicable(scenario: str) -> dict[str, str]:
    """The methods that do not apply to `scenario`, each with the reason its spec gives, in table order.

    Parameters
    ----------
    scenario : str
        A task (``"target"``, ``"localization"``) or a variant of one (``"position"``: position-only
        sensing of the team task; ``"switching"``: a switching graph).

    Returns
    -------
    dict of str to str
        Method name -> why (:attr:`MethodSpec.not_applicable`).

    Examples
    --------
    >>> from mascore.estimation import not_applicable
    >>> list(not_applicable("position"))
    ['song-mb']
    """
    return {s.name: s.not_applicable[scenario] for s in method_specs() if scenario in s.not_applicable}


def _check_pair(state: object, names: tuple[str, str], definite: bool) -> None:
    """A state value's vector ``(..., n)`` and matrix ``(..., n, n)``: finite real arrays of matching shapes, stored
    as read-only copies."""
    vector, matrix = (require_finite(float_array(getattr(state, name), name), name) for name in names)
    if vector.ndim < 1 or vector.shape[-1] < 1:
        raise ValueError(f"{names[0]} must be an array (..., n) with n >= 1; got shape {vector.shape}")
    if matrix.shape != (*vector.shape, vector.shape[-1]):
        raise ValueError(f"{names[1]} must have shape (..., n, n) = {(*vector.shape, vector.shape[-1])} for "
                         f"{names[0]} of shape {vector.shape}; got {matrix.shape}")
    check_covariance(matrix, names[1], definite=definite)  # symmetric, positive semidefinite (a set's: definite)
    object.__setattr__(state, names[0], frozen_copy(vector))
    object.__setattr__(state, names[1], frozen_copy(matrix))
