# kesbrdf — one-command setup, demo, tests and benchmarks on a fresh machine.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
OUT ?= out/demo
# Dr.Jit needs LLVM >= 17 (LLVM 15/16 crash, docs/architecture.md, "Tools it runs on"): Debian's libllvm19, installed by `make system`.
export DRJIT_LIBLLVM_PATH ?= /usr/lib/$(shell uname -m)-linux-gnu/libLLVM-19.so
export MPLBACKEND ?= Agg

.PHONY: all demo showcase test test-py test-web bench fuzz system venv viewer clean

all: test

system:
	bash scripts/setup-system.sh

$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q -e '.[all]'
	# Blender 4.5 as a module (the `blender` extra, for kesbrdf.export.looks) without its
	# numpy<2 pin: it runs on numpy 2 (docs/decisions.md, "bpy outside [all]")
	$(PIP) install -q --no-deps 'bpy>=4.5,<4.6'
	touch $@

venv: system $(VENV)/.installed

viewer/node_modules/.installed: viewer/package.json
	cd viewer && npm ci --no-audit --no-fund --loglevel=error
	touch $@

viewer: viewer/node_modules/.installed

demo: venv
	$(VENV)/bin/kesbrdf demo -o $(OUT)

# The full clip: the satin skirt on the mannequin turning 180°, 4.5 s at 24 fps, native
# 1280x720, denoised (MP4 + GIF + a strip of four frames) in out/showcase; resumable.
# Uses the demo's model when `make demo` ran, else fits the embedded sample itself.
SHOWCASE_OUT ?= out/showcase
showcase: venv
	$(VENV)/bin/kesbrdf showcase $(if $(wildcard $(OUT)/model.kes.json),$(OUT)/model.kes.json) -o $(SHOWCASE_OUT)

# The suite includes the doctests of src/kesbrdf (tests/test_doctests.py) and a few
# thousand fuzz examples per reader (tests/fuzz).  Two workers (pytest-xdist), one per
# core; a test file stays on one worker so its module fixtures are built once.
# Tests marked `slow` (acceptance sweeps over whole fits, e.g. dense vs paper protocol on a
# satin) run in `make test-long`, which CI runs after `make test`.
PYTEST_WORKERS ?= 2
test: venv $(if $(shell command -v npm 2>/dev/null),viewer)
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile -m "not slow"
	@if [ -f viewer/package.json ]; then $(MAKE) --no-print-directory test-web; fi

test-long: venv
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) -m slow

test-web: venv viewer
	cd viewer && npm run build -- --outDir ../build/viewer-check --emptyOutDir >/dev/null && \
	  diff -r ../build/viewer-check ../src/kesbrdf/viewer/static >/dev/null || \
	  { echo "viewer bundle in src/kesbrdf/viewer/static is stale: run 'make viewer-bundle'"; exit 1; }
	cd viewer && KESBRDF_PYTHON=../$(PY) npm test

viewer-bundle: viewer
	cd viewer && npm run build -- --outDir ../src/kesbrdf/viewer/static --emptyOutDir

# Property-based fuzzing at full strength: 100,000 mutated inputs per reader (tests
# marked `fuzz`; FUZZ_EXAMPLES=N for a shorter sweep).  Counts go to build/fuzz-stats.json.
FUZZ_EXAMPLES ?= 100000
fuzz: venv
	@mkdir -p build
	HYPOTHESIS_PROFILE=fuzz KESBRDF_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) KESBRDF_FUZZ_STATS=build/fuzz-stats.json \
	  $(PY) -m pytest -q -m fuzz tests

bench: venv
	$(PY) benchmarks/run.py --output benchmarks/results.json

clean:
	rm -rf out build .pytest_cache
