# Two commands: `make demo` (videos of every scene under scenes/) and `make test`.
# Both create .venv and install the project once; a second run installs nothing.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# The demo's part (the stages, the examples' images) first, the tests' and the optional backends' after.
DEMO_INSTALLED := $(VENV)/.installed-demo
INSTALLED := $(VENV)/.installed

.PHONY: demo test browser debug-kernels

# One resolver run; --no-compile: the modules a run imports are byte-compiled then, not all of torch's now.
$(DEMO_INSTALLED): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --no-compile torch==2.13.0 -e ".[examples,reconstruct]"
	touch $@

$(INSTALLED): $(DEMO_INSTALLED)
	$(BIN)/pip install --quiet --no-compile -e ".[test,examples,reconstruct,diffusion,setup]"
	touch $@

demo: $(DEMO_INSTALLED)
	$(BIN)/snakemake --cores 2

# One pytest-xdist worker per core; tests/conftest.py keeps each module that shares a fixture on one.
# PYTEST_ARGS adds options (benchmarks/test_suite.py: a JUnit report).
test: $(INSTALLED) browser
	$(BIN)/pytest -n auto $(PYTEST_ARGS)

# Debian's chromium and chromedriver for pm-setup's browser test (tests/setup), installed with apt when
# missing and this is root on Debian; elsewhere that test is skipped and says why.
browser:
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || \
	{ [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null && apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null; } || \
	echo "chromium and chromedriver could not be installed: the browser test will be skipped"

# Every simulate kernel in Warp's debug mode (bounds-checked indexing); splat's
# kernels are checked the same way by tests/splat.
debug-kernels: $(INSTALLED)
	PYTHONPATH=. $(BIN)/python benchmarks/debug_kernels.py
