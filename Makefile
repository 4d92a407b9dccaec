# Two entry points: `make demo` runs the main job, `make test` runs the test suite.
# Both create .venv on first use (torch's CPU wheel first, then the project with dev extras).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-long lint bench clean-venv

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[dev,ray,sweep]"
	touch $(STAMP)

demo: $(STAMP)
	MUJOCO_GL=egl $(BIN)/python evo/main.py +exp=demo

test: $(STAMP)
	MUJOCO_GL=egl $(BIN)/python -m pytest -q -n 2 --dist loadfile
	$(BIN)/ruff check evo analysis tests bench
	$(BIN)/mypy
	$(BIN)/lint-imports

test-long: $(STAMP)
	MUJOCO_GL=egl $(BIN)/python -m pytest -q -n 2 --dist loadfile -m long

clean-venv:
	rm -rf $(VENV)
