# mrslam: `make demo` runs the main job, `make test` runs every test. Both set up .venv first.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OUT    ?= runs/demo
DATA   ?= ../shared/data

.PHONY: venv demo test bench clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[ros,test]"
	touch $(STAMP)

# Until the simulated team lands, the main job is the joint filter on real multi-robot data.
demo: venv
	$(VENV)/bin/mrslam mrclam $(DATA)/mrclam/dataset6 --out $(OUT)
	@echo "report: $(OUT)/report.json"

test: venv
	$(PY) -m pytest -q

bench: venv
	$(VENV)/bin/mrslam bench filter --out runs/bench

clean:
	rm -rf $(VENV) runs build *.egg-info
