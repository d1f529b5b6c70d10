# The study book's commands. Only python3 (3.11) is needed; everything else is
# installed into .venv from environment.txt the first time.
PROFILE ?= paper
# JOBS > 1: train the missing runs first on a Dask LocalCluster of JOBS workers (drfkit.book.grid)
JOBS ?= 1
# WORKERS: the notebooks' evaluations as tasks on this many single-threaded processes (auto: every usable core;
# 1: in each notebook's kernel); the tables are the same at any WORKERS (drfkit.util.tasks)
WORKERS ?= auto
# REMEASURE=1: measure timings and compute the cached studies again (drfkit.book.measurements)
REMEASURE ?=
REMEASURE_FLAG := $(if $(filter-out 0,$(REMEASURE)),--remeasure)
# CELL_PROFILE=30: keep a cProfile of every cell slower than 30 s in results/$PROFILE/cell_profiles/
CELL_PROFILE ?=
CELL_PROFILE_FLAG := $(if $(CELL_PROFILE),--cell-profile $(CELL_PROFILE))
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.drfkit-installed
# the book's tools (Sphinx, MyST-NB, playwright), installed on the first `make book` only
BOOK_STAMP := $(VENV)/.book-installed
NBVAL_FLAGS := --nbval --nbval-sanitize-with notebooks/nbval_sanitize.cfg --nbval-cell-timeout 1200

.PHONY: reproduce quick test unit nbval bench notebooks book book-tools book-check clean help

help:
	@echo "make reproduce [PROFILE=paper|quick]  run every notebook, results in results/\$$PROFILE/"
	@echo "               [JOBS=N]               train the missing runs first on N Dask workers"
	@echo "               [WORKERS=auto|N]       the evaluations on N worker processes (default: every core)"
	@echo "               [REMEASURE=1]          measure timings again instead of reusing this machine's"
	@echo "               [CELL_PROFILE=30]      keep a cProfile of every cell slower than 30 s (cell_profiles/)"
	@echo "make quick                            the fast profile (< 10 min on 2 CPU cores)"
	@echo "make test                             unit tests + strict nbval on notebooks/"
	@echo "make bench                            the timing benchmark alone, prints the table"
	@echo "make notebooks                        rebuild notebooks/*.ipynb from notebooks/src/ and store outputs"
	@echo "make book [PROFILE=paper|quick]       the executed notebooks as an HTML book in results/\$$PROFILE/book/"
	@echo "make book-check                       open that book in headless chromium and check it (apt-get install chromium)"
	@echo "make book-tools                       only install the book's tools (then make test also builds small books)"
	@echo "make clean                            remove what runs produce (keeps results/paper/)"

$(STAMP): environment.txt pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r environment.txt
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $@

reproduce: $(STAMP)
	$(PY) -m drfkit reproduce --profile $(PROFILE) --jobs $(JOBS) --workers $(WORKERS) $(REMEASURE_FLAG) $(CELL_PROFILE_FLAG)

# the pipeline directly, not a second make: a SIGTERM to this make then reaches it (it dies with its parent)
quick: $(STAMP)
	$(PY) -m drfkit reproduce --profile quick --workers $(WORKERS) $(REMEASURE_FLAG)

test: $(STAMP) unit nbval

unit: $(STAMP)
	$(PY) -m pytest -q tests

# --durations: the slowest cells, named by notebook and code-cell index, where CI's time goes
nbval: $(STAMP)
	$(PY) -m pytest -q $(NBVAL_FLAGS) --durations=10 notebooks/

bench: $(STAMP)
	$(PY) -m drfkit bench --profile $(PROFILE)

notebooks: $(STAMP)
	$(PY) tools/build_notebooks.py --execute

# -c environment.txt: the book's packages never change the pins make test and make reproduce use
$(BOOK_STAMP): requirements-book.txt $(STAMP)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-book.txt -c environment.txt
	@touch $@

book-tools: $(BOOK_STAMP)

# nothing is executed: results/$(PROFILE)/ as a run left it, rendered by Sphinx (tools/build_book.py)
book: $(BOOK_STAMP)
	$(PY) tools/build_book.py --profile $(PROFILE)

book-check: $(BOOK_STAMP)
	$(PY) tools/check_book.py --profile $(PROFILE)

clean:
	find results -mindepth 1 -maxdepth 1 ! -name paper -exec rm -rf {} +
	rm -rf .pytest_cache
	find . -name __pycache__ -type d -not -path './$(VENV)/*' -prune -exec rm -rf {} +
	rm -rf results/paper/data results/paper/predictions results/paper/measurements results/paper/book
