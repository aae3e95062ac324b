# mascore: the two commands of the README are `make book` and `make test`.
# Both create .venv if needed and install the exact versions of requirements.lock.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
RESULTS := results/.reproduced-stamp
PIP_VERSION := 26.3

# One BLAS thread per process: notebooks and test workers run side by side on 2 cores.
export OMP_NUM_THREADS := 1
export OPENBLAS_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
# No MPLBACKEND here: the book's kernels (and `make lab`) need ipykernel's inline backend to
# show figures. A headless backend is set only where nothing is shown: reproduce and pytest.
HEADLESS := MPLBACKEND=Agg
export PYDEVD_DISABLE_FILE_VALIDATION := 1
# Python writes the .pyc of what it imports into .venv and mascore/__pycache__ (the environment is compiled
# lazily, not at install): where PYTHONDONTWRITEBYTECODE is set, as on some CI machines, every kernel, test
# worker and Dask worker would otherwise compile numpy, scipy, pandas and matplotlib again (about 2.5 s each).
unexport PYTHONDONTWRITEBYTECODE

JOBS ?= 2

.PHONY: help install book test test-min lint reproduce lab bench sync captions lock clean

help:  ## list the targets
	@grep -E '^[a-z]+:.*## ' $(MAKEFILE_LIST) | sed 's/:.*## /\t/'

install: $(STAMP)  ## create .venv and install the locked environment

# .ci/install.py installs with uv (pinned there, bootstrapped into $(VENV)/.uv by the environment's pip; it passes
# on the indexes pip is configured with), or with pip if uv cannot be installed: the same wheels, about half the
# time. Neither byte-compiles at install (about 26 s for the ~10,500 modules of the environment, most of them never
# imported): each module is compiled when a process first imports it, and the .pyc is kept in .venv for the next.
INSTALL = $(BIN)/python .ci/install.py $(VENV)
# The lock is complete (`pip freeze --all`), so it is installed as it is (--no-deps), less one optional
# package: rfc3987-syntax (with lark), which jsonschema's format checker imports when present and which
# compiles 39 grammars on import, about 2.5 s in every notebook kernel (glue imports nbformat, nbformat
# jsonschema); it only checks the syntax of "iri" strings, which nothing here validates.
LOCK_OMITS := -e '^rfc3987-syntax==' -e '^lark=='

$(STAMP): requirements.lock pyproject.toml .ci/install.py
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(INSTALL) pip==$(PIP_VERSION) --no-deps -r requirements.lock
	$(INSTALL) --no-deps --no-build-isolation -e .
	@touch $(STAMP)

# The package's own modules byte-compiled before the processes that import them start side by side (only those
# changed since; a fraction of a second), so that they do not each compile the same modules at once.
COMPILE := $(BIN)/python -m compileall -q mascore

# The book's build (one process) starts first and reads the API pages, which need no notebook, while the
# results stage runs (`--first`: the results the notebooks read, when the package changed); then the notebooks
# are executed on both cores into an emptied cache. The build waits for the cache before the first page with
# executed cells (book/_ext/notebooks_pending.py). A notebook missing from the cache is executed by the
# build, which shows why it failed; its output is in $(BOOK_LOG) (its last lines are shown if it fails).
BUILD_BOOK := env -u MPLBACKEND $(BIN)/python -m mascore._booktools build
BOOK_LOG := book/_build/build.log
# Through a variable: a recipe line that names $(MAKE) itself is run even by `make -n`.
RESULTS_STAGE = $(MAKE) --no-print-directory $(RESULTS)

book: $(STAMP)  ## execute every notebook and render the HTML book into book/_build/html
	@$(COMPILE)
	$(BUILD_BOOK) --log $(BOOK_LOG) --first "$(RESULTS_STAGE)"
	@echo "Open book/_build/html/index.html"

# `make test` executes every notebook once, as a test: nbmake runs copies of them (results/notebooks) on both
# cores and writes their outputs back (--overwrite); the book is rendered from those outputs. `_booktools build`
# starts the book's build first, as `make book` does (it reads the API pages during the results stage); once the
# notebooks are executed, the other tests (the unit tests and the doctests) start while the build reads and
# writes the notebooks' pages (one process), and the checks of the rendered HTML run once the book is built,
# beside those tests (their output is shown once the tests have ended too): the build's tail, one process, no
# longer leaves a core idle, and the tests and the checks share both cores. The notebooks' kernels need ipykernel's
# inline backend to draw their figures, so MPLBACKEND stays unset for them (tests/conftest.py gives the test
# processes themselves a headless backend).
# --dist worksteal: a worker that runs out of items takes half of the other's queue, so that no long item leaves
# one core idle at the end.
EXECUTED := results/notebooks
# The notebooks' kernel (.ci/jupyter/kernels/python3-quick-exit, found through JUPYTER_PATH) is ipykernel's, given two
# documented options: its history kept in memory, and an exit handler that ends the process at once when nbmake shuts
# the kernel down after the last cell (once the exit handlers the notebook itself registered have run). A kernel that
# exits by itself first clears its namespace, collects its garbage and unloads its modules: about 0.5 s of CPU per
# notebook, which nbmake waits for. Nothing it would do then reaches the notebook (`make book`'s executor kills them).
# The session's three processes load no pytest plugin the notebooks do not use (Hypothesis', anyio's: 0.4 s of CPU
# in each).
NOTEBOOK_TESTS = env JUPYTER_PATH=$(CURDIR)/.ci/jupyter $(BIN)/python -m pytest -n $(JOBS) --dist worksteal --nbmake \
    --nbmake-kernel=python3-quick-exit -p no:hypothesispytest -p no:anyio --overwrite --durations=5 $(EXECUTED)
OTHER_TESTS = $(BIN)/python -m pytest -n $(JOBS) --dist worksteal --doctest-modules --durations=25 \
    --ignore=$(HTML_TESTS) tests mascore
# The HTML checks run in one process: one headless Chromium measures every page, the reading and the API pages,
# two at a time (a session fixture of tests/test_book_html.py), while the remaining checks only read files.
HTML_TESTS := tests/test_book_html.py
HTML_CHECKS = env MPLBACKEND=Agg $(BIN)/python -m pytest -p no:xdist -p no:cacheprovider $(HTML_TESTS)

test: $(STAMP) lint  ## lint, the unit tests, doctests, published numbers and every notebook (nbmake), then render the book and check its HTML
	@$(COMPILE) && rm -rf $(EXECUTED) && mkdir -p $(EXECUTED) book/_build && cp notebooks/*.ipynb $(EXECUTED)/
	@$(BUILD_BOOK) --log $(BOOK_LOG) --first "$(RESULTS_STAGE)" --then "$(OTHER_TESTS)" --checks "$(HTML_CHECKS)" \
	    $(EXECUTED) $(NOTEBOOK_TESTS)

lint: $(STAMP)  ## ruff on the package, the tests and the benchmarks; the layers of the package (import-linter)
	$(BIN)/ruff check mascore tests benchmarks
	$(BIN)/lint-imports

# The lowest versions pyproject.toml admits for the core (numpy, scipy, networkx), tested with
# the tests that need nothing else. `make test` does not run it; .ci/run does.
MIN_VENV := .venv-min
MIN_PINS := numpy==1.26.4 scipy==1.11.4 networkx==3.2.1
MIN_TESTS := tests/test_core_install.py tests/test_agents_noise.py tests/test_graphs.py tests/test_consensus.py \
             tests/test_ellipsoids.py tests/test_sensing.py tests/test_distributed_kf.py
# Where the project's environment exists (CI: `make install` first), it installs $(MIN_VENV) with its uv, and
# $(MIN_VENV) is created without pip: no ensurepip, no second uv to bootstrap (about 7 CPU-s less).
MIN_BY = $(if $(wildcard $(BIN)/python),$(BIN)/python,$(MIN_VENV)/bin/python)
test-min:  ## the core alone on its minimum versions: install size, import times, core tests
	@test -x $(MIN_VENV)/bin/python || $(PYTHON) -m venv $(if $(wildcard $(BIN)/python),--without-pip) $(MIN_VENV)
	$(MIN_BY) .ci/install.py $(MIN_VENV) pip==$(PIP_VERSION) $(MIN_PINS) \
	    $(shell grep -E "^(pytest|hypothesis|setuptools|wheel)==" requirements.lock)
	$(MIN_BY) .ci/install.py $(MIN_VENV) --no-deps --no-build-isolation -e .
	$(MIN_VENV)/bin/python -m pytest -q -p no:cacheprovider $(MIN_TESTS)

reproduce: $(STAMP)  ## rebuild every paper's figures, tables and claims.json, and the quick comparison, into results/
	@rm -f $(RESULTS)
	@$(MAKE) --no-print-directory $(RESULTS)

# book and test reuse results/ while no source file of the package has changed since.
# The papers' studies (one process, about 100 CPU-s, song2023 first and longest) run beside the quick comparison's
# workers (about twice that CPU, in many short cells). The grid runs at a lower priority (GRID_NICE): the papers'
# process, which can only ever use one core, has a whole core from the start, the grid's workers the other one, and
# both once the papers are done, so that no core idles while work remains. At equal priority (GRID_NICE=0) the
# papers had about half a core and finished some 20 s after the grid, alone on one core.
GRID_NICE ?= 10
$(RESULTS): $(STAMP) $(wildcard mascore/*.py mascore/*/*.py)
	rm -rf results/compare && mkdir -p results  # the package changed: no cell of an older table is reused
	@$(COMPILE)
	@$(HEADLESS) $(BIN)/python -m mascore reproduce all --out results > results/reproduce.log 2>&1 & papers=$$!; \
	$(HEADLESS) nice -n $(GRID_NICE) $(BIN)/python -m mascore compare --grid quick --out results --workers $(JOBS); grid=$$?; \
	wait $$papers; reproduced=$$?; cat results/reproduce.log; \
	test $$reproduced -eq 0 -a $$grid -eq 0
	@touch $(RESULTS)

lab: $(STAMP)  ## JupyterLab on notebooks/ with the project's environment
	env -u MPLBACKEND $(BIN)/jupyter lab notebooks

bench: $(STAMP)  ## timing benchmarks (printed, and written to results/benchmarks/)
	$(HEADLESS) $(BIN)/python -m benchmarks

sync: $(STAMP)  ## write the API reference pages (book/api, long modules split into sub-pages) and their entries in book/_toc.yml, and the registry's figure captions into the notebooks
	$(BIN)/python -m mascore._booktools sync

captions: sync

lock:  ## regenerate requirements.lock from pyproject.toml in a scratch venv
	rm -rf .lock-venv && $(PYTHON) -m venv .lock-venv
	.lock-venv/bin/python -m pip install --quiet pip==$(PIP_VERSION) && .lock-venv/bin/python -m pip install --quiet ".[book,dev,bench]" "setuptools>=77" wheel
	echo '# Exact versions installed by the Makefile (regenerate with `make lock`).' > requirements.lock
	.lock-venv/bin/python -m pip freeze --all --exclude-editable | grep -v -e '^mascore' -e '^pip==' $(LOCK_OMITS) >> requirements.lock
	rm -rf .lock-venv

clean:  ## remove the environment, the built book, results and caches
	rm -rf $(VENV) $(MIN_VENV) book/_build results .pytest_cache .hypothesis .test-min.log
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
