# Two commands: `make demo` (videos of every scene under scenes/) and `make test`.
# Both create .venv and install the project once; a second run installs nothing.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
INSTALLED := $(VENV)/.installed
# The stage programs (pm-*) live in the venv; snakemake rules call them by name.
export PATH := $(CURDIR)/$(BIN):$(PATH)

.PHONY: demo test

$(INSTALLED): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e ".[test,examples,diffusion]"
	touch $@

demo: $(INSTALLED)
	$(BIN)/snakemake --cores 2

test: $(INSTALLED)
	$(BIN)/pytest
