# Self-installing targets: each creates .venv and installs the project with the
# extras it needs on first use, so a fresh machine needs only python3 and make.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# Tiny least-squares solves are ~10x slower with threaded BLAS on 2 cores.
export OPENBLAS_NUM_THREADS := 1
export OMP_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
export MPLBACKEND := Agg

.PHONY: demo test test-slow test-docs test-wheel bench bench-quick docs readme install clean

$(VENV)/.installed-%: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[$*]"
	touch $@

install: $(VENV)/.installed-test

demo: $(VENV)/.installed-test
	$(BIN)/vivbench demo --out demo

test: $(VENV)/.installed-test
	$(BIN)/python -m pytest -m "not slow" -q -n auto --dist loadfile

# The worked property test of docs/testing.md, written only against vivbench.testing, in a
# fresh venv where vivbench is installed from its wheel with the `testing` extra (nothing from
# this source tree is importable there): what a user of the published package gets. The venv
# gets no pip of its own (.venv's pip installs into it) and no byte-compilation: 4x faster.
test-wheel: $(VENV)/.installed-test
	@set -e; start=$$(date +%s); tmp=$$(mktemp -d); trap 'rm -rf "$$tmp"' EXIT; \
	$(BIN)/python -m pip wheel --quiet --no-deps --wheel-dir "$$tmp/dist" .; \
	$(PYTHON) -m venv --without-pip "$$tmp/venv"; \
	$(BIN)/python -m pip --python "$$tmp/venv/bin/python" install --quiet --no-compile \
		"$$(ls "$$tmp"/dist/vivbench-*.whl)[testing]" pytest; \
	awk '/^```python/{f=1;next} /^```/{f=0} f' docs/testing.md > "$$tmp/test_docs_testing.py"; \
	(cd "$$tmp" && venv/bin/python -m pytest -q -p no:cacheprovider test_docs_testing.py); \
	rm -rf "$$tmp"; echo "test-wheel: passed in $$(( $$(date +%s) - start )) s (wheel, venv, install, test, clean-up)"

test-slow: $(VENV)/.installed-test
	$(BIN)/python -m pytest -m slow -q

# The user paths as the pages print them: every shell command of the README, the field workflow,
# the field import and the contributed-methods section of docs/methods.md, run in order in an
# empty folder (tests/project/test_doc_shell.py; the fast page checks are part of `make test`).
test-docs: $(VENV)/.installed-test
	$(BIN)/python -m pytest -m slow -q -p no:cacheprovider tests/project/test_doc_shell.py

# The benchmark suite: speed against the reference packages (pysindy, pynumdiff, pyconturb,
# pydpc) and the chain's own timings; writes benchmarks/results.md (bench-quick: a reduced
# set on small workloads, under 10 min on 2 cores, writes benchmarks/results_quick.md).
# The accuracy studies are separate commands, each writing its own page under
# docs/results/studies/: python benchmarks/run_study.py NAME [ARGS ...].
bench: $(VENV)/.installed-test,bench
	$(BIN)/python benchmarks/run_all.py

bench-quick: $(VENV)/.installed-test,bench
	$(BIN)/python benchmarks/run_all.py --quick

# The documentation site (Sphinx): user guide, API reference from the docstrings, and the
# examples of examples/gallery/ executed during the build. Warnings are errors.
docs: $(VENV)/.installed-docs
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html

# The README's headline table, from the committed reference report (tests/project/test_readme.py
# checks that the README holds what this writes).
readme: $(VENV)/.installed-test
	$(BIN)/python tools/update_readme.py README.md reports/default/report.md

clean:
	rm -rf $(VENV) demo .pytest_cache .hypothesis docs/_build docs/generated docs/auto_examples docs/sg_execution_times.rst
