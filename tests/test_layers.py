"""The layers of the package: what the core and the cost tables load, and no module using another's private names.

The layers themselves (core < benchmark < studies < CLI and book tools) are an import-linter
contract in ``pyproject.toml``, checked by ``lint-imports`` (``make lint``).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

PACKAGE = Path(__file__).parents[1] / "mascore"

#: Private names still used across modules, to be folded into public ones (issue 28, item 5); none may be added.
KNOWN_PRIVATE_USES: set[tuple[str, str]] = set()


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(dotted: str) -> bool:
    """A private *module* (``mascore._validation``) is the package's own: importing it is allowed."""
    rel = Path(*dotted.split(".")[1:])
    return (PACKAGE / rel).with_suffix(".py").exists() or (PACKAGE / rel / "__init__.py").exists()


def private_uses(source: str, module: str, is_package: bool = False) -> set[tuple[str, str]]:
    """``(module, name)`` for every ``_private`` name of another mascore module that `source` imports or reads."""
    tree = ast.parse(source)
    package = module if is_package else module.rpartition(".")[0]
    aliases: dict[str, str] = {}
    found = set()

    def origin(node: ast.ImportFrom) -> str:
        if node.level == 0:
            return node.module or ""
        base = package.split(".")[:len(package.split(".")) - node.level + 1]
        return ".".join(base + ([node.module] if node.module else []))

    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and origin(node).startswith("mascore"):
            src = origin(node)
            for a in node.names:
                full = f"{src}.{a.name}"
                if a.name.startswith("_") and not a.name.startswith("__") and not _is_module(full):
                    found.add((module, full))
                else:
                    aliases[a.asname or a.name] = full
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("mascore"):
                    aliases[a.asname or a.name.split(".")[0]] = a.name if a.asname else "mascore"
    for node in ast.walk(tree):
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                and node.attr.startswith("_") and not node.attr.startswith("__")):
            full = f"{aliases[node.value.id]}.{node.attr}"
            if not _is_module(full) and not full.startswith(f"{module}."):
                found.add((module, full))
    return found


def test_no_module_uses_another_modules_private_names():
    found = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        found |= private_uses(path.read_text(), _module_name(path), path.name == "__init__.py")
    assert found - KNOWN_PRIVATE_USES == set(), "a module uses another's private names: make them public there"
    assert KNOWN_PRIVATE_USES - found == set(), "a known private use is gone: remove it from KNOWN_PRIVATE_USES"


def test_the_private_names_check_can_fail():
    source = "from .sensing import _check_flag\nfrom . import fusion\nfusion._mix(1, 2, 1)\n"
    assert private_uses(source, "mascore.toy") == {("mascore.toy", "mascore.sensing._check_flag"),
                                                   ("mascore.toy", "mascore.fusion._mix")}
    assert private_uses("from . import _validation\n", "mascore.toy") == set()


def test_the_cost_tables_and_the_specs_load_neither_the_studies_nor_pandas_matplotlib_dask():
    code = textwrap.dedent("""
        import json, sys
        import mascore.agent_cost
        from mascore import estimation
        estimation.method_specs()
        heavy = ("pandas", "matplotlib", "dask", "cvxpy", "mascore.registry", "mascore.ledger", "mascore.papers",
                 "mascore.compare.grid", "mascore.compare.verdicts")
        print(json.dumps([m for m in heavy if m in sys.modules]))
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == []



def _contracts() -> list[dict]:
    import tomllib

    return tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]


def _named(modules: set[str], names: set[str]) -> set[str]:
    """The modules that are one of `names` or inside one of them (a package named covers its modules)."""
    return {m for m in modules if any(m == n or m.startswith(f"{n}.") for n in names)}


def _package_graph():
    grimp = pytest.importorskip("grimp")
    return grimp.build_graph("mascore", include_external_packages=True, cache_dir=None)


def cycles(graph) -> list[list[str]]:
    """The import cycles among the package's modules (every import statement, in functions too)."""
    import networkx as nx

    edges = nx.DiGraph((m, i) for m in graph.modules if m.startswith("mascore")
                       for i in graph.find_modules_directly_imported_by(m) if i.startswith("mascore"))
    return sorted(sorted(c) for c in nx.simple_cycles(edges))


def core_breaches(graph, upper: set[str], forbidden: list[str]) -> list[tuple[str, str]]:
    """(core module, forbidden module) pairs with an import chain; the core: every module not in `upper`."""
    core = {m for m in graph.modules if m.startswith("mascore.")} - _named(set(graph.modules), upper)
    return sorted((m, f) for m in core for f in forbidden
                  if f in graph.modules and graph.chain_exists(importer=m, imported=f, as_packages=True))


def test_the_house_has_no_cycle():
    """No two modules import each other, through any chain (the layers contract lets a ``:`` group do so)."""
    assert cycles(_package_graph()) == []


def test_the_core_by_exclusion_imports_no_layer_above_it():
    """Every module not in a layer above the core is core, listed or not: a new filter module is checked as it is."""
    layers, forbidden = _contracts()
    upper = {m.strip() for layer in layers["layers"] for m in layer.replace("|", ":").split(":")}
    upper |= {m for m in forbidden["forbidden_modules"] if m.startswith("mascore")}
    assert core_breaches(_package_graph(), upper, forbidden["forbidden_modules"]) == []


def test_the_graph_checks_can_fail():
    grimp = pytest.importorskip("grimp")
    graph = grimp.ImportGraph()
    for importer, imported in [("mascore.a", "mascore.b"), ("mascore.b", "mascore.a"), ("mascore.toy", "pandas"),
                               ("mascore.compare.x", "pandas"), ("mascore.c", "mascore.a")]:
        graph.add_import(importer=importer, imported=imported)
    assert cycles(graph) == [["mascore.a", "mascore.b"]]
    assert core_breaches(graph, {"mascore.compare"}, ["pandas", "mascore.compare"]) == [("mascore.toy", "pandas")]
