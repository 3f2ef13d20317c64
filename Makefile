# make demo: set up .venv if missing, then run the built-in demo.  make test: set up, then run the tests.
# make lint: set up, then check the code with ruff (its settings: pyproject.toml's [tool.ruff]).
# make docs: set up, then build the documentation site into site/ (strict: a broken link or reference fails).
PYTHON ?= python3
VENV   := .venv
STAMP  := $(VENV)/.installed

.PHONY: demo test lint docs bench clean base-check

$(STAMP): pyproject.toml
	@test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e '.[dev]'
	@touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/freespace demo --out demo_out

test: $(STAMP)
	$(VENV)/bin/python -m pytest -q

lint: $(STAMP)
	$(VENV)/bin/ruff check freespace tests bench studies docs

# the base install (no extras: NumPy, OpenCV, tqdm, PyYAML) in a fresh environment, and what it serves: synth,
# generate, autolabel and datasets info on a small rendered dataset (issue 60: no torch, no pydantic on that path)
base-check:
	rm -rf .venv-base
	$(PYTHON) -m venv .venv-base
	.venv-base/bin/python -m pip install --quiet .
	tmp=$$(mktemp -d) && trap 'rm -rf "$$tmp"' EXIT && \
	.venv-base/bin/freespace synth --out $$tmp/syn --num 20 --width 160 --height 120 --frames-per-scenario 5 && \
	.venv-base/bin/freespace generate --dataset synth --root $$tmp/syn --out $$tmp/gen && \
	.venv-base/bin/freespace autolabel --dataset synth --root $$tmp/syn --out $$tmp/labels && \
	.venv-base/bin/freespace datasets info --dataset synth --root $$tmp/syn > /dev/null && \
	.venv-base/bin/python -c "import sys, freespace.cli; assert 'torch' not in sys.modules and 'pydantic' not in sys.modules"
	rm -rf .venv-base

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/python -m mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(VENV)/bin/python bench/generate.py
	$(VENV)/bin/python bench/synth.py
	$(VENV)/bin/python bench/models.py
	$(VENV)/bin/python bench/train.py
	$(VENV)/bin/python bench/infer.py

clean:
	rm -rf $(VENV) .venv-base demo_out .pytest_cache site
