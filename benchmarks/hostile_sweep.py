"""A hostile sweep: every public function of the core, called with one argument spoiled at a time.

Not a benchmark of speed but of behaviour on bad input (issue "Nothing silent").
Two steps:

1. ``record``: run the core unit tests with a pytest plugin that wraps every
   public function of the concept modules and keeps, for each, the first call
   that returned normally (small arguments only): the *baseline* calls.
2. ``sweep``: replay each baseline with one argument spoiled (NaN or inf entry,
   wrong shape, non-symmetric or indefinite matrix, zero or negative number,
   zero or negative count, a float for a count, a string, a negative seed) and
   classify what happens:

   * ``clear``: ``ValueError``/``TypeError`` whose message names the argument;
   * ``unclear``: another exception, or a message that does not name it;
   * ``silent-nan``: returned with NaN/inf in the output (unless the unspoiled baseline
     call already returns NaN/inf: documented ones, such as a metric a method lacks);
   * ``accepted``: returned normally although the spoil is always invalid
     (NaN/inf entries, a string for a number, a negative seed, a count < 1, dt <= 0);
   * ``returned``: returned normally from a spoil that can be valid (a smaller
     array, a non-symmetric matrix): not counted against the function;
   * ``hang``: no answer within the time limit.

Usage::

    python -m benchmarks.hostile_sweep record --out results/sweep/baselines.pkl
    python -m benchmarks.hostile_sweep sweep results/sweep/baselines.pkl --csv results/sweep/outcomes.csv

A settings dataclass argument (fields declared with ``mascore.registry.setting``) is
spoiled as a whole (a string) and field by field: each field gets the spoils of its value,
and the settings are rebuilt with ``dataclasses.replace`` as part of the call, so a
settings class that refuses the value when built counts as a (named) refusal. The paper
modules and the comparison are swept with ``--modules`` (e.g. ``papers.ren2005 compare``);
the summary is printed for all calls and per module.

Run ``record`` against an older checkout (``PYTHONPATH=<checkout>``) to compare
before and after with the same kind of calls.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import importlib
import inspect
import pickle
import re
import signal
import sys
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

#: Concept modules swept (the paper modules, plotting and the ledger are not).
MODULES = ("agents", "graphs", "kalman", "noise", "consensus", "rendezvous", "flocking", "synchronization",
           "lqr", "sensing", "team_model", "distributed_kf", "centralized_team_filter", "team_observability",
           "distributed_ekf", "ellipsoids", "set_membership", "observers")

#: Arguments whose zero or negative values are always invalid.
POSITIVE_NAMES = re.compile(r"^(dt|t_final|horizon|sensing_range|.*_range|rtol|atol|tol|dwell|.*_time)$")
COUNT_NAMES = re.compile(r"^(n|N|m|size|n_.*|.*_steps|.*_runs|steps|repeat|number|dwell|k_max|kmax)$")
SEED_NAMES = re.compile(r"^(rng|seed)$")

MAX_BASELINE_SIZE = 20_000
TIME_LIMIT_S = 10


# ---------------------------------------------------------------- step 1: record baselines


def public_functions(modules: tuple[str, ...] | None = None) -> list[tuple[str, str, object]]:
    """(module, name, function) for every public callable of the swept modules."""
    out = []
    for mod_name in modules or MODULES:
        module = importlib.import_module(f"mascore.{mod_name}")
        for name in getattr(module, "__all__", []):
            obj = getattr(module, name, None)
            if inspect.isfunction(obj) and obj.__module__ == module.__name__:
                out.append((mod_name, name, obj))
    return out


def _small(value) -> bool:
    sizes = []

    def walk(v):
        if isinstance(v, np.ndarray):
            sizes.append(v.size)
        elif isinstance(v, (list, tuple)):
            for x in v:
                walk(x)
        elif isinstance(v, dict):
            for x in v.values():
                walk(x)

    walk(value)
    return sum(sizes) <= MAX_BASELINE_SIZE


class Recorder:
    """pytest plugin: wraps the public functions and records one successful call of each."""

    def __init__(self, out: Path, modules: tuple[str, ...] | None = None) -> None:
        self.out = out
        self.modules = modules
        self.calls: dict[str, tuple] = {}

    def pytest_configure(self, config) -> None:  # noqa: D401 - pytest hook
        functions = public_functions(self.modules)
        self.n_functions = len(functions)
        for mod_name, name, func in functions:
            module = importlib.import_module(f"mascore.{mod_name}")
            setattr(module, name, self._wrap(mod_name, name, func))

    def _wrap(self, mod_name, name, func):
        key = f"{mod_name}.{name}"
        recorder = self

        def wrapper(*args, **kwargs):
            if key in recorder.calls or not _small((args, kwargs)):
                return func(*args, **kwargs)
            try:
                saved = copy.deepcopy((args, kwargs))
            except Exception:  # noqa: BLE001 - an argument that cannot be copied is not recorded
                return func(*args, **kwargs)
            result = func(*args, **kwargs)
            try:
                pickle.dumps(saved)
                recorder.calls[key] = saved
            except Exception:  # noqa: BLE001
                pass
            return result

        wrapper.__wrapped__ = func
        wrapper.__name__ = func.__name__
        wrapper.__doc__ = func.__doc__
        wrapper.__signature__ = inspect.signature(func)
        return wrapper

    def pytest_unconfigure(self, config) -> None:
        self.out.parent.mkdir(parents=True, exist_ok=True)
        kept = {}
        for key, call in self.calls.items():  # a call holding a class of a module gone by now is dropped
            try:
                pickle.dumps(call)
                kept[key] = call
            except Exception:  # noqa: BLE001
                pass
        self.calls = kept
        self.out.write_bytes(pickle.dumps(self.calls))
        print(f"\nrecorded baselines of {len(self.calls)} of {self.n_functions} functions -> {self.out}")


def record(out: Path, tests: list[str], modules: tuple[str, ...] | None = None) -> int:
    import pytest

    return pytest.main(["-q", "-p", "no:cacheprovider", "--no-header", *tests],
                       plugins=[Recorder(out, modules)])


# ---------------------------------------------------------------- step 2: spoil and classify


class Replaced:
    """A settings dataclass with one field spoiled, built (``dataclasses.replace``) only when the call is made.

    The build is part of the call: a settings class that refuses the value on ``replace`` counts
    as a refusal of the call, named if the message names the field.
    """

    def __init__(self, settings, field: str, value) -> None:
        self.settings, self.field, self.value = settings, field, value

    def build(self):
        return dataclasses.replace(self.settings, **{self.field: self.value})


def _is_settings(value) -> bool:
    """A settings dataclass instance: a ``...Settings`` class or fields declared with ``mascore.registry.setting``."""
    return (dataclasses.is_dataclass(value) and not isinstance(value, type)
            and (type(value).__name__.endswith("Settings")
                 or any("source" in f.metadata for f in dataclasses.fields(value))))


def field_spoils(value) -> list[tuple[str, str, object, bool]]:
    """(field, kind, Replaced, always_invalid): each field of a settings dataclass spoiled in turn."""
    out = []
    for f in dataclasses.fields(value):
        current = getattr(value, f.name)
        if isinstance(current, tuple) and current and all(isinstance(x, tuple) for x in current):
            current = np.asarray(current, dtype=float) if _numeric_rows(current) else current
        elif isinstance(current, tuple):
            current = list(current)
        for kind, spoiled, invalid in spoils(f.name, current):
            out.append((f.name, f"{f.name}: {kind}", Replaced(value, f.name, spoiled), invalid))
    return out


def _numeric_rows(rows) -> bool:
    return all(isinstance(x, (int, float)) and not isinstance(x, bool) for r in rows for x in r) and \
        len({len(r) for r in rows}) == 1


def spoils(name: str, value) -> list[tuple[str, object, bool]]:
    """(kind, spoiled value, always_invalid) for one argument value."""
    out: list[tuple[str, object, bool]] = []
    if isinstance(value, bool) or value is None or callable(value):
        return out
    if _is_settings(value):
        return [("string for settings", "settings", True)]
    if isinstance(value, np.random.Generator) or (SEED_NAMES.match(name) and isinstance(value, int)):
        return [("negative seed", -1, True), ("string seed", "seed", True)]
    if isinstance(value, (int, np.integer)):
        count = bool(COUNT_NAMES.match(name))
        out += [("zero", 0, count), ("negative", -1, count), ("float for int", float(value) + 0.5, False),
                ("string", "3", True)]
        return out
    if isinstance(value, (float, np.floating)):
        positive = bool(POSITIVE_NAMES.match(name))
        return [("nan", float("nan"), True), ("inf", float("inf"), True), ("zero", 0.0, positive),
                ("negative", -abs(float(value)) - 1.0, positive), ("string", "0.1", True)]
    arr = None
    if isinstance(value, np.ndarray) and value.dtype.kind == "f" and value.size:
        arr = value
    elif isinstance(value, list) and value and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
        arr = np.asarray(value, dtype=float)
    if arr is None:
        return out
    nan, inf = arr.copy(), arr.copy()
    nan.flat[0], inf.flat[-1] = np.nan, np.inf
    out += [("nan entry", nan, True), ("inf entry", inf, True), ("string", "array", True)]
    if arr.ndim >= 1 and arr.shape[0] > 1:
        out.append(("wrong shape", arr[:-1], False))
    if arr.ndim >= 2 and arr.shape[-1] == arr.shape[-2] and arr.shape[-1] > 1:
        nonsym = arr.copy()
        nonsym[..., 0, -1] += 1.0
        out += [("non-symmetric", nonsym, False), ("negated (indefinite)", -arr, False),
                ("zero matrix", np.zeros_like(arr), False)]
    return out


def _has_nonfinite(result) -> bool:
    seen = 0

    def walk(v, depth=0) -> bool:
        nonlocal seen
        seen += 1
        if seen > 10_000 or depth > 4:
            return False
        if isinstance(v, np.ndarray):
            return v.dtype.kind in "fc" and not np.all(np.isfinite(v))
        if isinstance(v, (float, np.floating)):
            return not np.isfinite(v)
        if isinstance(v, (list, tuple)):
            return any(walk(x, depth + 1) for x in v)
        if isinstance(v, dict):
            return any(walk(x, depth + 1) for x in v.values())
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return any(walk(getattr(v, f.name), depth + 1) for f in dataclasses.fields(v))
        return False

    return walk(result)


class _Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise _Timeout


def classify(func, args, kwargs, arg_name: str, always_invalid: bool, nan_documented: bool = False) -> str:
    signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIME_LIMIT_S)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            args = tuple(a.build() if isinstance(a, Replaced) else a for a in args)
            kwargs = {k: v.build() if isinstance(v, Replaced) else v for k, v in kwargs.items()}
            result = func(*args, **kwargs)
    except _Timeout:
        return "hang"
    except (ValueError, TypeError) as exc:
        return "clear" if arg_name in str(exc) else "unclear"
    except Exception:  # noqa: BLE001 - any other exception is an unclear refusal
        return "unclear"
    finally:
        signal.alarm(0)
    if _has_nonfinite(result) and not nan_documented:
        return "silent-nan"
    return "accepted" if always_invalid else "returned"


def _baseline_has_nonfinite(func, args, kwargs) -> bool:
    """Whether the unspoiled call already returns NaN/inf (documented ones, e.g. a metric a method lacks)."""
    signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIME_LIMIT_S)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return _has_nonfinite(func(*copy.deepcopy(args), **copy.deepcopy(kwargs)))
    except Exception:  # noqa: BLE001 - a baseline that no longer runs: judge its spoils as usual
        return False
    finally:
        signal.alarm(0)


def sweep(baselines: Path, csv: Path | None, modules: tuple[str, ...] | None = None) -> Counter:
    calls = pickle.loads(baselines.read_bytes())
    functions = {f"{m}.{n}": f for m, n, f in public_functions(modules)}
    rows = []
    for key, (args, kwargs) in sorted(calls.items()):
        func = functions.get(key)
        if func is None:
            continue
        try:
            bound = inspect.signature(func).bind(*args, **kwargs)
        except TypeError:
            continue  # the signature changed since the baseline was recorded
        nan_documented = _baseline_has_nonfinite(func, args, kwargs)
        for arg_name, value in list(bound.arguments.items()):
            trials = [(arg_name, kind, spoiled, invalid) for kind, spoiled, invalid in spoils(arg_name, value)]
            if _is_settings(value):
                trials += field_spoils(value)
            for named, kind, spoiled, always_invalid in trials:
                trial = copy.deepcopy(bound)
                trial.arguments[arg_name] = spoiled
                outcome = classify(func, trial.args, trial.kwargs, named, always_invalid, nan_documented)
                rows.append({"function": key, "argument": arg_name if named == arg_name else f"{arg_name}.{named}",
                             "spoil": kind, "outcome": outcome})
    counts = Counter(r["outcome"] for r in rows)
    if csv is not None:
        import pandas as pd

        csv.parent.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(rows).to_csv(csv, index=False)
    _report("all", rows)
    for group in sorted({r["function"].rsplit(".", 1)[0] for r in rows}):
        _report(group, [r for r in rows if r["function"].rsplit(".", 1)[0] == group])
    return counts


def _report(title: str, rows: list[dict]) -> None:
    counts = Counter(r["outcome"] for r in rows)
    refused = counts["clear"] + counts["unclear"]
    named = f"{counts['clear'] / refused:.1%}" if refused else "-"
    print(f"{title}: {len(rows)} calls of {len({r['function'] for r in rows})} functions; "
          + ", ".join(f"{o} {counts[o]}" for o in ("clear", "unclear", "silent-nan", "accepted", "returned", "hang"))
          + f"; refusals naming the argument {named}")


def main(argv: list[str] | None = None) -> int:
    global TIME_LIMIT_S
    parser = argparse.ArgumentParser(prog="python -m benchmarks.hostile_sweep", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="record baseline calls from the core unit tests")
    rec.add_argument("--out", type=Path, default=Path("results/sweep/baselines.pkl"))
    rec.add_argument("tests", nargs="*", default=[f"tests/test_{m}.py" for m in (
        "agents_noise", "graphs", "kalman", "consensus", "flocking", "synchronization", "lqr", "sensing",
        "distributed_kf", "distributed_ekf", "ellipsoids", "set_membership", "observers")])
    swp = sub.add_parser("sweep", help="spoil the baselines one argument at a time")
    swp.add_argument("baselines", type=Path)
    swp.add_argument("--csv", type=Path, default=None)
    swp.add_argument("--time-limit", type=int, default=TIME_LIMIT_S,
                     help=f"seconds before a call counts as a hang (default {TIME_LIMIT_S}; raise it on a loaded machine)")
    for p in (rec, swp):
        p.add_argument("--modules", nargs="+", default=None,
                       help="modules of mascore to sweep (default: the concept modules), e.g. papers.ren2005")
    args = parser.parse_args(argv)
    modules = tuple(args.modules) if args.modules else None
    if args.command == "record":
        return int(record(args.out, [t for t in args.tests if Path(t).exists()], modules))
    TIME_LIMIT_S = args.time_limit
    sweep(args.baselines, args.csv, modules)
    return 0


if __name__ == "__main__":
    sys.exit(main())
