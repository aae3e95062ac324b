"""The book's build reads the API pages while its notebooks are still being executed.

``python -m mascore._booktools build`` starts ``jupyter-book build`` and executes the notebooks
(or runs the command that executes them) at the same time, on the other core: Sphinx reads
one page after the other, and the API pages, which only import the package, come first.
Before it reads a page that shows executed cells, the build waits until the notebooks are in
the cache: while the file named by the environment variable :data:`PENDING` exists and the
process whose id it holds (the one executing the notebooks) is alive. It first creates that
file's name + ``.waiting``: the executor then runs notebooks on every core (one until then, so
that no notebook that times its code shares its core with the build).

Without that variable (a plain ``jupyter-book build``) nothing waits and nothing is reordered.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from sphinx.util import logging

#: Environment variable naming the file that exists while the notebooks are being executed.
PENDING = "MASCORE_NOTEBOOKS_PENDING"
#: Seconds between two looks at that file.
POLL = 0.1

logger = logging.getLogger(__name__)


def needs_no_execution(docname: str) -> bool:
    """Whether page `docname` can be read before any notebook is executed (an API page)."""
    return docname.startswith("api/")


def api_pages_first(app, env, docnames: list[str]) -> None:
    """Read the pages that need no executed notebook first (a stable reordering, in place)."""
    if os.environ.get(PENDING):
        docnames.sort(key=lambda name: not needs_no_execution(name))


def executing(pending: Path) -> bool:
    """Whether the notebooks are still being executed: `pending` exists and its process is alive."""
    try:
        pid = int(pending.read_text())
        os.kill(pid, 0)  # signal 0: only checks that the process exists
    except (FileNotFoundError, ValueError, ProcessLookupError):
        return False
    except PermissionError:  # it exists, owned by another user
        return True
    return True


def wait_for_notebooks(app, docname: str, source: list[str]) -> None:
    """Before page `docname` is read, wait until the notebooks' execution has ended."""
    pending = os.environ.get(PENDING)
    if not pending or needs_no_execution(docname):
        return
    Path(pending + ".waiting").touch()  # tells the executor that this process no longer needs a core
    start = time.monotonic()
    while executing(Path(pending)):
        time.sleep(POLL)
    if time.monotonic() - start > POLL:
        logger.info(f"waited {time.monotonic() - start:.1f} s for the notebooks' execution before {docname}")


def setup(app):
    app.connect("env-before-read-docs", api_pages_first)
    app.connect("source-read", wait_for_notebooks)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
