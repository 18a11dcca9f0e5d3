# The README's two commands: `make demo` (set up, run the main job) and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
export PIP_CONSTRAINT := $(CURDIR)/constraints.txt
export RAY_USAGE_STATS_ENABLED := 0
export MLFLOW_SUPPRESS_PRINTING_URL_TO_STDOUT := 1

.PHONY: setup demo test bench gpu-bundle gpu-bundle-check clean

# The venv is (re)built when pyproject.toml or the constraints change; torch comes first so
# that nothing later can pull a CUDA build.
$(BIN)/sray: pyproject.toml setup.py constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip "setuptools>=77" wheel
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e ".[test]"
	touch $@

setup: $(BIN)/sray

demo: setup
	$(BIN)/sray demo

test: setup
	$(BIN)/python -m pytest -q -n 2 --dist loadgroup

bench: setup
	$(BIN)/sray bench loader
	$(BIN)/sray bench model

# The wheels a bare GPU machine needs beyond its image (docs/gpu.md), and the slow proof that such a bundle,
# built for this machine's Python, installs offline beside the CPU torch and runs the prepared GPU call's stages.
gpu-bundle: setup
	$(BIN)/sray gpu-bundle --out outputs/gpu-bundle

gpu-bundle-check: setup
	$(BIN)/sray gpu-bundle --check --out outputs/gpu-bundle-check

clean:
	rm -rf $(VENV) outputs build *.egg-info
