# Two entry points for a fresh machine (README): `make figure7` and `make test`.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(BIN)/.thinfilm_jax-installed

.PHONY: figure7 test bench setup gpu-wheels gpu-check

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test,plots]'
	touch $@

setup: $(STAMP)

# writes the results only (figures/figure7.{png,json,npz}, figure7_error.png: the committed
# files, byte for byte, tests/test_main_job_clean.py) and prints its time; `make bench` times it
# into figures/figure7_timing.json (the docs' timing sentence)
figure7: $(STAMP)
	$(BIN)/thinfilm-jax figure7 --out figures

# two pytest-xdist workers (the CI machine has 2 cores); work units: tests/conftest.py. The
# run ends with where its time went (per file and the 20 longest tests: JAX tracing, lowering,
# XLA compilation, the rest; tests/_compile_report.py), from .test-time/ (git-ignored).
test: $(STAMP)
	@rm -rf .test-time && mkdir -p .test-time
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --jax-time-report=.test-time/run; \
	  rc=$$?; $(BIN)/python tests/_compile_report.py .test-time/run 20; exit $$rc

bench: $(STAMP)
	$(BIN)/thinfilm-jax figure7 --out figures --quiet --timing figures/figure7_timing.json
	$(BIN)/python -m benchmarks.bench --out figures

# The accelerator check (benchmarks/gpu_check.py). The device machine is offline and
# has JAX, NumPy, SciPy, matplotlib, optimistix and pytest but not these three: `make
# gpu-wheels` here downloads them for its Python 3.12 into .whl/ (ignored by git, ≈ 18 MB),
# `make gpu-check` there installs them and runs the suite, the GPU table and the kernel bench
# into $$OUT (or figures/); GPU_CHECK_ARGS=--kernel-baseline DIR times an older checkout's
# kernels too (e.g. `git worktree add .base 6b7cf29`, carried). CPU dry run: `make gpu-check
# PY=.venv/bin/python JAX_PLATFORMS=cpu GPU_CHECK_ARGS=--small`.
GPU_WHEELS := colour-science==0.4.7 openimageio==3.2.2.0 tmm==0.2.0
GPU_CHECK_ARGS ?=
gpu-wheels:
	$(PY) -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
	  --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
	  --platform manylinux2014_x86_64 -d .whl $(GPU_WHEELS)

gpu-check:
	@if ls .whl/*.whl >/dev/null 2>&1; then $(PY) -m pip install -q --no-index --no-deps \
	  --no-compile --no-cache-dir --upgrade --target /tmp/thinfilm_site .whl/*.whl; fi
	PYTHONPATH=$$PWD:/tmp/thinfilm_site$${PYTHONPATH:+:$$PYTHONPATH} \
	  $(PY) -m benchmarks.gpu_check $(GPU_CHECK_ARGS)
