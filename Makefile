# Entry points: `make demo` runs the main job, `make test` runs the test suite, `make docs`
# builds the site. They create .venv on first use (torch's CPU wheel first, then the
# project with its dev, ray, sweep and docs extras).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-long docs docs-serve lint bench clean-venv

# The suite runs two test processes side by side (-n 2); each one's BLAS/OpenMP pool on
# one thread keeps them from oversubscribing two cores (measured: 11.5 min against
# 13.6). Code that wants more threads sets them itself (torch_threads, the executors).
PYTEST := OMP_NUM_THREADS=1 MUJOCO_GL=egl $(BIN)/python -m pytest -q -n 2 --dist loadfile

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[dev,ray,sweep,docs]"
	touch $(STAMP)

demo: $(STAMP)
	MUJOCO_GL=egl $(BIN)/python evo/main.py +exp=demo

test: $(STAMP)
	$(PYTEST) --durations=15
	$(BIN)/ruff check evo analysis tests bench
	$(BIN)/mypy
	$(BIN)/lint-imports

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

docs-serve: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs serve

test-long: $(STAMP)
	$(PYTEST) -m long

clean-venv:
	rm -rf $(VENV)
