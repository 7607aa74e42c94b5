# navkit - every target sets itself up: a virtual environment in .venv with what it needs.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)

.PHONY: demo test bench lint fuzz clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/pip install --quiet -e ".[test,dev]"
	@rm -f $(VENV)/.installed-* && touch $@

$(VENV)/.bench-installed: $(STAMP)
	$(BIN)/pip install --quiet -e ".[test,dev,bench]"
	@# Open3D's wheel needs the system's libusb; install it where we can (Debian, root).
	@if ! ldconfig -p 2>/dev/null | grep -q libusb-1.0 && command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
	  apt-get install -y -qq libusb-1.0-0 >/dev/null 2>&1 || (apt-get update -qq && apt-get install -y -qq libusb-1.0-0) >/dev/null 2>&1 || \
	  echo "note: libusb-1.0 missing; Open3D comparisons will be skipped"; fi
	@touch $@

demo: $(STAMP)
	MPLBACKEND=Agg $(BIN)/navkit demo --out out/demo --overwrite

# The suite runs on TEST_WORKERS processes (pytest-xdist), one test file per worker at a time, so
# that a file's kernels compile once; 2 = the CI machine's cores. TEST_WORKERS=0 runs serially.
TEST_WORKERS ?= 2
test: $(STAMP)
	MPLBACKEND=Agg $(BIN)/python -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile

bench: $(VENV)/.bench-installed
	MPLBACKEND=Agg $(BIN)/python -m benchmarks

# Coverage-guided fuzzing of the binary readers (atheris; optional extra "fuzz"). The in-project
# Hypothesis fuzz suite (tests/fuzz) runs with `make test`; this one searches longer.
FUZZ_SECONDS ?= 120
fuzz: $(STAMP)
	$(BIN)/pip install --quiet -e ".[fuzz]"
	@mkdir -p out/fuzz/corpus
	cd out/fuzz && MPLBACKEND=Agg ../../$(BIN)/python ../../fuzz/fuzz_readers.py -max_total_time=$(FUZZ_SECONDS) -rss_limit_mb=2048 corpus

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks fuzz
	$(BIN)/ruff format --check src tests benchmarks fuzz
	$(BIN)/mypy

clean:
	rm -rf $(VENV) out build *.egg-info src/*.egg-info
