# Two commands from a fresh clone: `make demo` and `make test`. Each creates .venv and installs
# the project into it (editable, with the test extras) the first time, then runs.
#   make demo ARGS="--viewer none"      extra arguments for `sensornet demo`
#   make test ARGS="-m 'not network'"   extra arguments for pytest
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
ARGS ?=

.PHONY: demo test install clean-venv

demo: $(STAMP)
	$(BIN)/sensornet demo $(ARGS)

test: $(STAMP)
	$(BIN)/python -m pytest -q $(ARGS)

install: $(STAMP)

# Re-installed when pyproject.toml changes; a failed install leaves no stamp (and fails make).
$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	-$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	@touch $(STAMP)

clean-venv:
	rm -rf $(VENV)
