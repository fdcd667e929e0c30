# One command sets up and runs the main job (`make run`); one sets up and runs the tests
# (`make test`). Both create .venv on first use.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
OUT ?= out

.PHONY: setup build run test test-slow bench clean

$(BIN)/railfmu: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $@

setup: $(BIN)/railfmu

build: setup
	$(BIN)/railfmu build

run: build
	$(BIN)/railfmu run lateral_alignment --master container --out $(OUT)/lateral_alignment

test: setup
	$(BIN)/python -m pytest -q

test-slow: setup
	$(BIN)/python -m pytest -q -m slow

bench: build
	$(BIN)/python benchmarks/step_cost.py
	$(BIN)/python benchmarks/masters.py
	$(BIN)/python benchmarks/overhead.py
	$(BIN)/python benchmarks/train_ukf.py
	$(BIN)/python benchmarks/process_model.py
	$(BIN)/python benchmarks/strapdown.py
	$(BIN)/python benchmarks/trolley_survey.py
	$(BIN)/python benchmarks/trolley_filter.py

clean:
	rm -rf build $(OUT) .pytest_cache
