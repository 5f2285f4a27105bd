# greenloop: every entry point. `make help` lists targets and the variables you can override.
SHELL := bash
.DELETE_ON_ERROR:
.SUFFIXES:

PYTHON   ?= python3
VENV     ?= .venv
BIN      := $(VENV)/bin
DATASET  ?= data/synthetic-greenhouse
RESULTS  ?= results
PARAMS   ?=
TIMEOUT  ?= 7200
KERNEL   := greenloop
SWEEP_NOTEBOOK ?= notebooks/01_spot_grouping.ipynb
SWEEP_GRID     ?= frames_per_spot_list=[40],[50],[60],[70],[80]
SWEEP_METRIC   ?= table1.csv:acc_mean_%
SWEEP_OUT      ?= $(RESULTS)/sweep/$(basename $(notdir $(SWEEP_NOTEBOOK)))
SCHEDULER      ?= local
WORKERS        ?=
export PYTHONPATH := $(CURDIR)
export TF_CPP_MIN_LOG_LEVEL := 2
export PYTHONUNBUFFERED := 1

NOTEBOOKS := $(sort $(wildcard notebooks/[0-9][0-9]_*.ipynb))
EXECUTED  := $(patsubst notebooks/%.ipynb,$(RESULTS)/%.ipynb,$(NOTEBOOKS))
HTML      := $(EXECUTED:.ipynb=.html)
SOURCES   := $(wildcard greenloop/*.py)
STAMP     := $(VENV)/.installed
SYNTHETIC := data/synthetic-greenhouse

.PHONY: all help venv synthetic data test quick sweep bench clean-results
.DEFAULT_GOAL := help

help: ## this list
	@echo "greenloop: CNN loop-closure detection study. Targets:"
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-14s %s\n", $$1, $$2}'
	@echo "Variables (make VAR=value ...):"
	@echo "  DATASET=$(DATASET)   sequence folder the notebooks study"
	@echo "  RESULTS=$(RESULTS)   where executed notebooks, figures and tables go"
	@echo "  PARAMS='-p epochs 50'   extra papermill arguments for every notebook"
	@echo "  TIMEOUT=$(TIMEOUT)   per-cell execution timeout, seconds"
	@echo "  PYTHON=$(PYTHON)   interpreter used to create $(VENV)"
	@echo "  make sweep: SWEEP_NOTEBOOK=$(SWEEP_NOTEBOOK)  SWEEP_GRID='$(SWEEP_GRID)' (space-separated grids)"
	@echo "              SWEEP_METRIC='$(SWEEP_METRIC)'  SWEEP_OUT=$(SWEEP_OUT)"
	@echo "              SCHEDULER=$(SCHEDULER) (local | tcp://host:8786 | slurm | pbs)  WORKERS=N  PARAMS='-f params/quick.yaml'"

venv: $(STAMP) ## create .venv from environment.txt (and register the Jupyter kernel)

$(STAMP): environment.txt
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -r environment.txt
	$(BIN)/python -m ipykernel install --sys-prefix --name $(KERNEL) --display-name "Python (greenloop)" >/dev/null
	@touch $@

synthetic: $(SYNTHETIC)/synthetic.json ## generate the embedded synthetic greenhouse sequence (2260 frames)

# The generator renders into a temporary folder and renames it at the end, so synthetic.json
# in place means a complete sequence.
$(SYNTHETIC)/synthetic.json: | $(STAMP)
	$(BIN)/python -m greenloop.synthetic $(SYNTHETIC) --overwrite

data: | $(STAMP) ## download the real GreenHouse set into data/greenhouse (resumable)
	$(BIN)/python -m greenloop.download data/greenhouse

# The dataset a run needs: the synthetic default is generated when missing; any other folder
# must exist already.
ifeq ($(DATASET),$(SYNTHETIC))
DATA_DEP := $(SYNTHETIC)/synthetic.json
else
DATA_DEP := $(DATASET)
endif

all: $(HTML) $(RESULTS)/tables.md ## run every notebook into results/, render HTML, assemble results/tables.md

$(RESULTS)/%.ipynb: notebooks/%.ipynb $(SOURCES) $(DATA_DEP) | $(STAMP)
	@mkdir -p $(@D)
	@echo "== $*"
	$(BIN)/papermill -k $(KERNEL) --execution-timeout $(TIMEOUT) --log-output --progress-bar \
	    -p dataset $(DATASET) -p results_dir $(RESULTS) $(PARAMS) $< $(@D)/.tmp-$*.ipynb
	@mv $(@D)/.tmp-$*.ipynb $@

$(RESULTS)/%.html: $(RESULTS)/%.ipynb
	$(BIN)/jupyter nbconvert --to html --log-level WARN --output-dir $(@D) --output .tmp-$* $<
	@mv $(@D)/.tmp-$*.html $@

$(RESULTS)/tables.md: $(EXECUTED)
	$(BIN)/python -m greenloop.report $(RESULTS)

quick: ## the same notebooks with few epochs and seeds into results/quick/ (minutes)
	$(MAKE) all RESULTS=results/quick PARAMS="-f params/quick.yaml $(PARAMS)"

# `make sweep`: greenloop.sweep over Dask (python -m greenloop sweep --help). Each --grid is one
# word of SWEEP_GRID; points whose point.json says ok are skipped, so an interrupted sweep resumes.
sweep: $(DATA_DEP) | $(STAMP) ## Dask sweep of SWEEP_GRID over SWEEP_NOTEBOOK (default L = 40..80 in 01) -> results/sweep/
	$(BIN)/python -m greenloop sweep $(SWEEP_NOTEBOOK) $(foreach g,$(SWEEP_GRID),--grid '$(g)') \
	    --dataset $(DATASET) --out $(SWEEP_OUT) --scheduler $(SCHEDULER) $(if $(WORKERS),--workers $(WORKERS)) \
	    $(if $(SWEEP_METRIC),--metric '$(SWEEP_METRIC)') --timeout $(TIMEOUT) $(PARAMS)

bench: | $(STAMP) ## speed benchmark: streaming detector and training vs plain Keras -> results/bench/
	$(BIN)/python -m greenloop.bench --out $(RESULTS)/bench --dataset $(DATASET)
	$(BIN)/python -m greenloop.report $(RESULTS)

# Optional, for the GhostNet-vs-timm check only: a CPU torch wheel where the machine has one
# (never the multi-GB CUDA build from PyPI), and timm without its torchvision dependency.
TORCH_WHEEL := $(firstword $(wildcard /opt/wheels/torch-2.13.0*cpu*.whl))
$(VENV)/.timm: $(STAMP)
ifneq ($(TORCH_WHEEL),)
	$(BIN)/python -m pip install -q $(TORCH_WHEEL)
	$(BIN)/python -m pip install -q --no-deps timm==1.0.31
else
	@echo "no local CPU torch wheel: the GhostNet-vs-timm test will be skipped"
endif
	@touch $@

test: $(VENV)/.timm | $(STAMP) ## run the test suite (unit tests and every notebook on tiny parameters)
	$(BIN)/python -m pytest -q tests

clean-results: ## remove executed notebooks and tables (keeps the model cache)
	rm -rf $(EXECUTED) $(HTML) $(RESULTS)/tables.md
