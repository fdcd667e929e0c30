# One command sets up and runs the main job (`make run`); one sets up and runs the tests
# (`make test`). Both create .venv on first use, from the exact versions of requirements.lock.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
OUT ?= out

.PHONY: setup build run test test-slow test-latest lint-imports lock bench clean sanitize

$(BIN)/railfmu: pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet -r requirements.lock
	$(BIN)/pip install --quiet --no-deps -e .
	touch $@

setup: $(BIN)/railfmu

build: setup
	$(BIN)/railfmu build

run: build
	$(BIN)/railfmu run lateral_alignment --master container --out $(OUT)/lateral_alignment

# import-linter reads the package as installed (it cannot follow the package-dir mapping).
lint-imports: setup
	rm -rf build/lint-imports
	$(BIN)/pip install --quiet --no-deps --target build/lint-imports .
	cd build/lint-imports && PYTHONPATH=. ../../$(BIN)/lint-imports --no-cache --config ../../pyproject.toml

# The sanitizer build and its fuzz first (about 2 min with the build), then the whole suite.
test: lint-imports sanitize
	$(BIN)/python -m pytest -q

test-slow: setup
	$(BIN)/python -m pytest -q -m slow

# Every FMU built with ASan + UBSan (and float-to-integer overflow, which UBSan leaves out) into
# its own cache (never mixed with the normal build; -O1: the build takes half the time of -O2),
# then the hostile-file corpus, the seeded fuzzes (FUZZ_SEED, FUZZ_CASES: FMU states, table
# readers, FMI call sequences) and the FMU tests run against them; any out-of-bounds access or
# undefined behaviour aborts the run. Python itself is not instrumented, so the runtime is
# preloaded and leak checks are off (CPython's own allocations); --capture=sys leaves the
# sanitizer's report on the terminal (pytest's capture of fd 2 dies with the aborted process).
SANITIZE_CACHE ?= build/sanitize
FUZZ_SEED ?= 0
FUZZ_CASES ?= 60
SANITIZE_TESTS := tests/test_fmu_state.py tests/test_runtime_c.py tests/test_fmus.py tests/test_hostile_tables.py \
	tests/test_fmi_call_fuzz.py tests/test_csv_table.py tests/test_table_files.py
sanitize: setup
	RAILFMU_CACHE=$(abspath $(SANITIZE_CACHE)) \
	RAILFMU_EXTRA_CFLAGS="-O1 -fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=all -fno-omit-frame-pointer" \
	LD_PRELOAD="$$(gcc -print-file-name=libasan.so) $$(gcc -print-file-name=libubsan.so)" \
	ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	RAILFMU_FUZZ_SEED=$(FUZZ_SEED) RAILFMU_FUZZ_CASES=$(FUZZ_CASES) \
	$(BIN)/python -m pytest -q -p no:cacheprovider --capture=sys $(SANITIZE_TESTS)

# The newest releases of every dependency instead of the lock: how the next refresh would fare.
test-latest:
	$(PYTHON) -m venv .venv-latest
	.venv-latest/bin/pip install --quiet --upgrade pip
	.venv-latest/bin/pip install --quiet --upgrade --upgrade-strategy eager -e '.[test]'
	.venv-latest/bin/python -m pytest -q

# Refresh the lock (needs uv: pip install uv), then run `make test` and commit both.
lock:
	uv pip compile pyproject.toml --extra test --python-version 3.11 -o requirements.lock -q --no-header
	sed -i '1i # Exact versions for `make test` and `make run` (Python 3.11, Linux). Refresh: `make lock`\n# (uv pip compile pyproject.toml --extra test --python-version 3.11 -o requirements.lock).' requirements.lock

bench: build
	$(BIN)/python benchmarks/step_cost.py
	$(BIN)/python benchmarks/masters.py
	$(BIN)/python benchmarks/overhead.py
	$(BIN)/python benchmarks/train_ukf.py
	$(BIN)/python benchmarks/process_model.py
	$(BIN)/python benchmarks/strapdown.py
	$(BIN)/python benchmarks/alignment_filter.py
	$(BIN)/python benchmarks/trolley_survey.py
	$(BIN)/python benchmarks/trolley_filter.py

clean:
	rm -rf build dist $(OUT) .pytest_cache
