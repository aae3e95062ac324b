"""Maintenance of the book: figure captions in the notebooks, checks of the rendered HTML.

``python -m mascore._booktools sync [NOTEBOOK ...]`` (``make sync``) writes the API reference pages
``book/api/*.md`` from each module's ``__all__`` (:func:`write_api_pages`; a long module's reference
split into sub-pages by topic, :data:`API_TOPICS`) and their entries in ``book/_toc.yml``, and, into every code cell
that draws a registered figure (``STUDY.draw("NAME", ...)`` or
``REGISTRY.study(...).draw("NAME", ...)``), the MyST-NB figure metadata of that
figure: ``{"mystnb": {"figure": {"name": "fig-PAPER-NAME", "caption": ...}}}``,
the caption taken from the paper's registry. The book then renders the cell's
image as a numbered, captioned figure that the prose can reference with
``{numref}`fig-PAPER-NAME```. The tests check that the notebooks are in sync.

:func:`page_problems` lists what a reader would trip on in one built HTML page.
"""

from __future__ import annotations

import importlib
import json
import re
import shlex
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from .registry import PaperRegistry, Study, paper_registries, study_modules

__all__ = [
    "API_GROUPS",
    "API_TOPICS",
    "api_groups",
    "api_page",
    "api_pages",
    "api_topics",
    "chapter_studies",
    "drawn_figures",
    "measure_page",
    "measure_pages",
    "page_problems",
    "plain_text",
    "public_objects",
    "sync_notebook",
    "toc_with_api_pages",
    "topic_key",
    "write_api_pages",
]

#: The modules of the API reference, grouped as in the book's table of contents; the papers' modules
#: are not listed here but discovered (:func:`api_groups`).
API_GROUPS: dict[str, tuple[str, ...]] = {
    "Shared building blocks": ("agents", "graphs", "noise", "kalman", "sensing"),
    "Consensus and cooperative control": ("consensus", "consensus_filters", "rendezvous", "flocking", "synchronization",
                                          "lqr", "riccati"),
    "Estimation": ("estimation", "team_model", "distributed_kf", "centralized_team_filter", "team_observability",
                   "distributed_ekf", "sensor_network", "fusion", "fusion_forwarding", "fusion_cost", "fusion_links",
                   "own_state", "ellipsoids", "set_membership", "observers", "network_observer"),
    "Comparing the methods": ("compare", "papers.compare", "agent_cost", "sweep"),
    "Reproduction and the book": ("registry", "settings", "claims", "ledger", "formatting", "report", "reproduce",
                                  "plotting", "exceptions"),
}

#: The group of the papers' study modules in the API reference.
PAPERS_GROUP = "The papers' scenarios"

#: The modules whose reference is too long for one page (more than about 3,800 visible words), and the
#: sub-pages it is split into: ``(slug, title, keys)``, the sub-page ``api/<module>.<slug>.md`` documenting the
#: public objects whose :func:`topic_key` is one of `keys`: the submodule that defines the object (for a
#: package) or, for an object defined in the module itself, ``"classes"`` or ``"functions"``. The module's
#: own page keeps its summary, the table of all its public objects and the objects no sub-page takes, so a
#: new public name is never left out of the reference.
API_TOPICS: dict[str, tuple[tuple[str, str, tuple[str, ...]], ...]] = {
    "compare": (
        ("tasks", "Tasks and simulations", ("benchmark", "team", "shared", "target")),
        ("grid", "Running the grid", ("grid", "summary", "stats", "verdicts", "cost")),
        ("tables", "Tables and plots", ("tables", "plots")),
    ),
    "distributed_kf": (("functions", "The steps and checks", ("functions",)),),
    "distributed_ekf": (("functions", "The steps and the simulation", ("functions",)),),
    "fusion": (("functions", "Tracking, exact errors, fusion rules", ("functions",)),),
}

_DRAW = re.compile(r"""\.draw\(\s*["'](?P<name>[A-Za-z0-9_\-]+)["']""")


def chapter_studies() -> dict[str, tuple[PaperRegistry, Study]]:
    """Notebook stem -> (paper, study) for every registered study."""
    out = {}
    for reg in paper_registries():
        for study in reg.studies:
            out[study.chapter] = (reg, study)
    return out


def drawn_figures(cell_source: str) -> list[str]:
    """Names of the registered figures a code cell draws (``.draw("NAME", ...)`` calls)."""
    return _DRAW.findall(cell_source)


#: TeX commands that read as a symbol (or nothing) in an alt text; any other reads as its name.
_TEX_WORDS = {"lvert": "|", "rvert": "|", "vert": "|", "lVert": "‖", "rVert": "‖", "Vert": "‖", "cdot": "·",
              "bar": "", "hat": "", "tilde": "", "approx": "≈", "le": "≤", "ge": "≥", "pm": "±", "times": "×"}


def plain_text(markup: str) -> str:
    """A caption as plain text, for an image's alt text: math without TeX, no Markdown markup.

    Examples
    --------
    >>> plain_text(r"Errors for $Q_2 = 5$ and $\\Phi$ of eq. (62), *not* {numref}`fig-x`.")
    'Errors for Q_2 = 5 and Phi of eq. (62), not the figure fig-x.'

    A value computed by the chapter's run (``{glue:text}`...```) is not known when the alt text is
    written: the brackets that quote it are left out, so the sentence stays whole.

    >>> plain_text("It settles at the fused value ({glue:text}`bias-fused:.4g` h).")
    'It settles at the fused value.'
    >>> plain_text(r"Norms $\\lVert A_c^k\\rVert \\le 1.1 \\cdot 0.9^k$ of $\\bar\\delta_k$.")
    'Norms ‖ A_c^k‖ ≤ 1.1 · 0.9^k of delta_k.'
    """
    text = re.sub(r"\{numref\}`([^`]*)`", r"the figure \1", markup)
    text = re.sub(r"\s*\((?:[^()]|\([^()]*\))*\{glue:text\}`[^`]*`(?:[^()]|\([^()]*\))*\)", "", text)
    text = re.sub(r"\s*\{glue:text\}`[^`]*`", "", text)
    text = re.sub(r"\{[a-z:]+\}`([^`]*)`", r"\1", text)
    text = re.sub(r"\\(?:mathcal|mathbb|mathrm|mathbf|operatorname|boldsymbol|left|right|[bB]ig)\b\s*", "", text)
    text = re.sub(r"\$([^$]*)\$", lambda m: re.sub(r"\\([A-Za-z]+)", lambda c: _TEX_WORDS.get(c.group(1), c.group(1)),
                                                   m.group(1)).replace("{", "").replace("}", ""), text)
    text = re.sub(r"\\[,;:!]", " ", text).replace("*", "").replace("`", "")
    return " ".join(text.split())


def sync_notebook(path: str | Path) -> int:
    """Write the registry's figure metadata into the notebook's figure cells; returns cells changed.

    Every figure cell (registered or captioned by hand) also gets its caption, as plain text, as the
    image's alt text (``{"mystnb": {"image": {"alt": ...}}}``).
    """
    path = Path(path)
    chapters = chapter_studies()
    reg, study = chapters.get(path.stem, (None, None))
    nb = json.loads(path.read_text())
    changed = 0
    for cell in nb["cells"]:
        if cell["cell_type"] != "code":
            continue
        names = drawn_figures("".join(cell["source"])) if study is not None else []
        if len(names) > 1:
            raise ValueError(f"{path.name}: one registered figure per cell, found {names}")
        if names:
            spec = study.figure(names[0])
            meta = {"name": reg.figure_label(spec.name), "caption": reg.full_caption(spec)}
            if cell["metadata"].get("mystnb", {}).get("figure") != meta:
                cell["metadata"].setdefault("mystnb", {})["figure"] = meta
                changed += 1
        figure = cell["metadata"].get("mystnb", {}).get("figure")
        if figure and cell["metadata"]["mystnb"].get("image") != {"alt": plain_text(figure["caption"])}:
            cell["metadata"]["mystnb"]["image"] = {"alt": plain_text(figure["caption"])}
            changed += 1
    if changed:
        path.write_text(json.dumps(nb, indent=1, ensure_ascii=False) + "\n")
    return changed


# ---------------------------------------------------------------- checks of the rendered HTML

#: LaTeX that must never be visible as text (outside MathJax's math containers).
RAW_LATEX = re.compile(
    r"\$|\\[A-Za-z]+\{|\\(mathbb|mathcal|frac|sum|sigma|Sigma|top|hat|bar|left|right|begin|mathrm|le|ge|in|otimes|"
    r"alpha|beta|gamma|delta|lambda|mu|nu|xi|Phi|Gamma|Omega|infty|cdot|quad|qquad)\b"
)


def page_problems(html: str) -> list[str]:
    """What a reader would trip on in one built page: raw LaTeX, network loads, error/warning output, a build date.

    Math rendered by MathJax sits in ``<span class="math ...">`` / ``<div class="math ...">``
    and in ``<script>``, code in ``<pre>``/``<code>``; everything else is text the reader
    sees, and must not contain ``$...`` or LaTeX commands.
    """
    from html.parser import HTMLParser

    problems: list[str] = []

    class Scan(HTMLParser):
        skip_tags = {"script", "style", "pre", "code", "textarea"}

        def __init__(self) -> None:
            super().__init__(convert_charrefs=True)
            self.stack: list[tuple[str, bool]] = []

        def skipping(self) -> bool:
            return any(skip for _, skip in self.stack)

        def handle_starttag(self, tag, attrs):
            a = dict(attrs)
            classes = (a.get("class") or "").split()
            for attr in ("src", "href"):
                url = a.get(attr) or ""
                loads = tag in ("script", "img", "iframe") or (tag == "link" and "stylesheet" in (a.get("rel") or ""))
                if loads and attr in a and re.match(r"^(https?:)?//", url):
                    problems.append(f"loads from the network: <{tag} {attr}={url!r}>")
            if "stderr" in classes or "traceback" in classes or "output_error" in classes:
                problems.append(f"an error or stderr block is shown (<{tag} class={a.get('class')!r}>)")
            if tag in ("br", "img", "meta", "link", "input", "hr", "source", "wbr"):
                return
            self.stack.append((tag, tag in self.skip_tags or "math" in classes))

        def handle_endtag(self, tag):
            while self.stack:
                open_tag, _ = self.stack.pop()
                if open_tag == tag:
                    break

        def handle_data(self, data):
            if self.skipping():
                return
            m = RAW_LATEX.search(data)
            if m:
                start = max(m.start() - 40, 0)
                problems.append(f"raw LaTeX in the text: ...{data[start:m.end() + 40].strip()!r}...")

    Scan().feed(html)
    if "Last updated on" in html:
        problems.append("the page shows the date it was built (a 'Last updated on' footer)")
    return problems


#: Measures a page as the reader sees it, once it has loaded and MathJax has typeset it: the text column's
#: width, the words shown, formulas MathJax reports as errors, every display equation and table wider than the
#: column, cells showing NaN, and how much each figure's image is shrunk. An async JavaScript function of no
#: argument that returns the measures (:func:`measure_pages` calls it in the page).
_MEASURE_JS = r"""
async () => {
  const out = {};
  try {
    if (document.readyState !== "complete") { await new Promise((ok) => window.addEventListener("load", ok)); }
    if (window.MathJax && MathJax.startup) { await MathJax.startup.promise; }
    const article = document.querySelector("article.bd-article") || document.body;
    const cs = getComputedStyle(article);
    const column = article.clientWidth - parseFloat(cs.paddingLeft) - parseFloat(cs.paddingRight);
    out.column = column;
    const label = (el) => (el.closest("[id]") ? el.closest("[id]").id + ": " : "") +
                          el.textContent.replace(/\s+/g, " ").trim().slice(0, 80);
    out.equations = [];
    for (const el of document.querySelectorAll('mjx-container[display="true"]')) {
      const math = el.querySelector("mjx-math") || el;
      const w = math.getBoundingClientRect().width;
      if (w > column + 1) out.equations.push({width: Math.round(w), what: label(el.closest(".math") || el)});
    }
    out.math_errors = [];
    for (const el of document.querySelectorAll("mjx-merror")) {
      out.math_errors.push((el.getAttribute("data-mjx-error") || el.textContent).slice(0, 120));
    }
    out.tables = []; out.nan = [];
    for (const t of document.querySelectorAll("article table")) {
      const w = t.getBoundingClientRect().width;
      const head = t.querySelector("tr") ? t.querySelector("tr").textContent.replace(/\s+/g, " ").trim().slice(0, 80) : "";
      if (w > column + 1) out.tables.push({width: Math.round(w), what: head});
      for (const c of t.querySelectorAll("td, th")) {
        const text = c.textContent.trim();
        if (/^(nan|NaN|<NA>|None|NaT)$/.test(text)) out.nan.push(head);
      }
    }
    // Words a reader sees: the article's rendered text (closed dropdowns and hidden cells do not render).
    out.words = article.innerText.split(/\s+/).filter((w) => /[A-Za-z0-9]/.test(w)).length;
    out.images = [];
    for (const img of document.querySelectorAll("article figure img")) {
      if (!img.naturalWidth) continue;
      const fig = img.closest("figure");
      out.images.push({id: fig ? fig.id : "", natural: img.naturalWidth, shown: Math.round(img.getBoundingClientRect().width)});
    }
  } catch (e) { out.error = String(e); }
  return out;
}
"""

#: Chromium's switches for measuring: headless, no GPU, no network of its own, a throw-away profile. The pages
#: are measured in minimized windows (laid out as at full size, not painted); the last three switches keep
#: such a page's timers and priority as a shown page's.
_CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                   "--disable-component-update", "--disable-sync", "--no-first-run",
                   "--disable-background-timer-throttling", "--disable-renderer-backgrounding",
                   "--disable-backgrounding-occluded-windows")

#: Run in each page before its own scripts: the page starts with no stored state, as in a fresh profile.
_FRESH_STORAGE_JS = "try { localStorage.clear(); sessionStorage.clear(); } catch (e) {}"


def chromium() -> str | None:
    """Path of a Chromium (or Chrome) executable, or None."""
    import shutil

    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        if shutil.which(name):
            return shutil.which(name)
    return None


def measure_pages(paths: Sequence[str | Path], width: int = 1280, browser: str | None = None, tabs: int = 2,
                  timeout: float = 120.0) -> dict[Path, dict]:
    """Render built pages in one headless Chromium, a `width` px by 2000 px window each, and measure them.

    One browser is started for all the pages (POSIX: it is driven over its DevTools pipe). It opens `tabs`
    windows, each in a browser context of its own, minimized (a page is laid out as in a shown window of that
    size, but not painted), and each window loads page after page; every page starts with empty local and
    session storage, as in a fresh profile. A page is measured once its ``load`` event has fired and MathJax
    has typeset it (``MathJax.startup.promise``). A window whose page failed is closed and a new one opened.

    Parameters
    ----------
    paths : sequence of str or Path
        Built HTML files.
    width : int
        Width of each page's window, CSS px.
    browser : str, optional
        Chromium executable (default: :func:`chromium`).
    tabs : int
        Pages loading at once (at least 1).
    timeout : float
        Seconds a page may take from the start of its loading to its measures (> 0).

    Returns
    -------
    dict
        For each path (as a :class:`~pathlib.Path`, in the order given): ``column`` (width of the text column,
        px), ``words`` (words of the article's rendered text: collapsed blocks left out), ``math_errors``
        (formulas MathJax could not typeset), ``equations`` and ``tables`` (those wider than the column: width
        in px and what they start with), ``nan`` (tables with a cell showing NaN or None) and ``images``
        (natural and shown width, px, of every figure's image). A page that could not be loaded or measured
        (missing file, script error, crash, `timeout`) maps to ``{"error": "what happened"}`` alone; the
        other pages are measured all the same.

    Raises
    ------
    FileNotFoundError
        If `browser` is None and no Chromium is on the PATH.
    ValueError
        If `width` or `tabs` is not a positive integer or `timeout` is not positive.
    """
    import tempfile
    import time

    if isinstance(width, bool) or not isinstance(width, int) or width < 1:
        raise ValueError(f"width must be a positive whole number of CSS px, got {width!r}")
    if isinstance(tabs, bool) or not isinstance(tabs, int) or tabs < 1:
        raise ValueError(f"tabs must be a positive whole number, got {tabs!r}")
    if not timeout > 0:
        raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
    browser = browser or chromium()
    if browser is None:
        raise FileNotFoundError("no chromium on the PATH (apt-get install -y chromium)")
    pages = [Path(p) for p in paths]
    if not pages:
        return {}
    results: dict[Path, dict] = {}
    todo = list(dict.fromkeys(pages))[::-1]  # popped from the end: in order
    with tempfile.TemporaryDirectory() as profile, _DevTools(browser, profile) as devtools:
        windows: list[_Window] = []
        try:
            while todo or any(window.path is not None for window in windows):
                for window in windows:
                    if window.path is None and todo:
                        window.load(todo.pop(), time.monotonic() + timeout)
                while todo and len(windows) < tabs:
                    windows.append(_Window(devtools, width))
                    windows[-1].load(todo.pop(), time.monotonic() + timeout)
                loading = [window for window in windows if window.path is not None]
                message = devtools.receive(until=min(window.deadline for window in loading))
                for window in list(windows):
                    outcome = window.handle(message) if message is not None else None
                    if outcome is None and window.path is not None and time.monotonic() >= window.deadline:
                        outcome = {"error": f"not measured within {timeout:g} s"}
                    if outcome is not None:
                        if window.path is not None:  # (else the window broke between two pages)
                            results[window.path] = outcome
                            window.path = None
                        if "error" in outcome:  # the next page gets a new window
                            window.close()
                            windows.remove(window)
        except (OSError, RuntimeError) as exc:  # the browser has gone: every page not yet measured says so
            for path in [window.path for window in windows if window.path is not None] + todo:
                results[path] = {"error": f"{type(exc).__name__}: {exc}"}
    return {p: results[p] for p in pages}


def measure_page(path: str | Path, width: int = 1280, browser: str | None = None, timeout: float = 120.0) -> dict:
    """Render one built page in headless Chromium at `width` px and measure it (see :func:`measure_pages`).

    Raises
    ------
    RuntimeError
        If the page could not be loaded or measured.
    """
    path = Path(path)
    measures = measure_pages([path], width=width, browser=browser, tabs=1, timeout=timeout)[path]
    if "error" in measures:
        raise RuntimeError(f"{path.name}: the page was not measured: {measures['error']}")
    return measures


class _DevTools:
    """A headless Chromium driven over ``--remote-debugging-pipe``: JSON messages ending in a NUL byte, sent to
    its file descriptor 3 and read from its descriptor 4 (started with ``posix_spawn``: safe from threads)."""

    def __init__(self, browser: str, profile: str) -> None:
        import os
        import tempfile

        to_browser, self._send = os.pipe()
        self._read, from_browser = os.pipe()
        self._stderr = tempfile.TemporaryFile()
        # The child's ends numbered above 4, so that moving them to 2, 3 and 4 cannot overwrite one another.
        ends = [_fd_above(fd, 5) for fd in (to_browser, from_browser)] + [_fd_above(os.dup(self._stderr.fileno()), 5)]
        try:
            self._pid = os.posix_spawn(browser, [browser, *_CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                                 "--remote-debugging-pipe", "about:blank"], os.environ,
                                       file_actions=[(os.POSIX_SPAWN_OPEN, 0, os.devnull, os.O_RDONLY, 0),
                                                     (os.POSIX_SPAWN_OPEN, 1, os.devnull, os.O_WRONLY, 0),
                                                     (os.POSIX_SPAWN_DUP2, ends[2], 2),
                                                     (os.POSIX_SPAWN_DUP2, ends[0], 3),
                                                     (os.POSIX_SPAWN_DUP2, ends[1], 4)])
        finally:
            for fd in ends:
                os.close(fd)
        self._exit_code: int | None = None
        self._buffer = b""
        self._last_id = 0

    def __enter__(self) -> _DevTools:
        return self

    def __exit__(self, *exc) -> None:
        import os
        import signal
        import time

        try:
            self.send("Browser.close")
        except OSError:
            pass  # it has gone already
        until = time.monotonic() + 30
        try:
            while self.receive(until) is not None:  # replies and events until the browser closes the pipe
                pass
            os.kill(self._pid, signal.SIGKILL)  # still there after 30 s
        except RuntimeError:
            pass  # it has exited
        self._wait()
        os.close(self._send)
        os.close(self._read)
        self._stderr.close()

    def _wait(self) -> int:
        """The browser's exit code, once it has exited."""
        import os

        if self._exit_code is None:
            self._exit_code = os.waitstatus_to_exitcode(os.waitpid(self._pid, 0)[1])
        return self._exit_code

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> int:
        """Send one command (to the browser, or to a page's `session`); its id, which its reply carries."""
        import os

        self._last_id += 1
        message = {"id": self._last_id, "method": method, "params": params or {}}
        if session is not None:
            message["sessionId"] = session
        os.write(self._send, json.dumps(message).encode() + b"\0")
        return self._last_id

    def receive(self, until: float) -> dict | None:
        """The next reply or event, or None if none came before the monotonic time `until`."""
        import os
        import select
        import time

        while b"\0" not in self._buffer:
            left = until - time.monotonic()
            if left <= 0 or not select.select([self._read], [], [], left)[0]:
                return None
            chunk = os.read(self._read, 1 << 20)
            if not chunk:
                self._stderr.seek(0)
                tail = self._stderr.read().decode(errors="replace").strip().splitlines()[-3:]
                raise RuntimeError(f"Chromium exited (code {self._wait()}): {' | '.join(tail)}")
            self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)


def _fd_above(fd: int, lowest: int) -> int:
    """A copy of file descriptor `fd` numbered `lowest` or more (not inherited); `fd` is closed."""
    import fcntl
    import os

    copy = fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, lowest)
    os.close(fd)
    return copy


class _Window:
    """A minimized window in a browser context of its own that loads and measures one page after another: the
    page it is at (`path`, None while it waits for one), its DevTools session and the replies it awaits."""

    def __init__(self, devtools: _DevTools, width: int) -> None:
        self.devtools, self.width = devtools, width
        self.context = self.target = self.session = self.path = None
        self.url, self.deadline, self.ready, self.navigated, self.measuring = "", 0.0, False, False, False
        self.waiting = {devtools.send("Target.createBrowserContext"): "context"}

    def load(self, path: Path, deadline: float) -> None:
        """Load and measure `path` by the monotonic time `deadline` (once the window is ready)."""
        self.path, self.url, self.deadline = path, path.resolve().as_uri(), deadline
        self.navigated = self.measuring = False
        if self.ready:
            self._navigate()

    def handle(self, message: dict) -> dict | None:
        """Take one message from the browser; the page's measures (or ``{"error": ...}``) once it is done."""
        step = self.waiting.pop(message.get("id"), None) if "id" in message else None
        if step is None:
            if self.session is None or message.get("sessionId") != self.session or not self.navigated:
                return None
            if message.get("method") == "Page.loadEventFired" and not self.measuring:
                self.measuring = True
                expression = f"(async () => [location.href, await ({_MEASURE_JS})()])()"
                self._send("Runtime.evaluate", {"expression": expression, "awaitPromise": True,
                                                "returnByValue": True}, "measures")
            elif message.get("method") == "Inspector.targetCrashed":
                return {"error": "the page crashed Chromium's renderer"}
            return None
        if "error" in message:
            return {"error": f"DevTools {step}: {message['error'].get('message')}"}
        result = message.get("result", {})
        if step == "context":
            self.context = result["browserContextId"]
            self._send("Target.createTarget", {"url": "about:blank", "browserContextId": self.context,
                                               "newWindow": True, "width": self.width, "height": 2000}, "target")
        elif step == "target":
            self.target = result["targetId"]
            self._send("Browser.getWindowForTarget", {"targetId": self.target}, "window")
        elif step == "window":
            self._send("Browser.setWindowBounds", {"windowId": result["windowId"],
                                                   "bounds": {"windowState": "minimized"}}, "minimized")
        elif step == "minimized":
            self._send("Target.attachToTarget", {"targetId": self.target, "flatten": True}, "session")
        elif step == "session":
            self.session = result["sessionId"]
            for method, params in (("Page.enable", {}), ("Inspector.enable", {}),
                                   ("Page.addScriptToEvaluateOnNewDocument", {"source": _FRESH_STORAGE_JS})):
                self._send(method, params, "enabled")
            self._send("Runtime.evaluate", {"expression": "0"}, "ready")  # replied to after the three above
        elif step == "ready":
            self.ready = True
            if self.path is not None:
                self._navigate()
        elif step == "navigation" and result.get("errorText"):
            return {"error": f"Chromium could not open {self.url}: {result['errorText']}"}
        elif step == "measures":
            if "exceptionDetails" in result:
                return {"error": f"the measuring script failed: {result['exceptionDetails'].get('text')}"}
            value = result.get("result", {}).get("value")
            if not (isinstance(value, list) and len(value) == 2 and isinstance(value[1], dict)):
                return {"error": f"the measuring script returned {value!r}"}
            href, measures = value
            if href != self.url:
                return {"error": f"Chromium showed {href} instead of {self.url}"}
            return measures
        return None

    def _navigate(self) -> None:
        self.navigated = True
        self._send("Page.navigate", {"url": self.url}, "navigation")

    def _send(self, method: str, params: dict, step: str) -> None:
        """Send a command (to the page once it has a session, else to the browser), awaited as `step`."""
        self.waiting[self.devtools.send(method, params, self.session)] = step

    def close(self) -> None:
        """Close the window and forget its storage (no reply awaited)."""
        if self.context is not None:
            self.devtools.send("Target.disposeBrowserContext", {"browserContextId": self.context})


def public_objects(module: str) -> list[str]:
    """Names of ``mascore.<module>.__all__`` that are classes or functions (what the API pages list)."""
    import inspect

    mod = importlib.import_module(f"mascore.{module}")
    return [n for n in getattr(mod, "__all__", []) if inspect.isclass(getattr(mod, n)) or callable(getattr(mod, n))]


def topic_key(module: str, name: str) -> str:
    """What :data:`API_TOPICS` groups ``mascore.<module>.<name>`` by.

    The submodule that defines it when ``mascore.<module>`` is a package (``"grid"`` for an object of
    ``mascore.compare.grid``), else ``"classes"`` or ``"functions"``.
    """
    import inspect

    package = f"mascore.{module}"
    obj = getattr(importlib.import_module(package), name)
    defined_in = getattr(obj, "__module__", "") or ""
    if defined_in.startswith(package + "."):
        return defined_in.removeprefix(package + ".").split(".")[0]
    return "classes" if inspect.isclass(obj) else "functions"


def api_topics(module: str) -> list[tuple[str, str, list[str]]]:
    """The sub-pages of ``mascore.<module>``'s reference: ``(slug, title, names)``.

    The names of a topic are in the order of its keys, then of ``__all__``. Empty for a module not in
    :data:`API_TOPICS`. Raises ValueError if a topic takes no public object
    (a stale entry of :data:`API_TOPICS`).
    """
    objects = public_objects(module)
    keys = {name: topic_key(module, name) for name in objects}
    topics = []
    for slug, title, wanted in API_TOPICS.get(module, ()):
        names = sorted((n for n in objects if keys[n] in wanted), key=lambda n: wanted.index(keys[n]))  # stable
        if not names:
            raise ValueError(f"API_TOPICS[{module!r}]: the sub-page {slug!r} takes no public object of "
                             f"mascore.{module} (keys {wanted}; the objects' keys: {sorted(set(keys.values()))})")
        topics.append((slug, title, names))
    return topics


def _autodoc(module: str, names: list[str]) -> list[str]:
    """The autodoc directives of `names` (reST lines): a class with its public methods and properties."""
    lines = []
    for o in names:
        if _is_class(module, o):  # its public methods and properties, each from its own docstring
            lines += [f".. autoclass:: {o}", "   :members:", ""]
        else:
            lines += [f".. autofunction:: {o}", ""]
    return lines


def api_pages(module: str) -> dict[str, str]:
    """The MyST sources of the API reference of ``mascore.<module>``: file name -> text.

    ``<module>.md``: the module's summary, a table of all its public classes and functions (each linked
    to its entry), then each one rendered from its NumPy-style docstring (autodoc + numpydoc), in the
    order of the module's ``__all__``. For a module of :data:`API_TOPICS` the entries are shared out:
    each sub-page ``<module>.<slug>.md`` renders the objects of its topic, the module's page the rest.
    """
    name = f"mascore.{module}"
    objects = public_objects(module)
    topics = api_topics(module)
    elsewhere = {o for _, _, names in topics for o in names}
    lines = [f"# `{name}`", "", "```{eval-rst}", f".. automodule:: {name}", "   :no-members:", ""]
    if topics:
        links = [f"[{title}]({module}.{slug}.md)" for slug, title, _ in topics]
        links = " and ".join([", ".join(links[:-1]), links[-1]] if len(links) > 1 else links)
        where = f"on {links}" if set(objects) <= elsewhere else f"below it, or on {links}"
        lines += ["```", "", f"The table links every object to its entry: {where}.", "", "```{eval-rst}"]
    if objects:
        lines += [f".. currentmodule:: {name}", "", ".. autosummary::", "   :nosignatures:", ""]
        lines += [f"   {o}" for o in objects]
        lines += [""]
        lines += _autodoc(name, [o for o in objects if o not in elsewhere])
    lines += ["```", ""]
    pages = {f"{module}.md": "\n".join(lines)}
    for slug, title, names in topics:
        sub = [f"# {title}", "", f"Part of the reference of [`{name}`]({module}.md).", "", "```{eval-rst}",
               f".. currentmodule:: {name}", ""] + _autodoc(name, names) + ["```", ""]
        pages[f"{module}.{slug}.md"] = "\n".join(sub)
    return pages


def api_page(module: str) -> str:
    """The MyST source of the API reference page of ``mascore.<module>`` (its sub-pages: :func:`api_pages`)."""
    return api_pages(module)[f"{module}.md"]


def _is_class(module: str, name: str) -> bool:
    import inspect

    return inspect.isclass(getattr(importlib.import_module(module), name))


def api_groups() -> dict[str, tuple[str, ...]]:
    """:data:`API_GROUPS` and, last, the papers' study modules in book order (:func:`mascore.registry.study_modules`)."""
    papers = tuple(m.__name__.removeprefix("mascore.") for m in study_modules())
    return {**API_GROUPS, PAPERS_GROUP: papers}


def api_modules() -> list[str]:
    """The modules of :func:`api_groups` that exist in this checkout, in book order."""
    import importlib.util

    return [m for group in api_groups().values() for m in group if importlib.util.find_spec(f"mascore.{m}")]


def write_api_pages(folder: str | Path = "book/api", toc: str | Path | None = None) -> int:
    """Write the API reference pages of every module of :func:`api_groups` and the index page into `folder`.

    The pages are :func:`api_pages`; generated pages of modules no longer listed are removed. In the
    table of contents `toc` (default: ``_toc.yml`` beside `folder`) the entry ``<folder>/index`` gets the
    module pages as its sections, in the index's order, each with its sub-pages.
    Returns the number of files that changed.
    """
    folder = Path(folder)
    toc = Path(toc) if toc is not None else folder.parent / "_toc.yml"
    folder.mkdir(parents=True, exist_ok=True)
    by_module = {m: api_pages(m) for m in api_modules()}
    pages = {fname: text for module_pages in by_module.values() for fname, text in module_pages.items()}
    if len(pages) < sum(map(len, by_module.values())) or "index.md" in pages:
        raise ValueError("two API pages have the same file name: a sub-page's slug (API_TOPICS) names another page")
    index = ["# API reference", "",
             "Every public class and function of the package, rendered from its docstring. Each page opens with",
             "the module's summary; the examples are executed as doctests by `make test`.", ""]
    for group, modules in api_groups().items():
        present = [m for m in modules if m in by_module]
        if present:
            index += [f"## {group}", ""] + [_index_line(m, by_module[m]) for m in present] + [""]
    pages["index.md"] = "\n".join(index)
    changed = 0
    for stale in sorted(set(p.name for p in folder.glob("*.md")) - set(pages)):
        (folder / stale).unlink()
        changed += 1
    for fname, text in pages.items():
        path = folder / fname
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
            changed += 1
    if toc.exists():
        old = toc.read_text()
        new = toc_with_api_pages(old, folder.name, [list(p) for p in by_module.values()])
        if new != old:
            toc.write_text(new)
            changed += 1
    return changed


def _index_line(module: str, pages: dict[str, str]) -> str:
    """The index's line of one module: its page, then its sub-pages (by their titles)."""
    line = f"- [`mascore.{module}`]({module}.md)"
    subs = [f"[{text.split(chr(10), 1)[0].removeprefix('# ')}]({fname})" for fname, text in pages.items()
            if fname != f"{module}.md"]
    return line + (": " + " · ".join(subs) if subs else "")


def toc_with_api_pages(toc: str, folder: str, pages: list[list[str]]) -> str:
    """`toc` (a ``_toc.yml``) with the sections of its ``<folder>/index`` entry replaced by the API pages.

    `pages` holds one list per module: its page's file name first, then its sub-pages', which become
    the sections of the module's entry. Raises ValueError if `toc` has no ``file: <folder>/index`` entry.
    """
    lines = toc.splitlines()
    entry = re.compile(rf"^(?P<indent>\s*)- file: {re.escape(folder)}/index\s*(#.*)?$")
    at = next((i for i, line in enumerate(lines) if entry.match(line)), None)
    if at is None:
        raise ValueError(f"the table of contents has no entry '- file: {folder}/index'")
    indent = len(entry.match(lines[at])["indent"])
    end = at + 1
    while end < len(lines) and (not lines[end].strip() or len(lines[end]) - len(lines[end].lstrip()) > indent):
        end += 1
    pad = " " * (indent + 2)
    body = [f"{pad}sections:  # the API pages in the index's order: written by `make sync` (mascore._booktools)"]
    for module_pages in pages:
        body.append(f"{pad}  - file: {folder}/{module_pages[0].removesuffix('.md')}")
        if module_pages[1:]:
            body.append(f"{pad}    sections:")
            body += [f"{pad}      - file: {folder}/{fname.removesuffix('.md')}" for fname in module_pages[1:]]
    return "\n".join(lines[:at + 1] + body + lines[end:]) + ("\n" if toc.endswith("\n") else "")


def _emptied_cache(book: Path):
    """The jupyter-cache of `book` (``_build/.jupyter_cache``), emptied: no output of an earlier build is reused."""
    import shutil

    from jupyter_cache import get_cache

    cache_path = book / "_build" / ".jupyter_cache"
    shutil.rmtree(cache_path, ignore_errors=True)
    return get_cache(str(cache_path))


def _add_notebooks(cache, book: Path, ipynb: bool = True) -> None:
    """Add the book's notebooks to the project of `cache`: ``notebooks/*.ipynb`` (unless not `ipynb`) and the
    MyST pages with code cells."""
    for notebook in sorted((book / "notebooks").glob("*.ipynb")) if ipynb else []:
        cache.add_nb_to_project(str(notebook))
    for page in sorted(book.glob("*.md")):  # a text notebook (the intro), read as the build reads it
        if "```{code-cell}" in page.read_text():
            cache.add_nb_to_project(str(page), read_data={"name": "myst_nb_md", "type": "plugin"})


def _run_project(cache, timeout: int, all_cores: Callable[[], bool] | None = None) -> list[str]:
    """Execute the notebooks of the cache's project on every core, one at a time per core; the failed ones.

    The notebooks are handed out longest first (:func:`_code_length`), so that the last ones to run are
    short and neither core idles long at the end while the other finishes. Each kernel is killed once
    its last cell's outputs are in (:func:`_execute_and_kill`). With `all_cores`, one notebook at a time
    until ``all_cores()`` is true: the cores are shared with another process meanwhile (the book's build
    reading its API pages), and the notebooks that time their code should not measure it with a third
    process competing for their core.
    """
    import multiprocessing
    import os
    import time

    from jupyter_cache.executors.basic import ExecutionWorkerLocalMProc, ProcessData

    records = sorted(cache.list_project_records(), key=lambda record: -_code_length(record.uri))  # stable
    jobs = [ProcessData(record.pk, record.uri, cache, timeout, False) for record in records]
    worker = ExecutionWorkerLocalMProc()
    worker.execute = _execute_and_kill  # the worker's one step that runs the notebook (picklable: a module function)
    cores = os.cpu_count() or 1
    with multiprocessing.Pool(cores) as pool:
        if all_cores is None:
            # One notebook per task (chunksize 1): Pool.map's default hands out runs of five consecutive
            # notebooks, which left one core idle while the other ran the last run.
            results = list(pool.imap_unordered(worker, jobs, chunksize=1))
        else:
            results, running = [], []
            while jobs or running:
                allowed = cores if all_cores() else 1
                while jobs and len(running) < allowed:
                    running.append(pool.apply_async(worker, (jobs.pop(0),)))
                time.sleep(0.05)
                results += [task.get() for task in running if task.ready()]
                running = [task for task in running if not task.ready()]
    return sorted(uri for status, uri in results if status != 0)


def _code_length(path: str | Path) -> int:
    """Characters in the code cells of notebook `path` (of a MyST page, such as the intro: its whole text).

    The executor's estimate of how long a notebook runs, to hand out the longest first: over the book's
    notebooks it orders them about as well as their measured times do (the last few to start are short
    ones either way), with nothing to record or keep up to date. A file that is no notebook counts 0:
    the executor then reports it as failed, and the book's build shows why.
    """
    path = Path(path)
    if path.suffix != ".ipynb":
        return len(path.read_text())
    try:
        cells = json.loads(path.read_text())["cells"]
        return sum(len("".join(cell["source"])) for cell in cells if cell["cell_type"] == "code")
    except (ValueError, KeyError, TypeError):
        return 0


def _execute_and_kill(project_nb, data):
    """jupyter-cache's execution of one notebook (``ExecutionWorkerLocalMProc.execute``), its kernel then killed.

    The kernel is killed (``shutdown_kernel="immediate"``) once the outputs of its last cell are in,
    instead of being asked to shut down: a kernel that exits by itself first clears its namespace,
    collects its garbage and unloads its modules, about half a second of CPU per notebook, and the
    executor waits for it; nothing it does then reaches the notebook.
    """
    from jupyter_cache.executors.utils import single_nb_execution

    return single_nb_execution(project_nb.nb, cwd=str(Path(project_nb.uri).parent), timeout=data.timeout,
                               allow_errors=data.allow_errors, shutdown_kernel="immediate")


def execute_notebooks(book: str | Path = "book", timeout: int = 900) -> list[str]:
    """Execute the book's notebooks on every core into the cache that ``jupyter-book build`` reads.

    The cache (``_build/.jupyter_cache`` of `book`) is emptied first, so no output of an
    earlier build, made by other code, is reused; the build then takes each notebook's
    outputs from it (``execute_notebooks: cache``) and executes itself only what is missing,
    which it reports with its traceback. The notebooks are ``book/notebooks/*.ipynb`` and the
    MyST pages of `book` with code cells (the intro).

    Parameters
    ----------
    book : str or Path
        The book's folder.
    timeout : int
        Seconds a cell may run.

    Returns
    -------
    list of str
        The notebooks that failed (the build executes them again and shows why).
    """
    cache = _emptied_cache(Path(book))
    _add_notebooks(cache, Path(book))
    return _run_project(cache, timeout)


#: Environment variable naming the file that exists while :func:`build_book` executes the notebooks: the
#: build waits for them before it reads a page with executed cells (book/_ext/notebooks_pending.py).
NOTEBOOKS_PENDING = "MASCORE_NOTEBOOKS_PENDING"


def build_book(book: str | Path = "book", command: list[str] | None = None, executed: str | Path | None = None,
               log: str | Path | None = None, timeout: int = 900, first: list[str] | None = None,
               then: list[str] | None = None, checks: list[str] | None = None) -> tuple[int, int]:
    """Render the book with ``jupyter-book build`` while its notebooks are executed.

    The build is one process (Sphinx reads, then writes, one page at a time), so it starts at
    once and reads the API pages, which need no executed notebook, while the notebooks are
    executed: as :func:`execute_notebooks` does, on one core until the build has read those
    pages and then on every core (no notebook that times its code shares its core with the
    build), or, given `command`, by that command (``pytest --nbmake`` in ``make test``), whose
    executed copies in `executed` are then put into the cache by :func:`cache_executed` (the
    intro, which is no notebook of ``notebooks/``, is executed meanwhile by this process). The
    build waits for them before it reads a page with executed cells (book/_ext/notebooks_pending.py,
    told by :data:`NOTEBOOKS_PENDING`); a notebook missing from the cache is executed by the build,
    which shows why it fails. With `first`, that command (``make``'s results stage, which the notebooks
    read) runs before any notebook is executed, while the build reads the API pages. ``make test`` also
    gives `then` (the other tests: they start once the notebooks are executed and run beside the rest
    of the build) and `checks` (the checks of the built HTML: they start once the book is built, beside
    `then`), so that the build's own tail, one process, leaves no core idle.

    Parameters
    ----------
    book : str or Path
        The book's folder.
    command : list of str, optional
        A command that executes the notebooks into `executed` (default: :func:`execute_notebooks`).
    executed : str or Path, optional
        The folder of the notebooks `command` executed; required with `command`.
    log : str or Path, optional
        File for the build's output (default: this process's standard output).
    timeout : int
        Seconds a cell may run (:func:`execute_notebooks`).
    first : list of str, optional
        A command run to its end before the notebooks are executed; if it fails, the build is stopped.
    then : list of str, optional
        A command started once the notebooks are executed (`command` has ended), while the build reads
        and writes their pages; it is waited for.
    checks : list of str, optional
        A command run once the book is built (not if the build failed), beside `then`; its output is
        kept in ``checks.log`` beside the book's HTML folder and shown once both have ended.

    Returns
    -------
    (int, int)
        The exit status of the build (-15 if `first` stopped it), and of `first` if it failed, else the
        first non-zero status of `command`, `then` and `checks` (0 if none failed).
    """
    import contextlib
    import os
    import shutil
    import subprocess

    if (command is None) != (executed is None):
        raise ValueError("build_book: give both `command` and `executed` (the folder it writes), or neither")
    jupyter_book = shutil.which("jupyter-book", path=str(Path(sys.executable).parent)) or shutil.which("jupyter-book")
    if jupyter_book is None:
        raise FileNotFoundError("build_book: no `jupyter-book` beside this Python or on the PATH (pip install .[book])")
    book = Path(book)
    first_run = subprocess.Popen(first) if first is not None else None  # at once: it does not use the cache
    try:
        cache = _emptied_cache(book)  # ready, with its project, before the build starts
        _add_notebooks(cache, book, ipynb=command is None)  # `command` executes notebooks/*.ipynb, not the intro
    except BaseException:
        if first_run is not None:
            first_run.terminate()
        raise
    pending = (book / "_build" / "notebooks-pending").resolve()
    pending.parent.mkdir(parents=True, exist_ok=True)
    (book / "_build" / "html" / "index.html").unlink(missing_ok=True)  # sphinx-external-toc writes it only if missing
    pending.write_text(str(os.getpid()))  # the build waits while this process lives and the file exists
    api_read = pending.with_name(pending.name + ".waiting")  # the build creates it once it waits for the notebooks
    api_read.unlink(missing_ok=True)
    with open(log, "w") if log is not None else contextlib.nullcontext() as out:
        try:
            build = subprocess.Popen([jupyter_book, "build", str(book), "--all", "-W", "-n", "--keep-going"],
                                     env={**os.environ, NOTEBOOKS_PENDING: str(pending)},
                                     stdout=out, stderr=subprocess.STDOUT if out else None)
            status = first_run.wait() if first_run is not None else 0
            if status != 0:
                print(f"{shlex.join(first)} failed (exit status {status}): the book's build is stopped", file=sys.stderr)
                build.terminate()
                then = checks = None
            else:
                status = _execute_beside_build(cache, book, build, api_read, command, executed, timeout)
        finally:
            pending.unlink(missing_ok=True)
        others = subprocess.Popen(then) if then is not None else None  # beside the build's reading and writing
        try:
            status_build = build.wait()
            api_read.unlink(missing_ok=True)
            checks_log = book / "_build" / "checks.log"
            if checks is not None and status_build == 0:
                with open(checks_log, "w") as checks_out:  # shown once `then` has ended: outputs not interleaved
                    checked = subprocess.run(checks, stdout=checks_out, stderr=subprocess.STDOUT).returncode
            else:
                checked, checks = 0, None
        finally:
            tested = others.wait() if others is not None else 0
        if checks is not None:
            print(checks_log.read_text(), end="", flush=True)
        return status_build, status or tested or checked


def _execute_beside_build(cache, book: Path, build, api_read: Path, command: list[str] | None,
                          executed: str | Path | None, timeout: int) -> int:
    """:func:`build_book`'s execution of the notebooks while `build` runs: `command`'s exit status (0 without)."""
    import subprocess

    running = subprocess.Popen(command) if command is not None else None
    # all the notebooks, or the intro beside `command`; on every core once the build waits for them
    try:
        failed = _run_project(cache, timeout, lambda: api_read.exists() or build.poll() is not None)
    finally:
        status = running.wait() if running is not None else 0
    for uri in failed:
        print(f"{uri}: failed (the book's build shows why)", file=sys.stderr)
    for name in _cache_copies(cache, executed, book) if command is not None else []:
        print(f"{name}: not executed by the tests (the book's build executes it)", file=sys.stderr)
    return status


def cache_executed(executed: str | Path, book: str | Path = "book") -> list[str]:
    """Put the book's notebooks, executed elsewhere, into the emptied cache that ``jupyter-book build`` reads.

    ``make test`` executes copies of the notebooks once, as tests (``pytest --nbmake --overwrite`` on
    ``book/_build/executed``); this function carries their outputs into the book's cache, so that the
    build renders them instead of executing every notebook a second time. A copy is taken only if its
    code cells are the source notebook's, in order, and no output is an error; any other notebook is left
    out, and the build executes it (and shows why it fails, if it does).

    Parameters
    ----------
    executed : str or Path
        The folder of the executed copies (same file names as ``book/notebooks``).
    book : str or Path
        The book's folder.

    Returns
    -------
    list of str
        The notebooks left out (missing, changed or failed).
    """
    return _cache_copies(_emptied_cache(Path(book)), executed, book)


def _cache_copies(cache, executed: str | Path, book: str | Path) -> list[str]:
    """:func:`cache_executed` into `cache` as it is."""
    import nbformat
    from jupyter_cache.base import CacheBundleIn

    folder = Path(book)
    left_out = []
    for source in sorted((folder / "notebooks").glob("*.ipynb")):
        copy = Path(executed) / source.name
        nb = nbformat.read(source, as_version=4)
        run = nbformat.read(copy, as_version=4) if copy.exists() else None
        code = [c for c in nb.cells if c.cell_type == "code"]
        code_run = [c for c in run.cells if c.cell_type == "code"] if run is not None else []
        if (run is None or [c.source for c in code] != [c.source for c in code_run]
                or any(o.get("output_type") == "error" for c in code_run for o in c.outputs)):
            left_out.append(source.name)
            continue
        for cell, done in zip(code, code_run):  # the source's cells and metadata, the copy's outputs
            cell.outputs, cell.execution_count = done.outputs, done.execution_count
        cache.cache_notebook_bundle(CacheBundleIn(nb, str(source)), check_validity=False, overwrite=True)
    return left_out


def main(argv: list[str] | None = None) -> int:
    """``python -m mascore._booktools sync [NOTEBOOK ...]`` (default: every notebook of a study), ``execute``,
    ``cache FOLDER`` (:func:`cache_executed`), or ``build [--log FILE] [--first "CMD"] [--then "CMD"]
    [--checks "CMD"] [FOLDER COMMAND ...]`` (:func:`build_book`: the first CMD run first, then the notebooks
    executed by COMMAND into FOLDER, or by :func:`execute_notebooks`, then the other two as
    :func:`build_book` says; the exit status is the build's if it failed, else the commands')."""
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "build":
        args, log, commands = argv[1:], None, {}
        while args[:1] in (["--log"], ["--first"], ["--then"], ["--checks"]):
            if args[0] == "--log":
                log = args[1]
            else:
                commands[args[0][2:]] = shlex.split(args[1])
            args = args[2:]
        built, status = build_book(command=args[1:] or None, executed=args[0] if args else None, log=log,
                                   **commands)
        if "first" in commands and built < 0 and status != 0:  # the first command failed: the build was stopped
            return status
        if built != 0:
            if log is not None:
                print("".join(Path(log).read_text().splitlines(keepends=True)[-80:]), file=sys.stderr)
            print("The book did not build" + (f" (the whole log: {log})." if log else "."), file=sys.stderr)
            return built
        print("The book is built" + (f" (log: {log})." if log else "."))
        return status
    if argv and argv[0] == "cache":
        for name in cache_executed(argv[1]):
            print(f"{name}: not executed by the tests (the book's build executes it)", file=sys.stderr)
        return 0
    if argv and argv[0] == "execute":
        failed = execute_notebooks()
        for uri in failed:
            print(f"{uri}: failed (the book's build shows why)", file=sys.stderr)
        return 0
    if not argv or argv[0] != "sync":
        print(__doc__.splitlines()[0], "\nusage: python -m mascore._booktools sync [NOTEBOOK ...]", file=sys.stderr)
        return 2
    paths = [Path(p) for p in argv[1:]] or sorted(Path("notebooks").glob("*.ipynb"))
    if len(argv) == 1:
        n = write_api_pages("book/api")
        if n:
            print(f"book/api: {n} page(s) updated")
    for p in paths:
        n = sync_notebook(p)
        if n:
            print(f"{p}: {n} figure cell(s) updated")
    return 0


if __name__ == "__main__":
    sys.exit(main())
