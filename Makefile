# Two commands: `make demo` (videos of every scene under scenes/) and `make test`.
# Both create .venv and install the project once; a second run installs nothing.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
INSTALLED := $(VENV)/.installed

.PHONY: demo test debug-kernels

$(INSTALLED): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e ".[test,examples,reconstruct,diffusion]"
	touch $@

demo: $(INSTALLED)
	$(BIN)/snakemake --cores 2

test: $(INSTALLED)
	$(BIN)/pytest

# Every simulate kernel in Warp's debug mode (bounds-checked indexing); splat's
# kernels are checked the same way by tests/splat.
debug-kernels: $(INSTALLED)
	$(BIN)/python benchmarks/debug_kernels.py
