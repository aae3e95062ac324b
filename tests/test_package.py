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
