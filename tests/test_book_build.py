"""The book's build: its local Sphinx extensions (book/_ext) and how `_booktools build` runs it beside the notebooks."""

from __future__ import annotations

import gc
import importlib.util
import json
import os
import subprocess
import sys
import threading
from pathlib import Path
from types import SimpleNamespace

import pytest

pytest.importorskip("sphinx")

ROOT = Path(__file__).resolve().parents[1]
EXT = ROOT / "book" / "_ext"


def extension(name: str):
    """The local Sphinx extension ``book/_ext/<name>.py``, imported from its file."""
    spec = importlib.util.spec_from_file_location(f"book_ext_{name}", EXT / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_local_extension_is_loaded_by_the_book():
    config = (ROOT / "book" / "_config.yml").read_text()
    for path in EXT.glob("*.py"):
        assert f"    {path.stem}: _ext" in config, path.name


def test_the_build_waits_until_the_notebooks_are_executed(tmp_path, monkeypatch):
    pending = extension("notebooks_pending")
    marker = tmp_path / "pending"
    marker.write_text(str(os.getpid()))  # this process "executes the notebooks"
    monkeypatch.setenv(pending.PENDING, str(marker))
    pending.wait_for_notebooks(None, "api/lqr", [""])  # an API page needs no notebook: returns at once
    reader = threading.Thread(target=pending.wait_for_notebooks, args=(None, "notebooks/song2023_rendezvous", [""]))
    reader.start()
    reader.join(timeout=1.0)
    assert reader.is_alive()  # still waiting while the file exists
    assert Path(f"{marker}.waiting").exists()  # and it has told the executor that it needs no core
    marker.unlink()
    reader.join(timeout=30)
    assert not reader.is_alive()


def test_a_dead_executor_does_not_hold_the_build(tmp_path, monkeypatch):
    pending = extension("notebooks_pending")
    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    marker = tmp_path / "pending"
    marker.write_text(done.stdout.strip())  # the id of a process that has ended
    assert not pending.executing(marker)
    assert not pending.executing(tmp_path / "missing")
    marker.write_text(str(os.getpid()))
    assert pending.executing(marker)


def test_api_pages_are_read_first_only_when_notebooks_are_pending(monkeypatch):
    pending = extension("notebooks_pending")
    names = ["intro", "api/lqr", "notebooks/a", "api/agents", "bibliography"]
    unchanged = list(names)
    monkeypatch.delenv(pending.PENDING, raising=False)
    pending.api_pages_first(None, None, unchanged)
    assert unchanged == names
    monkeypatch.setenv(pending.PENDING, "/nonexistent")
    reordered = list(names)
    pending.api_pages_first(None, None, reordered)
    assert reordered == ["api/lqr", "api/agents", "intro", "notebooks/a", "bibliography"]


def test_the_collector_thresholds_are_restored_when_the_build_ends():
    build_gc = extension("build_gc")
    before = gc.get_threshold()
    app = SimpleNamespace()
    try:
        build_gc.collect_less(app)
        assert gc.get_threshold() == build_gc.THRESHOLDS
    finally:
        build_gc.restore(app, None)
    assert gc.get_threshold() == before


@pytest.mark.parametrize(("code", "tex"), [
    ("|M^k| <= alpha mu^k", r"|M^k| <= \alpha \mu^k"),  # words: "alphamu" without the commands
    ("e^T Sigma^{-1} e", r"e^T \Sigma^{-1} e"),
    ("x_i = sum_l c_{l,i} psi_l", r"x_i = \sum_l c_{l,i} \psi_l"),
    ("z_{i,x_j} = x_j + nu_ij", r"z_{i,x_j} = x_j + \nu_ij"),
    ("mu_bar^k + sigma_max(A)^2 + x_hat^T", "mu_bar^k + sigma_max(A)^2 + x_hat^T"),  # names stay names
    (r"\Sigma_i^- + trace(P)^2 + etas^2", r"\Sigma_i^- + \operatorname{trace}(P)^2 + etas^2"),
])
def test_formulas_written_as_code_get_greek_letters_and_operators(code, tex):
    assert extension("api_math").to_tex(code) == tex


AUTOSUMMARY_PAGE = """\
Objects
=======

.. currentmodule:: mascore.lqr

.. autosummary::
   :nosignatures:

   lqr
   TopDownLQR
"""


def _autosummary_table(tmp_path: Path, extensions: list[str]) -> tuple[str, int]:
    """The HTML of an autosummary table with ``:nosignatures:``, and how many signatures were formatted."""
    from sphinx.application import Sphinx

    src = tmp_path / "src"
    src.mkdir(parents=True)
    (src / "conf.py").write_text(f"import sys\nsys.path.insert(0, {str(EXT)!r})\nextensions = {extensions!r}\n")
    (src / "index.rst").write_text(AUTOSUMMARY_PAGE)
    app = Sphinx(str(src), str(src), str(tmp_path / "out"), str(tmp_path / "doctrees"), "html",
                 status=None, warning=None, freshenv=True)
    signatures = []
    app.connect("autodoc-process-signature", lambda *args: signatures.append(args[1]))
    app.build()
    html = (tmp_path / "out" / "index.html").read_text()
    return html[html.index("<table"):html.index("</table>")], len(signatures)


def test_autosummary_tables_without_signatures_are_unchanged_and_format_none(tmp_path):
    plain, formatted = _autosummary_table(tmp_path / "plain", ["sphinx.ext.autodoc", "sphinx.ext.autosummary"])
    unsigned, none = _autosummary_table(tmp_path / "unsigned", ["sphinx.ext.autodoc", "autosummary_unsigned"])
    assert "TopDownLQR" in plain and "lqr" in plain
    assert unsigned == plain
    assert formatted == 2 and none == 0


def test_build_book_needs_the_command_and_its_folder_together(tmp_path):
    from mascore._booktools import build_book

    with pytest.raises(ValueError, match="command"):
        build_book(tmp_path, command=["true"])
    with pytest.raises(ValueError, match="executed"):
        build_book(tmp_path, executed=tmp_path)


def test_a_failing_first_command_stops_the_build_before_any_notebook(tmp_path, capsys, monkeypatch):
    """`make book`'s results stage runs first (``--first``): if it fails, no notebook is executed, the build is
    stopped and the command's exit status is returned."""
    pytest.importorskip("jupyter_cache")
    from mascore._booktools import main

    monkeypatch.chdir(tmp_path)
    book = tmp_path / "book"
    (book / "notebooks").mkdir(parents=True)
    (book / "notebooks" / "x.ipynb").write_text("not a notebook: executing it would fail")
    status = main(["build", "--log", str(tmp_path / "build.log"), "--first", f"{sys.executable} -c 'exit(3)'"])
    assert status == 3
    assert "failed (exit status 3): the book's build is stopped" in capsys.readouterr().err
    assert not (book / "_build" / "notebooks-pending").exists()


def _tiny_book(folder: Path, toc: bool = True) -> Path:
    """A book of one page that builds in a few seconds (without its table of contents it does not build)."""
    book = folder / "book"
    (book / "notebooks").mkdir(parents=True)
    (book / "_config.yml").write_text('title: tiny\nexecute:\n  execute_notebooks: "off"\n')
    (book / "intro.md").write_text("# Tiny\n\nOne page.\n")
    if toc:
        (book / "_toc.yml").write_text("format: jb-book\nroot: intro\n")
    return book


def _python(code: str) -> list[str]:
    return [sys.executable, "-c", code]


def test_make_tests_other_tests_follow_the_notebooks_and_the_html_checks_follow_the_book(tmp_path, capsys):
    """`make test`: the other tests (``then``) start once the notebooks' command has ended, beside the rest of the
    build; the HTML checks (``checks``) run once the book is built, their output shown; a failing check fails."""
    pytest.importorskip("jupyter_cache")
    from mascore._booktools import build_book

    book, executed = _tiny_book(tmp_path), tmp_path / "executed"
    executed.mkdir()
    html = book / "_build" / "html" / "intro.html"
    order = tmp_path / "order.txt"
    built, status = build_book(
        book, command=_python(f"import time; time.sleep(0.5); open({str(executed / 'done')!r}, 'w')"), executed=executed,
        log=tmp_path / "build.log",
        then=_python(f"import os; open({str(order)!r}, 'a').write('then %s' % os.path.exists({str(executed / 'done')!r}))"),
        checks=_python(f"import os; print('checked', os.path.exists({str(html)!r})); raise SystemExit(5)"))
    assert built == 0
    assert order.read_text() == "then True"  # started after the notebooks' command
    assert "checked True" in capsys.readouterr().out  # after the book was built; its output is shown
    assert status == 5


def test_without_a_built_book_the_html_checks_do_not_run_and_the_other_tests_still_count(tmp_path):
    pytest.importorskip("jupyter_cache")
    from mascore._booktools import build_book

    book, executed = _tiny_book(tmp_path, toc=False), tmp_path / "executed"
    executed.mkdir()
    ran = tmp_path / "checks-ran"
    built, status = build_book(book, command=_python("pass"), executed=executed, log=tmp_path / "build.log",
                               then=_python("raise SystemExit(4)"), checks=_python(f"open({str(ran)!r}, 'w')"))
    assert built != 0 and status == 4
    assert not ran.exists()


def test_the_intro_is_executed_with_the_notebooks(tmp_path):
    pytest.importorskip("jupyter_cache")
    pytest.importorskip("myst_nb")
    from jupyter_cache import get_cache

    from mascore._booktools import _add_notebooks

    cache = get_cache(str(tmp_path / "cache"))
    _add_notebooks(cache, ROOT / "book")
    uris = {Path(record.uri).name for record in cache.list_project_records()}
    assert uris == {p.name for p in (ROOT / "notebooks").glob("*.ipynb")} | {"intro.md"}
    intro = next(r for r in cache.list_project_records() if r.uri.endswith("intro.md"))
    code = [c.source for c in cache.get_project_notebook(intro.pk).nb.cells if c.cell_type == "code"]
    assert code and "reading_paths" in code[0]  # read as MyST: the code cells, not the page as one text cell


def test_make_dry_run_prints_the_book_commands_without_running_them():
    """`make -n book` / `make -n test` print the build's command line (the results stage runs inside it, through
    a variable: a recipe line naming $(MAKE) itself would be run even by `make -n`)."""
    import shutil

    if shutil.which("make") is None:
        pytest.skip("no make here")
    for target in ("book", "test"):
        out = subprocess.run(["make", "-n", target], cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert "mascore._booktools build" in out.stdout and "--first" in out.stdout
        assert "reading sources" not in out.stdout + out.stderr  # nothing was built


def _notebook(path: Path, *sources: str) -> Path:
    """A notebook at `path` with code cells `sources` (and one Markdown cell, which does not count as code)."""
    import nbformat

    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# " + "words " * 200)]
                                  + [nbformat.v4.new_code_cell(s) for s in sources])
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nbformat.write(nb, path)
    return path


def test_the_code_length_counts_the_code_cells_of_a_notebook_and_the_whole_text_of_a_page(tmp_path):
    pytest.importorskip("nbformat")
    from mascore._booktools import _code_length

    assert _code_length(_notebook(tmp_path / "a.ipynb", "x = 1", "y = 22")) == len("x = 1") + len("y = 22")
    assert _code_length(_notebook(tmp_path / "b.ipynb")) == 0
    page = tmp_path / "intro.md"
    page.write_text("# Intro\n\n```{code-cell} ipython3\nprint(1)\n```\n")
    assert _code_length(page) == len(page.read_text())
    (tmp_path / "broken.ipynb").write_text("not a notebook")
    assert _code_length(tmp_path / "broken.ipynb") == 0


def test_a_file_that_is_no_notebook_is_reported_as_failed_not_raised(tmp_path):
    """The executor lists it among the failed notebooks (the book's build then shows why); the others run."""
    pytest.importorskip("jupyter_cache")
    from jupyter_cache import get_cache

    from mascore._booktools import _run_project

    cache = get_cache(str(tmp_path / "cache"))
    (tmp_path / "broken.ipynb").write_text("not a notebook")
    cache.add_nb_to_project(str(tmp_path / "broken.ipynb"))
    assert _run_project(cache, timeout=60) == [str(tmp_path / "broken.ipynb")]


def test_the_notebooks_are_executed_longest_first_and_their_kernels_killed(tmp_path):
    """One notebook at a time (`all_cores` never true), so the order in which they run is the order handed out:
    the longest code first. Each kernel is killed after its last cell: its exit handlers never run. The outputs
    are in the cache."""
    pytest.importorskip("jupyter_cache")
    pytest.importorskip("ipykernel")
    from jupyter_cache import get_cache

    from mascore._booktools import _run_project

    log = tmp_path / "order.txt"
    run = f"import atexit, pathlib\nwith open({str(log)!r}, 'a') as f:\n    f.write('{{}}\\n')\n"
    exit_hook = f"atexit.register(pathlib.Path({str(tmp_path / 'exited')!r}).touch)\n"
    cache = get_cache(str(tmp_path / "cache"))
    for name, padding in [("short", 0), ("long", 400), ("middle", 200)]:
        code = run.format(name) + exit_hook + "#" * padding
        cache.add_nb_to_project(str(_notebook(tmp_path / f"{name}.ipynb", code, "print('done')")))
    assert _run_project(cache, timeout=120, all_cores=lambda: False) == []
    assert log.read_text().split() == ["long", "middle", "short"]
    assert not (tmp_path / "exited").exists()  # killed, not asked to exit
    outputs = [cache.get_cache_bundle(record.pk).nb.cells[-1].outputs for record in cache.list_cache_records()]
    assert len(outputs) == 3 and all(out[0]["text"] == "done\n" for out in outputs)


def test_make_tests_notebook_kernel_keeps_no_history_and_exits_at_once_after_the_last_cell(tmp_path, monkeypatch):
    """`make test` runs the notebooks (nbmake) with the kernel of .ci/jupyter: ipykernel with its history in memory
    and no name left in the notebook's namespace, which, once shut down after the last cell, runs the exit handlers
    the notebook registered and then ends at once, without clearing the namespace (an object of the notebook is
    never deleted)."""
    pytest.importorskip("nbmake")
    pytest.importorskip("ipykernel")
    from nbmake.nb_run import NotebookRun

    make = (ROOT / "Makefile").read_text()
    assert "JUPYTER_PATH=$(CURDIR)/.ci/jupyter" in make and "--nbmake-kernel=python3-quick-exit" in make
    spec = json.loads((ROOT / ".ci" / "jupyter" / "kernels" / "python3-quick-exit" / "kernel.json").read_text())
    assert any("atexit.register(os._exit, 0)" in arg for arg in spec["argv"])
    monkeypatch.setenv("JUPYTER_PATH", str(ROOT / ".ci" / "jupyter"))
    exited, cleared = tmp_path / "exited", tmp_path / "cleared"
    cells = (f"import atexit, pathlib\natexit.register(pathlib.Path({str(exited)!r}).touch)",
             f"class Kept:\n    def __del__(self):\n        pathlib.Path({str(cleared)!r}).touch()\nkept = Kept()",
             "print(get_ipython().history_manager.hist_file, 'os' in dir(), 'gc' in dir())")
    result = NotebookRun(_notebook(tmp_path / "nb.ipynb", *cells), 60, kernel="python3-quick-exit").execute()
    assert result.error is None
    assert result.nb.cells[-1].outputs[0]["text"].split() == [":memory:", "False", "False"]
    assert exited.exists() and not cleared.exists()


NUMPYDOC_PAGE = """\
Objects
=======

.. autofunction:: mascore.lqr.lqr

.. autoclass:: mascore.lqr.TopDownLQR

.. autofunction:: mascore.kalman.nees
"""


def _numpydoc_page(tmp_path: Path, extension_name: str, monkeypatch) -> tuple[str, int]:
    """The HTML body of three documented objects, and how many times numpydoc's template was compiled."""
    import jinja2
    from sphinx.application import Sphinx

    compiled = []
    get_template = jinja2.Environment.get_template

    def counting(self, name, *args, **kwargs):
        compiled.extend([name] if name == "numpydoc_docstring.rst" else [])
        return get_template(self, name, *args, **kwargs)

    src = tmp_path / "src"
    src.mkdir(parents=True)
    (src / "conf.py").write_text(f"import sys\nsys.path.insert(0, {str(EXT)!r})\n"
                                 f"extensions = ['sphinx.ext.autodoc', {extension_name!r}]\n"
                                 "numpydoc_show_class_members = False\nautodoc_typehints = 'none'\n")
    (src / "index.rst").write_text(NUMPYDOC_PAGE)
    with monkeypatch.context() as patched:
        patched.setattr(jinja2.Environment, "get_template", counting)
        app = Sphinx(str(src), str(src), str(tmp_path / "out"), str(tmp_path / "doctrees"), "html",
                     status=None, warning=None, freshenv=True)
        app.build()
    html = (tmp_path / "out" / "index.html").read_text()
    return html[html.index('<section id="objects">'):html.index("</section>")], len(compiled)


def test_numpydoc_renders_the_same_pages_with_its_template_compiled_once(tmp_path, monkeypatch):
    """book/_ext/numpydoc_template.py sets numpydoc up with its template compiled once per loader (the builder's,
    and numpydoc's own for the signatures): the same HTML as numpydoc's, which compiles it at every docstring
    and signature."""
    numpydoc = pytest.importorskip("numpydoc.numpydoc")
    monkeypatch.setattr(numpydoc, "get_doc_object", numpydoc.get_doc_object)  # numpydoc's setup replaces it
    plain, compiled_plain = _numpydoc_page(tmp_path / "plain", "numpydoc", monkeypatch)
    once, compiled_once = _numpydoc_page(tmp_path / "once", "numpydoc_template", monkeypatch)
    assert "TopDownLQR" in plain and "Parameters" in plain
    assert once == plain
    assert compiled_plain >= 6 and compiled_once == 2
