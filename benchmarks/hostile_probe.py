"""A hostile-input probe of the whole public API, each call isolated in a worker process.

Not a benchmark of speed but of behaviour on bad input (issue "Nothing silent"). It extends
:mod:`benchmarks.hostile_sweep` (whose spoils and classes it reuses) to every module named in
``mascore.__all__`` (and the paper modules), to constructors and public methods of the public
classes, to hostile values of another kind (``1e300``, counts of ``10**12``, a wrong number of
dimensions, a wrong type, a directed or a disconnected graph, non-SPD matrices), and it runs
every call in a worker process with an address-space limit (``resource.setrlimit``) and a
wall-clock limit enforced from outside (a call stuck in C code is killed, not waited for).

Two steps:

1. ``record``: run the docstring examples (``pytest --doctest-modules mascore``) with a plugin
   that keeps, for each public function, constructor and public method, the first call that
   returned normally with small arguments: the *baseline* calls. The examples are the
   smallest valid calls the API documents.
2. ``probe``: replay each baseline with one argument spoiled at a time and classify the outcome
   as :mod:`benchmarks.hostile_sweep` does (``clear``, ``unclear``, ``silent-nan``, ``accepted``,
   ``returned``, ``hang``), plus ``crash`` (the worker died: out of memory in C, a signal) and
   ``documented`` (an outcome the API documents: :data:`DOCUMENTED`, or a non-finite result the
   function's docstring names, such as the ``inf`` cost of an unstable loop). Output records
   (:data:`RECORDS`, the containers functions return) are not probed.
   A spoil that the argument's own docstring rules out (a directed graph where it says
   *symmetric* or *undirected*, a disconnected one where it says *connected*, an indefinite or
   zero matrix where it says *positive definite*) counts as ``accepted`` when it returns.

Usage::

    python -m benchmarks.hostile_probe record --out /tmp/probe/baselines.pkl
    python -m benchmarks.hostile_probe probe /tmp/probe/baselines.pkl --csv /tmp/probe/outcomes.csv

Run ``record`` and ``probe`` with ``PYTHONPATH=<checkout>`` to compare two checkouts.
"""

from __future__ import annotations

import argparse
import copy
import importlib
import inspect
import multiprocessing as mp
import os
import pickle
import re
import resource
import sys
import tempfile
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

from benchmarks.hostile_sweep import (
    COUNT_NAMES,
    SEED_NAMES,
    Replaced,
    _has_nonfinite,
    _is_settings,
    _small,
    field_spoils,
    spoils,
)

TIME_LIMIT_S = 10.0
MEMORY_LIMIT = 3 * 2**30  # bytes of address space per worker
GRAPH_NAMES = re.compile(r"^(adjacency|adjacencies|graph|graphs|laplacian|A_adj|L|Lap|comm|topology|schedule)$")
HUGE_COUNT = 10**12

#: Output records (what a function returns, built by it): plain containers, not probed.
RECORDS = frozenset({
    "consensus.ConsensusResult", "flocking.FlockingRun", "fusion_cost.FilterCost", "lqr.BottomUpLQR",
    "lqr.TopDownLQR", "observers.DistributedObserver", "observers.MinEnergyObserver",
    "papers.bhattacharjee2021.ClosedLoopRun", "papers.bhattacharjee2021.Draw",
    "papers.bhattacharjee2021.SetMembershipResult", "papers.ren2005.Fig1Result", "papers.song2023.Fig2Result",
    "papers.song2023.Fig3Result", "papers.song2023.RendezvousRun", "papers.vlahakis.ObserverResult",
    "rendezvous.RendezvousResult", "set_membership.FilterHistory", "synchronization.SyncDesign",
    "settings.SettingsView", "registry.SettingsView", "papers.ren2005.SwitchingDemo", "papers.vlahakis.Fig12Result",
    "distributed_ekf.EstimatedFlockingRun", "papers.song2023_flocking.Fig5Result",
    "papers.song2023_flocking.FlockingResult",
})

#: Outcomes the API documents: (function, argument, spoil) patterns and why the value is valid there.
DOCUMENTED = (
    (r"\.(agent_step|messages)$", r"^i$", r".", "i names the agent; unused where every agent's step is alike"),
    (r"^fusion\.(ConsensusOnInformationFilter|InformationConsensusFilter|safe_novelty_weight)$",
     r"^(n_consensus|n_iterations)$", r"^zero$", "zero rounds: the filter without exchange (the book's 'local')"),
    (r"^ellipsoids\.contains$", r"^rtol$", r"^zero$", "rtol = 0: the exact test"),
    (r"^papers\.song2023_flocking\.Fig5Result\.settled$", r"^series$", r"^(nan|inf) entry$",
     "a case whose run diverged has a NaN series, and its average is NaN (documented in Returns)"),
    (r"^agent_cost\.", r"^min_time$", r"^zero$", "min_time = 0: one repeat"),
    (r"^noise\.", r"^size$", r"^zero$", "size = 0: an empty draw, as numpy's"),
    (r"^(ledger|formatting)\.format_(number|value)$", r".", r"^(inf|nan)( entry)?$", "formats NaN and inf as text"),
    (r"^plotting\.plot_(band|trajectories)$", r".", r"^(inf|nan) entry$", "matplotlib draws NaN as a gap"),
    (r"^kalman\.predict$", r"^P$", r"^indefinite$", "a step checks shapes and a finite result only (module text)"),
    (r"^(centralized_team_filter\.CentralizedTeamFilter|own_state\.CentralizedOutputFilter)\.agent_inputs$", r"^i$",
     r".", "i is unused: the centre's step is the same for every agent (docstring)"),
    (r"^(ledger|formatting)\.format_value$", r".", r".", "a display helper: any value is shown, by design (docstring)"),
    (r"^set_membership\.", r"^(step|agent)$", r".", "labels of the error messages, shown as given"),
    (r"^settings\.setting$", r"^(default|low)$", r".", "a field declaration: values are checked when settings are built"),
    (r"^papers\.bhattacharjee2021\.(design|run)$", r"^A$", r"zero matrix", "A = 0: Lemma 2's r is inf, documented"),
)
#: Functions whose messages name an argument by a name the caller gives (``names=("x0", "P0")``).
ALIASES = {"sensor_network.SensorNetworkModel.check_state": {"x": "x0", "P": "P0"}}
NONFINITE_DOCUMENTED = re.compile(r"``\+?inf``|returns ``nan``|``nan`` (if|when|for)", re.I)


def module_names() -> list[str]:
    """Every public module: the submodules in ``mascore.__all__``, the package's other public modules (such as
    ``fusion_links``, imported by name only) and the paper modules."""
    import mascore
    import mascore.papers

    names = [m for m in mascore.__all__ if inspect.ismodule(getattr(mascore, m, None))
             or importlib.util.find_spec(f"mascore.{m}") is not None]
    names += sorted(p.stem for p in Path(mascore.__file__).parent.glob("*.py")
                    if not p.stem.startswith("_") and p.stem not in names)
    names = [m for m in names if m not in ("papers", "exceptions")]
    papers = sorted(p.stem for p in Path(mascore.papers.__file__).parent.glob("*.py") if not p.stem.startswith("_"))
    return names + [f"papers.{p}" for p in papers]


def public_callables(modules) -> list[tuple[str, str, object, object]]:
    """(module, qualified name, owner class or None, callable) of every public function, class and method."""
    out = []
    for mod_name in modules:
        try:
            module = importlib.import_module(f"mascore.{mod_name}")
        except Exception:  # noqa: BLE001 - an optional extra missing: nothing of it to probe
            continue
        for name in getattr(module, "__all__", []):
            obj = getattr(module, name, None)
            if inspect.isfunction(obj) and obj.__module__.startswith("mascore"):
                out.append((mod_name, name, None, obj))
            elif inspect.isclass(obj) and obj.__module__.startswith("mascore") and not issubclass(obj, BaseException):
                out.append((mod_name, name, None, obj))
                for meth, fn in vars(obj).items():
                    if not meth.startswith("_") and inspect.isfunction(fn):
                        out.append((mod_name, f"{name}.{meth}", obj, fn))
    return out


# ---------------------------------------------------------------- step 1: record baselines


class DoctestRecorder:
    """pytest plugin: wraps public functions, constructors and methods; keeps one small successful call of each."""

    def __init__(self, out: Path, modules) -> None:
        self.out, self.modules, self.calls, self.n = out, modules, {}, 0

    def pytest_configure(self, config) -> None:  # noqa: D401 - pytest hook
        items = public_callables(self.modules)
        self.n = len(items)
        for mod_name, name, owner, obj in items:
            key = f"{mod_name}.{name}"
            if owner is not None:
                setattr(owner, name.rsplit(".", 1)[1], self._wrap(key, obj, method=True))
            elif inspect.isclass(obj):
                if obj.__init__ is not object.__init__:  # a class built by __new__ alone (a NamedTuple) is not wrapped
                    obj.__init__ = self._wrap(key, obj.__init__, method=True, cls=obj)
            else:
                setattr(importlib.import_module(f"mascore.{mod_name}"), name, self._wrap(key, obj))

    def _wrap(self, key, func, method=False, cls=None):
        recorder = self

        def wrapper(*args, **kwargs):
            if key in recorder.calls or (cls is not None and type(args[0]) is not cls) or not _small((args, kwargs)):
                return func(*args, **kwargs)
            try:  # a constructor is replayed as cls(*args), without self
                saved = copy.deepcopy((args[1:] if cls is not None else args, kwargs))
            except Exception:  # noqa: BLE001 - an argument that cannot be copied is not recorded
                return func(*args, **kwargs)
            try:  # pickled before the call: a call may change its arguments (a figure's axes) into unpicklable ones
                pickled = pickle.dumps(saved)
            except Exception:  # noqa: BLE001
                pickled = None
            result = func(*args, **kwargs)
            if pickled is not None:  # the first call that returned normally
                recorder.calls[key] = pickled
            return result

        for attr in ("__name__", "__qualname__", "__doc__", "__module__"):
            setattr(wrapper, attr, getattr(func, attr, None))
        wrapper.__wrapped__ = func
        try:
            wrapper.__signature__ = inspect.signature(func)
        except (TypeError, ValueError):
            pass
        return wrapper

    def pytest_unconfigure(self, config) -> None:
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.out.write_bytes(pickle.dumps({key: pickle.loads(saved) for key, saved in self.calls.items()}))
        print(f"\nrecorded baselines of {len(self.calls)} of {self.n} callables -> {self.out}")


def record(out: Path, modules) -> int:
    import pytest

    import mascore

    root = Path(mascore.__file__).parent
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)  # examples that write files write them here
        return int(pytest.main(["-q", "-p", "no:cacheprovider", "--no-header", "--doctest-modules",
                                "-o", "doctest_optionflags=NORMALIZE_WHITESPACE ELLIPSIS NUMBER",
                                "-p", "no:randomly", str(root)], plugins=[DoctestRecorder(out, modules)]))


# ---------------------------------------------------------------- step 2: spoil, run isolated, classify


def param_docs(func) -> dict[str, str]:
    """The text of each parameter in a NumPy-style docstring (``name : type`` and its indented lines)."""
    doc = inspect.getdoc(func) or ""
    if inspect.isclass(func):
        doc = (inspect.getdoc(func) or "") + "\n" + (inspect.getdoc(func.__init__) or "")
    out, current, in_params = {}, None, False
    for line in doc.splitlines():
        if line.strip() in ("Parameters", "Attributes", "Other Parameters"):
            in_params = True
            continue
        if in_params and line.strip() in ("Returns", "Raises", "Examples", "Notes", "Yields", "See Also", "References"):
            in_params = False
        if not in_params or line.startswith("---"):
            continue
        head = re.match(r"^([A-Za-z_][\w, ]*?)\s*:\s*(.*)$", line)
        if head and not line.startswith(" "):
            for name in head.group(1).split(","):
                current = name.strip()
                out[current] = head.group(2)
            names = [n.strip() for n in head.group(1).split(",")]
        elif current is not None:
            for name in names:
                out[name] += " " + line.strip()
    return out


def extra_spoils(name: str, value, doc: str) -> list[tuple[str, object, bool]]:
    """The spoils :func:`benchmarks.hostile_sweep.spoils` lacks: 1e300, 10**12, ndim, types, graphs, SPD by doc."""
    out: list[tuple[str, object, bool]] = []
    needs_sym = bool(re.search(r"symmetric|undirected", doc, re.I)) and not re.search(r"directed allowed", doc, re.I)
    needs_conn = bool(re.search(r"(?<!dis)connected", doc, re.I))
    needs_pd = bool(re.search(r"positive definite|\bSPD\b", doc, re.I)) and not re.search(r"semi", doc, re.I)
    needs_psd = needs_pd or bool(re.search(r"semidefinite|semi-definite|\bPSD\b|covariance", doc, re.I))
    if isinstance(value, bool) or value is None or callable(value) or _is_settings(value):
        return out
    if isinstance(value, np.random.Generator) or (SEED_NAMES.match(name) and isinstance(value, int)):
        return [("huge seed object", {"seed": 1}, True)]
    if isinstance(value, (int, np.integer)):
        return [("10**12", HUGE_COUNT, False), ("list for int", [int(value)], True)]
    if isinstance(value, (float, np.floating)):
        return [("1e300", 1e300, False), ("list for float", [float(value)], True)]
    try:
        import networkx as nx
    except ImportError:  # pragma: no cover
        nx = None
    if nx is not None and isinstance(value, nx.Graph):
        value = nx.to_numpy_array(value, nodelist=sorted(value.nodes))
    if isinstance(value, (list, tuple)) and value and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                          for x in value):
        value = np.asarray(value, dtype=float)
    if not (isinstance(value, np.ndarray) and value.dtype.kind in "fiu" and value.size):
        return out
    arr = value.astype(float)
    big = arr.copy()
    big.flat[0] = 1e300
    out += [("1e300 entry", big, False), ("extra axis", arr[None, None], False), ("dict for array", {"a": 1}, True),
            ("object array", np.array([object()] * max(arr.shape[0], 1), dtype=object), True)]
    square = arr.ndim >= 2 and arr.shape[-1] == arr.shape[-2] and arr.shape[-1] > 2
    if square and (GRAPH_NAMES.match(name) or _looks_like_adjacency(arr)):
        first = arr if arr.ndim == 2 else arr.reshape(-1, *arr.shape[-2:])[0]
        edges = np.argwhere(np.triu(first, 1) != 0)
        i, j = edges[0] if len(edges) else (0, 1)
        directed = arr.copy()
        directed[..., i, j] = 0.0 if first[i, j] != 0 else 1.0
        cut = arr.copy()
        cut[..., 0, :] = 0.0
        cut[..., :, 0] = 0.0
        n = arr.shape[-1]
        if np.allclose(first.sum(-1), 0) and np.any(np.diagonal(first) != 0):  # a Laplacian stays one
            cut[..., range(n), range(n)] = 0.0
            cut[..., range(n), range(n)] = -cut.sum(-1)
            directed[..., i, i] = directed[..., i, i] - directed[..., i, :].sum(-1)
        out += [("directed graph", directed, needs_sym), ("disconnected graph", cut, needs_conn)]
    elif square and np.allclose(arr, np.swapaxes(arr, -1, -2)):
        indefinite = arr.copy()
        indefinite[..., 0, 0] = -abs(indefinite[..., 0, 0]) - 1.0
        out += [("indefinite", indefinite, needs_psd), ("singular (zero)", np.zeros_like(arr), needs_pd)]
    return out


def _looks_like_adjacency(arr: np.ndarray) -> bool:
    """A symmetric 0/1 matrix with a zero diagonal: read as a graph."""
    return (arr.ndim == 2 and np.isin(arr, (0.0, 1.0)).all() and not np.diagonal(arr).any()
            and np.array_equal(arr, arr.T) and arr.any())


def _trials(name: str, value, doc: str):
    base = spoils(name, value)
    if COUNT_NAMES.match(name) and isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        base = [(k, v, inv or k in ("zero", "negative")) for k, v, inv in base]
    kinds = {k for k, _, _ in base}
    return [(name, k, v, inv) for k, v, inv in base] + [
        (name, k, v, inv) for k, v, inv in extra_spoils(name, value, doc) if k not in kinds]


def _call(func, owner, args, kwargs):
    args = tuple(a.build() if isinstance(a, Replaced) else a for a in args)
    kwargs = {k: v.build() if isinstance(v, Replaced) else v for k, v in kwargs.items()}
    return func(*args, **kwargs)


def _worker(conn, memory_limit: int, modules) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (memory_limit, memory_limit))
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    funcs = {f"{m}.{n}": (owner, f) for m, n, owner, f in public_callables(modules)}
    tmp = tempfile.mkdtemp(prefix="hostile-")
    os.chdir(tmp)
    while True:
        job = conn.recv()
        if job is None:
            return
        key, args, kwargs, arg_name, always_invalid, baseline = job
        owner, func = funcs[key]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = _call(func, owner, args, kwargs)
                if inspect.isclass(func) and not baseline:
                    result = _public_state(result)
        except (ValueError, TypeError) as exc:
            msg = str(exc)
            names = arg_name if isinstance(arg_name, tuple) else (arg_name,)
            named = any(re.search(rf"\b{re.escape(n)}\b", msg) for n in names)
            conn.send(("clear" if named else "unclear", msg[:300]))
            continue
        except MemoryError as exc:
            conn.send(("unclear", f"MemoryError {exc}"[:300]))
            continue
        except Exception as exc:  # noqa: BLE001 - any other exception is an unclear refusal
            conn.send(("unclear", f"{type(exc).__name__}: {exc}"[:300]))
            continue
        try:
            bad = _has_nonfinite(result)
        except Exception:  # noqa: BLE001
            bad = False
        conn.send(("nonfinite" if bad else ("accepted" if always_invalid else "returned"), ""))


def _public_state(obj):
    """The public array attributes of a built object (a model's matrices): where a 1e300 shows as inf."""
    out = {}
    for name in dir(obj):
        if name.startswith("_"):
            continue
        try:
            value = getattr(obj, name)
        except Exception:  # noqa: BLE001
            continue
        if isinstance(value, (np.ndarray, float)):
            out[name] = value
    return out


class Pool:
    """One worker process at a time, restarted after a hang or a crash."""

    def __init__(self, modules) -> None:
        self.modules = modules
        self.ctx = mp.get_context("fork")
        self.proc = None

    def _start(self):
        self.conn, child = self.ctx.Pipe()
        self.proc = self.ctx.Process(target=_worker, args=(child, MEMORY_LIMIT, self.modules), daemon=True)
        self.proc.start()

    def run(self, job) -> tuple[str, str]:
        if self.proc is None or not self.proc.is_alive():
            self._start()
        try:
            self.conn.send(job)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            return ("skip", f"unpicklable: {exc}")
        if self.conn.poll(TIME_LIMIT_S):
            try:
                return self.conn.recv()
            except EOFError:
                pass
            self.proc.join(1)
            return ("crash", f"worker exit {self.proc.exitcode}")
        self.proc.kill()
        self.proc.join()
        self.proc = None
        return ("hang", f"no answer in {TIME_LIMIT_S:g} s")

    def close(self):
        if self.proc is not None and self.proc.is_alive():
            self.conn.send(None)
            self.proc.join(5)


def probe(baselines: Path, csv: Path | None, modules, only: str | None = None) -> list[dict]:
    calls = pickle.loads(baselines.read_bytes())
    items = {f"{m}.{n}": (owner, f) for m, n, owner, f in public_callables(modules)}
    pool, rows = Pool(modules), []
    try:
        for key, (args, kwargs) in sorted(calls.items()):
            if key not in items or key in RECORDS or (only and not re.search(only, key)):
                continue
            owner, func = items[key]
            try:
                sig = inspect.signature(func)
                bound = sig.bind(*args, **kwargs)
            except (TypeError, ValueError):
                continue  # the signature changed since the baseline was recorded
            docs = param_docs(func)
            base_outcome, _ = pool.run((key, bound.args, bound.kwargs, "", False, True))
            nan_documented = base_outcome == "nonfinite"
            if base_outcome not in ("returned", "nonfinite"):
                rows.append({"function": key, "argument": "-", "spoil": "baseline", "outcome": "baseline-fails",
                             "message": ""})
                continue
            for arg_name, value in list(bound.arguments.items()):
                if arg_name == "self":
                    continue
                trials = _trials(arg_name, value, docs.get(arg_name, ""))
                if _is_settings(value):
                    trials += [(f, k, v, inv) for f, k, v, inv in field_spoils(value)]
                for named, kind, spoiled, invalid in trials:
                    trial = copy.copy(bound)
                    trial.arguments = dict(bound.arguments)
                    trial.arguments[arg_name] = spoiled
                    alias = ALIASES.get(key, {}).get(named)
                    outcome, message = pool.run((key, trial.args, trial.kwargs, (named, alias) if alias else named,
                                                 invalid, False))
                    if outcome == "nonfinite":
                        outcome = "returned" if nan_documented else "silent-nan"
                    outcome = adjust(key, arg_name if named == arg_name else f"{arg_name}.{named}", kind, outcome, func)
                    rows.append({"function": key, "argument": arg_name if named == arg_name else f"{arg_name}.{named}",
                                 "spoil": kind, "outcome": outcome, "message": message})
    finally:
        pool.close()
    if csv is not None:
        import pandas as pd

        csv.parent.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(rows).to_csv(csv, index=False)
    report(rows)
    return rows


def adjust(key: str, argument: str, spoil: str, outcome: str, func) -> str:
    """``documented`` for an outcome the API documents (:data:`DOCUMENTED`, an ``inf`` its docstring names)."""
    if outcome not in ("accepted", "silent-nan"):
        return outcome
    if spoil in ("list for float", "list for int"):
        return "returned"  # a one-element list is read as the number by numpy: not always invalid
    for f, a, k, _ in DOCUMENTED:
        if re.search(f, key) and re.search(a, argument.split(".")[-1]) and re.search(k, spoil.split(": ")[-1]):
            return "documented"
    if outcome == "silent-nan" and NONFINITE_DOCUMENTED.search(inspect.getdoc(func) or ""):
        return "documented"
    return outcome


def reclassify(csv: Path, modules) -> list[dict]:
    """The rows of an earlier probe's CSV under today's :data:`RECORDS`, :data:`DOCUMENTED` and docstrings."""
    import pandas as pd

    items = {f"{m}.{n}": f for m, n, _, f in public_callables(modules)}
    rows = [r for r in pd.read_csv(csv).fillna("").to_dict("records") if r["function"] not in RECORDS]
    for r in rows:
        if r["function"] in items:
            r["outcome"] = adjust(r["function"], str(r["argument"]), str(r["spoil"]), r["outcome"],
                                  items[r["function"]])
    return rows


def _module_of(key: str, modules) -> str:
    return max((m for m in modules if key.startswith(m + ".")), key=len, default=key.split(".")[0])


def report(rows: list[dict], modules=None) -> None:
    modules = modules or module_names()
    rows = [r for r in rows if r["outcome"] not in ("skip", "baseline-fails")]
    _line("all", rows)
    for group in sorted({_module_of(r["function"], modules) for r in rows}):
        _line(group, [r for r in rows if _module_of(r["function"], modules) == group])


def _line(title: str, rows: list[dict]) -> None:
    counts = Counter(r["outcome"] for r in rows)
    refused = counts["clear"] + counts["unclear"]
    named = f"{counts['clear'] / refused:.1%}" if refused else "-"
    print(f"{title}: {len(rows)} calls of {len({r['function'] for r in rows})} callables; "
          + ", ".join(f"{o} {counts[o]}" for o in ("clear", "unclear", "silent-nan", "accepted", "documented",
                                                    "returned", "hang", "crash"))
          + f"; refusals naming the argument {named}")


def main(argv: list[str] | None = None) -> int:
    global TIME_LIMIT_S
    parser = argparse.ArgumentParser(prog="python -m benchmarks.hostile_probe", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="record baseline calls from the docstring examples")
    rec.add_argument("--out", type=Path, default=Path("/tmp/hostile-probe/baselines.pkl"))
    prb = sub.add_parser("probe", help="spoil the baselines one argument at a time, each call in a worker")
    prb.add_argument("baselines", type=Path)
    prb.add_argument("--csv", type=Path, default=None)
    prb.add_argument("--only", default=None, help="a regular expression on module.name: probe only those")
    prb.add_argument("--time-limit", type=float, default=TIME_LIMIT_S,
                     help=f"seconds before a call counts as a hang (default {TIME_LIMIT_S:g})")
    rep = sub.add_parser("report", help="the per-module totals of an earlier probe's CSV, reclassified")
    rep.add_argument("csv", type=Path)
    args = parser.parse_args(argv)
    modules = module_names()
    if args.command == "record":
        return record(args.out.resolve(), modules)
    if args.command == "report":
        report(reclassify(args.csv, modules), modules)
        return 0
    TIME_LIMIT_S = args.time_limit
    probe(args.baselines, args.csv, modules, args.only)
    return 0


if __name__ == "__main__":
    sys.exit(main())
