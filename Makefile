# Two commands for a fresh machine (python3 with pip and venv): `make demo`, `make test`.
# Every dependency comes from requirements.lock: exact versions, sha256 hashes required
# (docs/development.md says how to refresh it with `make lock` and check it with `make test-latest`).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
LOCK := requirements.lock
LATEST := .venv-latest
# what the lock covers: pyproject's runtime dependencies, the dev and eval extras and the
# build group, for every supported Python from 3.10 on, on any platform (Linux x86_64/aarch64 among them)
LOCK_ARGS := pyproject.toml --extra dev --extra eval --group build --universal --generate-hashes \
	--python-version 3.10
# pytest-xdist: one worker per core (override with `make test PYTEST_WORKERS=1`); a module
# goes to one worker whole (--dist loadscope), so its module fixtures are built once
PYTEST_WORKERS ?= auto
# mypy's parallel checking (mypy >= 2.0): a cold cache, as on a clean clone, in 25 s instead of 40
MYPY_WORKERS ?= 2

.PHONY: demo test lint bench lock test-latest clean

# (Re)install only when the lock or the project's metadata changes; idempotent.
$(STAMP): $(LOCK) pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --require-hashes --no-deps -r $(LOCK)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/roadpreview demo

lint: $(STAMP)
	$(BIN)/ruff check src tests bench
	$(BIN)/mypy --num-workers $(MYPY_WORKERS)

test: lint
	$(BIN)/python -m pytest -n $(PYTEST_WORKERS) --dist loadscope --durations=15

bench: $(STAMP)
	$(BIN)/roadpreview bench all

# Regenerate the lock from pyproject.toml's ranges with today's newest allowed releases.
lock: $(STAMP)
	$(BIN)/uv pip compile $(LOCK_ARGS) --upgrade --no-header -o $(LOCK)

# The newest releases pyproject.toml allows, in a scratch venv, through the whole suite:
# what the next `make lock` would bring, tried before it lands.
test-latest: $(STAMP)
	rm -rf $(LATEST)
	$(BIN)/uv venv --quiet --python $(BIN)/python $(LATEST)
	$(BIN)/uv pip install --quiet --python $(LATEST)/bin/python --upgrade -e '.[dev,eval]' --group build
	$(BIN)/uv pip list --python $(LATEST)/bin/python --format freeze > $(LATEST)/versions.txt
	@echo "test-latest: $$(wc -l < $(LATEST)/versions.txt) packages, listed in $(LATEST)/versions.txt"
	$(LATEST)/bin/ruff check src tests bench
	$(LATEST)/bin/mypy --num-workers $(MYPY_WORKERS)
	$(LATEST)/bin/python -m pytest -n $(PYTEST_WORKERS) --dist loadscope

clean:
	rm -rf $(VENV) $(LATEST) build .pytest_cache .mypy_cache .ruff_cache
