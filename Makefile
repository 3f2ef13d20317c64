# make demo: set up .venv if missing, then run the built-in demo.  make test: set up, then run the tests.
# make lint: set up, then check the code with ruff (its settings: pyproject.toml's [tool.ruff]).
# make docs: set up, then build the documentation site into site/ (strict: a broken link or reference fails).
PYTHON ?= python3
VENV   := .venv
STAMP  := $(VENV)/.installed

.PHONY: demo test lint docs bench clean

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

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/python -m mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(VENV)/bin/python bench/generate.py
	$(VENV)/bin/python bench/synth.py
	$(VENV)/bin/python bench/models.py
	$(VENV)/bin/python bench/train.py
	$(VENV)/bin/python bench/infer.py

clean:
	rm -rf $(VENV) demo_out .pytest_cache site
