# Quick start: `make demo` and `make test`. Both create .venv when it is missing.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
ZOO_STAMP := $(VENV)/.installed-zoo
# the numeric stack's pinned versions (pip constraints): the quick reference reproduces bit for bit only on them
STACK := trade_gym/bench/reference_stack.txt
# make test's reference check writes its results here (git-ignored)
CHECK_OUT := reference_check_out
# extra pip arguments for torch, e.g. --index-url https://download.pytorch.org/whl/cpu where pip's find-links hold no
# CPU wheel for the interpreter (this machine's /opt/wheels holds one for 3.11 only; PyPI's Linux wheel is the CUDA one)
TORCH_PIP_ARGS ?=
# the interpreters of make test-py312 / test-py313: a pyenv install if there is one, else the name on PATH
PYTHON312 ?= $(firstword $(wildcard $(HOME)/.pyenv/versions/3.12.*/bin/python3.12) python3.12)
PYTHON313 ?= $(firstword $(wildcard $(HOME)/.pyenv/versions/3.13.*/bin/python3.13) python3.13)

.PHONY: demo test test-py312 test-py313 test-slow bench clean-venv

$(STAMP): pyproject.toml $(STACK)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first (a CPU wheel where pip finds one: TORCH_PIP_ARGS), so stable-baselines3 does not pull a CUDA build
	$(PY) -m pip install --quiet $(TORCH_PIP_ARGS) "torch==2.13.0"
	$(PY) -m pip install --quiet -c $(STACK) -e ".[test,ray,video,lint]"
	# PyPI's CUDA torch brings triton (torch.compile's GPU kernels; nothing here uses it), whose bundled LLVM segfaults
	# the test process once pybullet's EGL plugin has loaded Mesa's LLVM (tests/trade_gym/test_egl.py probes it at
	# collection, then the first SB3 model imports torch._dynamo, which imports triton): seen on 3.12 and 3.13;
	# a no-op where torch is the CPU build
	$(PY) -m pip uninstall --yes --quiet triton
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/trade-bench --suite quick --out demo_out --video

test: $(STAMP)
	$(VENV)/bin/ruff check .
	# the type check of trade/, trade_gym/ and agents/ ([tool.mypy] in pyproject.toml)
	$(PY) scripts/typecheck.py
	$(PY) -m pytest -q -p no:cacheprovider
	# the regression guard: every quick-suite run must reproduce trade_gym/bench/quick_reference.json (~1-3 min)
	$(VENV)/bin/trade-bench --suite quick --out $(CHECK_OUT) --check-reference

# make test on another interpreter in a venv of its own: the same recipe, with PYTHON, VENV and CHECK_OUT overridden.
# pybullet has no wheel for 3.12 or 3.13: the venv's first install builds it from the sdist (~4 min on 2 cores, needs
# a C++ compiler); pip's cache keeps the built wheel, so later venvs on the same machine install it in seconds.
test-py312:
	$(MAKE) test PYTHON=$(PYTHON312) VENV=.venv-py312 CHECK_OUT=reference_check_out_py312

test-py313:
	$(MAKE) test PYTHON=$(PYTHON313) VENV=.venv-py313 CHECK_OUT=reference_check_out_py313

# the slow suite also trains with rl-zoo3 (the zoo extra, installed once into the venv)
$(ZOO_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -c $(STACK) -e ".[zoo]"
	touch $(ZOO_STAMP)

test-slow: $(ZOO_STAMP)
	$(PY) -m pytest -q -m slow

bench: $(STAMP)
	$(PY) benchmarks/speed.py

clean-venv:
	rm -rf $(VENV) .venv-py312 .venv-py313
