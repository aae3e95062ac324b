"""Install packages into a virtual environment with uv, or with pip where uv cannot be used.

Usage (the Makefile's install steps)::

    python .ci/install.py VENV PIP_INSTALL_ARGUMENTS...

for example ``python .ci/install.py .venv -r requirements.lock``. The arguments are those of
``pip install`` that ``uv pip install`` shares (``-r``, ``-e``, ``--no-deps``,
``--no-build-isolation``, requirement specifiers). The ``python`` that runs this script must
have pip; VENV need not (``make test-min`` creates ``.venv-min`` without pip and installs it
with the project's ``.venv``, whose uv it reuses).

uv, pinned to ``UV_VERSION``, is installed by pip into ``VENV/.uv`` unless the environment
running this script has it already in its own ``.uv`` (outside site-packages: ``pip freeze``
lists exactly what was asked for). It installs the
same wheels as pip, faster. Neither byte-compiles at install (pip is told
``--no-compile``): compiling the whole environment takes about 26 s, and most of its
modules are never imported; Python compiles each when it is first imported and keeps the
``.pyc`` (the Makefile unsets ``PYTHONDONTWRITEBYTECODE`` for its commands).

uv does not read pip's configuration, so the package sources pip is configured with
(``pip config list``: index-url, extra-index-url, find-links, no-index, constraint; e.g. a
local mirror) are passed to it, with pip's rule that a requirement is satisfied by the best
match over all indexes (``--index-strategy unsafe-best-match``; the lock pins every version).
Where uv cannot be installed or fails, pip installs the same packages, and a message says so.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

UV_VERSION = "0.13.8"
PIP_QUIET = ["--quiet", "--disable-pip-version-check"]


def pip_sources(python: Path) -> list[str]:
    """uv options for the package sources pip is configured with.

    Parameters
    ----------
    python : Path
        An interpreter with pip (the one running this script); its pip reports the configuration
        (files and ``PIP_*`` variables, as ``pip config list`` shows them).

    Returns
    -------
    list of str
        ``--index-url``, ``--extra-index-url``, ``--find-links``, ``--no-index`` and
        ``--constraint`` options, each value once, in pip's order; empty where pip uses PyPI
        alone.
    """
    listing = subprocess.run([str(python), "-m", "pip", "config", "list"], capture_output=True, text=True, check=False)
    options = {"index-url": "--index-url", "extra-index-url": "--extra-index-url", "find-links": "--find-links",
               "constraint": "--constraint"}
    found: dict[str, list[str]] = {}
    no_index = False
    for line in listing.stdout.splitlines():
        key, sep, value = line.partition("=")
        if not sep:
            continue
        section, _, name = key.rpartition(".")
        if section not in (":env:", "global", "install"):  # what `pip install` reads (not download.*, ...)
            continue
        try:
            text = str(ast.literal_eval(value))  # pip prints each value as a Python literal
        except (ValueError, SyntaxError):
            continue
        if name == "no-index":
            no_index = no_index or text.lower() in {"1", "true", "yes", "on"}
        elif name in options:
            values = found.setdefault(name, [])
            values.extend(item for item in text.split() if item not in values)
    args = ["--no-index"] if no_index else []
    if "index-url" in found:  # pip uses one index-url: the environment's overrides the files'
        found["index-url"] = found["index-url"][-1:]
    for name, values in found.items():
        for value in values:
            args += [options[name], value]
    if {"index-url", "extra-index-url", "find-links"} & found.keys():
        args += ["--index-strategy", "unsafe-best-match"]
    return args


def bootstrap_uv(venv: Path) -> Path | None:
    """uv at ``UV_VERSION``: ``VENV/.uv/bin/uv``, or that of the environment running this script, else
    installed into ``VENV/.uv`` by the pip of the environment running this script.

    Parameters
    ----------
    venv : Path
        The virtual environment to install into.

    Returns
    -------
    Path or None
        The uv executable, or None if pip could not install it.
    """
    target = venv / ".uv"
    for uv in (target / "bin" / "uv", Path(sys.prefix) / ".uv" / "bin" / "uv"):
        version = subprocess.run([str(uv), "--version"], capture_output=True, text=True,
                                 check=False) if uv.exists() else None
        if version is not None and version.stdout.split()[1:2] == [UV_VERSION]:
            return uv
    uv = target / "bin" / "uv"
    done = subprocess.run([sys.executable, "-m", "pip", "install", *PIP_QUIET, "--upgrade",
                           "--target", str(target), f"uv=={UV_VERSION}"], capture_output=True, text=True, check=False)
    if done.returncode == 0 and uv.exists():
        return uv
    print(done.stdout + done.stderr, file=sys.stderr)
    return None


def install(venv: Path, arguments: list[str]) -> int:
    """Install ``arguments`` (``pip install``'s) into ``venv`` with uv, or pip as the fallback.

    Parameters
    ----------
    venv : Path
        The virtual environment to install into.
    arguments : list of str
        Requirements and options, as for ``pip install``.

    Returns
    -------
    int
        The exit status of the installer that ran last (0: installed).
    """
    python = venv / "bin" / "python"
    uv = bootstrap_uv(venv)
    if uv is None:
        print(f"uv {UV_VERSION} could not be installed: pip installs {' '.join(arguments)} (slower).", flush=True)
    else:
        command = [str(uv), "pip", "install", "--quiet", "--python", str(python),
                   *pip_sources(Path(sys.executable)), *arguments]
        if subprocess.run(command, check=False).returncode == 0:
            return 0
        print(f"uv failed to install {' '.join(arguments)}: pip installs it instead (slower).", flush=True)
    return subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", *PIP_QUIET, "--no-compile",
                           *arguments], check=False).returncode


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    sys.exit(install(Path(sys.argv[1]), sys.argv[2:]))
