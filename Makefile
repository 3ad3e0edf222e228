# Quick start: `make demo` and `make test`. Both create .venv when it is missing.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# make test's reference check writes its results here (git-ignored)
CHECK_OUT := reference_check_out

.PHONY: demo test test-slow bench clean-venv

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first from the local CPU wheel, so stable-baselines3 does not pull a CUDA build
	$(PY) -m pip install --quiet "torch==2.13.0"
	$(PY) -m pip install --quiet -e ".[test,ray,video,lint]"
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

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

bench: $(STAMP)
	$(PY) benchmarks/speed.py

clean-venv:
	rm -rf $(VENV)
