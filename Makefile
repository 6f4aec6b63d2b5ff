# Two commands for a fresh machine (each sets up only what is missing, then runs):
#   make demo   the virtual environment, CPU-only PyTorch, the project; then the demo
#   make test   the same, plus the ETH/UCY and CITR data (unless STCROWD_DATA / STCROWD_CITR point at copies); then
#               the test suite
# On a machine whose pip already offers a CPU build of torch: make demo TORCH="torch==2.13.0"
# Then:
#   make docs   the documentation site, as CI builds it (mkdocs build --strict, into site/)
#   make fuzz   the property tests with fresh random draws, FUZZ_FACTOR times their examples (docs/contributing.md)

PYTHON ?= python3
VENV ?= .venv
TORCH ?= torch --index-url https://download.pytorch.org/whl/cpu
PY := $(VENV)/bin/python
FUZZ_FACTOR ?= 10
FUZZ_TESTS ?= tests

.PHONY: demo test docs fuzz data setup

demo: setup
	@echo "== running the demo: python -m st_sim demo"
	$(PY) -m st_sim demo

test: setup data
	@echo "== running the tests: OMP_NUM_THREADS=1 python -m pytest"
	OMP_NUM_THREADS=1 $(PY) -m pytest

docs: setup
	@echo "== building the documentation site: mkdocs build --strict (into site/)"
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

fuzz: setup data
	@echo "== exploring: the property tests in $(FUZZ_TESTS), fresh draws, $(FUZZ_FACTOR)x their examples"
	HYPOTHESIS_PROFILE=fuzz HYPOTHESIS_FUZZ_FACTOR=$(FUZZ_FACTOR) OMP_NUM_THREADS=1 $(PY) -m pytest $(FUZZ_TESTS)

setup: $(VENV)/.installed

$(PY):
	@echo "== creating the virtual environment $(VENV)"
	$(PYTHON) -m venv $(VENV)

# CPU-only torch first (a plain `pip install torch` pulls gigabytes of CUDA wheels), then the project and its test tools;
# redone only when pyproject.toml changes
$(VENV)/.installed: pyproject.toml | $(PY)
	@$(PY) -c "import torch" 2>/dev/null && echo "== torch is installed" || \
		{ echo "== installing CPU-only torch: pip install $(TORCH)"; $(PY) -m pip install --quiet $(TORCH); }
	@echo "== installing the project: pip install -e .[dev]"
	$(PY) -m pip install --quiet -e ".[dev]"
	@touch $@

data: setup
	@if [ -n "$$STCROWD_DATA" ]; then echo "== ETH/UCY data: STCROWD_DATA=$$STCROWD_DATA"; \
	else echo "== ETH/UCY data: python -m replays fetch (skips files already fetched and checked)"; \
		$(PY) -m replays fetch --quiet; fi
	@if [ -n "$$STCROWD_CITR" ]; then echo "== CITR data: STCROWD_CITR=$$STCROWD_CITR"; \
	else echo "== CITR data: python -m replays fetch --dataset citr (skips files already fetched and checked)"; \
		$(PY) -m replays fetch --dataset citr --quiet; fi
