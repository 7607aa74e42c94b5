# navkit - every target sets itself up: a virtual environment in .venv with what it needs.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)

.PHONY: demo test test-portable bench lint fuzz clean

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
	MPLBACKEND=Agg $(BIN)/python -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --durations=25

# The kernel, twin and mission tests once more as another CPU would run them: Numba compiling for
# a generic x86-64 (no AVX) with bounds checks on, into a cache of its own, and NumPy with its
# dispatched SIMD loops (AVX2, AVX-512 on x86; what the machine dispatches elsewhere) switched
# off. CI runs it after `make test` (.ci/run); docs/kernels.md, "The equivalence contract".
PORTABLE_TESTS ?= tests/geometry tests/localization/test_kernels.py tests/obstacles/test_kernels.py \
  tests/path/test_kernels.py tests/planes/test_kernels.py tests/stereo/test_kernels.py \
  tests/planes/test_dense.py::test_the_dense_kernels_equal_their_twins_bit_for_bit \
  tests/mission/test_mission.py tests/mission/test_twins.py $(wildcard tests/fuzz/test_kernel_inputs.py)
test-portable: $(STAMP)
	@cache=$$(mktemp -d) && \
	npy_off=$$($(BIN)/python -c "from numpy._core._multiarray_umath import __cpu_dispatch__ as d; print(' '.join(d))" 2>/dev/null || true) && \
	echo "portable pass: NUMBA_CPU_NAME=generic NUMBA_BOUNDSCHECK=1 NPY_DISABLE_CPU_FEATURES='$$npy_off'" && \
	NUMBA_CPU_NAME=generic NUMBA_BOUNDSCHECK=1 NUMBA_CACHE_DIR=$$cache NPY_DISABLE_CPU_FEATURES="$$npy_off" \
	  MPLBACKEND=Agg $(BIN)/python -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile $(PORTABLE_TESTS); \
	rc=$$?; rm -rf $$cache; exit $$rc

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
	$(BIN)/vulture src vulture_whitelist.py --min-confidence 80
	$(BIN)/ruff check src tests benchmarks fuzz
	$(BIN)/ruff format --check src tests benchmarks fuzz
	$(BIN)/mypy

clean:
	rm -rf $(VENV) out build *.egg-info src/*.egg-info
