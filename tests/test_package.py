"""The package's public face: lazy submodules and a light top-level import."""

import subprocess
import sys

import pytest

import mascore


@pytest.mark.parametrize("name", mascore.SUBMODULES)
def test_every_submodule_is_reachable_from_the_package(name):
    module = getattr(mascore, name)
    assert module.__name__ == f"mascore.{name}"
    assert name in dir(mascore)


def test_unknown_attribute_raises_attribute_error():
    with pytest.raises(AttributeError, match="no_such_module"):
        mascore.no_such_module  # noqa: B018


def test_bare_import_does_not_load_cvxpy():
    code = "import sys, mascore; print('cvxpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_progress_bar_passes_items_through_and_can_be_off():
    from mascore._progress import progress_bar

    items = [3, 1, 2]
    assert progress_bar(items, enabled=False) is items
    assert list(progress_bar(items, desc="test", disable=True)) == items


def test_progress_bar_is_silent_in_a_notebook_kernel_without_ipywidgets():
    # In a Jupyter kernel without ipywidgets, importing tqdm.auto warns "IProgress not found";
    # that warning must not reach the rendered book.
    code = (
        "import sys, types, IPython\n"
        "sys.modules['ipywidgets'] = None\n"  # as if not installed
        "sys.modules['ipykernel.zmqshell'] = types.ModuleType('ipykernel.zmqshell')\n"  # as in a kernel
        "from mascore._progress import progress_bar\n"
        "print(list(progress_bar([1, 2], desc='x', file=sys.stdout)))\n"
    )
    out = subprocess.run([sys.executable, "-W", "always", "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("[1, 2]")
    assert "IProgress" not in out.stderr and "Warning" not in out.stderr, out.stderr


def test_median_time_calls_once_to_warm_up_then_repeat_times_number():
    from mascore._timing import median_time

    calls = []
    assert median_time(lambda: calls.append(1), repeat=3, number=2) >= 0.0
    assert len(calls) == 1 + 3 * 2
    with pytest.raises(ValueError, match="repeat"):
        median_time(lambda: None, repeat=0)


def test_readme_python_snippets_run():
    """Every ```python block of the README runs as printed (the first thing a new user copies)."""
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", readme, flags=re.S)
    assert blocks, "the README shows no Python snippet"
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})


def test_exceptions_are_exported_from_the_package_and_subclass_builtins():
    import mascore

    for name, base in [("SolverError", RuntimeError), ("RiccatiError", ArithmeticError),
                       ("IsolatedAgentError", ValueError), ("ConsensusBreakdownError", ValueError),
                       ("DivergenceError", FloatingPointError)]:
        exc = getattr(mascore, name)
        assert issubclass(exc, base) and exc.__module__ == "mascore.exceptions"
