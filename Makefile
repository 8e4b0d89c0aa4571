# The only two set-up commands a newcomer needs are `make demo` and `make test`:
# both create .venv and install the project into it when it is absent.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench lint install browser clean

# The dependencies unpack to about 2.7 GB: uv installs them in about a quarter of pip's time
# (13 s against 52 s here, each from an empty cache). Where uv cannot be installed or cannot reach
# the package index, pip installs them instead. The repository's trustroute/ folder is the package
# root by design; setuptools warns about a folder named like the package at every editable
# install, which says nothing here.
EXTRAS := .[dev,peer,cities]
$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@$(BIN)/python -m pip install --quiet uv 2>/dev/null \
	  && $(BIN)/uv pip install --quiet --python $(BIN)/python -e '$(EXTRAS)' \
	  || { echo "uv did not install the dependencies; pip installs them"; \
	       $(BIN)/python -m pip install --quiet --upgrade pip \
	       && PYTHONWARNINGS="ignore:Editable installation" $(BIN)/python -m pip install --quiet -e '$(EXTRAS)'; }
	@touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/trustroute demo

# The browser tests drive Debian's Chromium and never skip (tests/browser.py): as root with apt-get
# it is installed here; elsewhere one line says what to install.
browser:
	@command -v chromium >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing Debian's Chromium for the browser tests (apt-get install chromium)"; \
	    apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	  else \
	    echo "make test needs Debian's Chromium for the browser tests: run 'sudo apt-get install -y chromium'" >&2; \
	    exit 2; \
	  fi; }

# tests/suite.py runs the suite in two lanes at once: the tests that wait on the wall clock (live
# stations, browsers; the `serial` browser session first and alone) at normal priority, the
# CPU-bound rest niced, one pytest-xdist worker per core in each. A lane that collects nothing is
# not a failure of the project.
test: $(STAMP) browser
	$(BIN)/python -m tests.suite

bench: $(STAMP)
	$(BIN)/python -m benchmarks

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m tests.typecheck

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .mypy_cache
