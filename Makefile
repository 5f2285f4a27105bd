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
# a dataset's own budget, applied before PARAMS: params/datasets/<folder name>.yaml when it exists
DATASET_PARAMS := $(wildcard params/datasets/$(notdir $(DATASET)).yaml)
TIMEOUT  ?= 7200
KERNEL   := greenloop
# Folder(s) of real ImageNet weight files that greenloop.features' weights="auto" looks in first
# (os.pathsep-separated): here the MobileNet TFLite graphs beside the repo, when they exist. Point it
# at the files downloaded from github.com/google-coral/test_data (see greenloop.backbones.mobilenet_tflite).
GREENLOOP_WEIGHTS ?= $(abspath $(wildcard ../shared/weights/mobilenet-tflite))
export GREENLOOP_WEIGHTS
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
SOURCES   := $(wildcard greenloop/*.py greenloop/*/*.py)
STAMP     := $(VENV)/.installed
SYNTHETIC := data/synthetic-greenhouse
DAYS      := data/greenhouse-days
NORDLAND  := data/nordland
# a local copy of the Nordland source (summer/, winter/); empty: clone it from NORDLAND_URL
NORDLAND_SRC ?= $(if $(wildcard ../shared/real/nordland/summer),../shared/real/nordland,)
NORDLAND_URL ?= https://github.com/TimQuelch/seqslam
GARDENSPOINT := data/gardenspoint
# a local copy of Gardens Point Walking (day_left/, day_right/, night_right/); empty: clone GARDENSPOINT_URL
GARDENSPOINT_SRC ?= $(if $(wildcard ../shared/real/gardenspoint/night_right),../shared/real/gardenspoint,)
GARDENSPOINT_URL ?= https://github.com/aghagol/loop-detection

.PHONY: all help venv synthetic greenhouse-days data nordland gardenspoint test quick sweep bench bench-scale bench-stream clean-results readme default-choice verify provenance summary book browser
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
	@echo "  NORDLAND_SRC=$(NORDLAND_SRC)   local Nordland source for make nordland (empty: clone it)"
	@echo "  GARDENSPOINT_SRC=$(GARDENSPOINT_SRC)   local Gardens Point source for make gardenspoint (empty: clone it)"
	@echo "  GREENLOOP_WEIGHTS=$(GREENLOOP_WEIGHTS)   folder(s) of ImageNet weight files (weights=\"auto\")"
	@echo "  make sweep: SWEEP_NOTEBOOK=$(SWEEP_NOTEBOOK)  SWEEP_GRID='$(SWEEP_GRID)' (space-separated grids)"
	@echo "              SWEEP_METRIC='$(SWEEP_METRIC)'  SWEEP_OUT=$(SWEEP_OUT)"
	@echo "              SCHEDULER=$(SCHEDULER) (local | tcp://host:8786 | slurm | pbs)  WORKERS=N  PARAMS='-f params/quick.yaml'"

venv: $(STAMP) ## create .venv from environment.txt (and register the Jupyter kernel)

$(STAMP): environment.txt
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -r environment.txt
	$(BIN)/python -m ipykernel install --sys-prefix --name $(KERNEL) --display-name "Python (greenloop)" >/dev/null
	@# the kernel does not copy low-level output (TensorFlow's C++ logs, progress bars on the real
	@# stderr) into executed notebooks: it goes to the terminal that runs make (greenloop.util.progress)
	@mkdir -p $(VENV)/etc/ipython
	@# and it does not warn, once per notebook, that papermill's local kernel talks over TCP
	@printf 'c.IPKernelApp.capture_fd_output = False\nc.IPKernelApp.log_level = "ERROR"\n' \
		> $(VENV)/etc/ipython/ipython_kernel_config.py
	@touch $@

synthetic: $(SYNTHETIC)/synthetic.json ## generate the embedded synthetic greenhouse sequence (2260 frames)

# The generator renders into a temporary folder and renames it at the end, so synthetic.json
# in place means a complete sequence.
$(SYNTHETIC)/synthetic.json: | $(STAMP)
	$(BIN)/python -m greenloop data synthetic $(SYNTHETIC) --overwrite

greenhouse-days: $(DAYS)/greenhouse_days.json ## render the greenhouse over 5 days (~8,000 frames: the days and their stream)

# Rendered into a temporary folder and renamed at the end: greenhouse_days.json in place means a
# complete render (and the command itself skips a folder already rendered with the same arguments).
$(DAYS)/greenhouse_days.json: | $(STAMP)
	$(BIN)/python -m greenloop data greenhouse-days $(DAYS) --overwrite

data: | $(STAMP) ## download the real GreenHouse set into data/greenhouse (resumable)
	$(BIN)/python -m greenloop data greenhouse data/greenhouse

nordland: $(NORDLAND)/sequence.yaml ## build data/nordland: Nordland summer then winter, loop pairs as ground truth

# Built in a temporary folder and renamed at the end, so nordland.json in place means a complete
# folder. From NORDLAND_SRC when set, else from a shallow clone of NORDLAND_URL (fails at once
# offline, naming the fix).
$(NORDLAND)/nordland.json: | $(STAMP)
	$(BIN)/python -m greenloop data nordland $(NORDLAND) --overwrite \
	    $(if $(NORDLAND_SRC),--src $(NORDLAND_SRC),--url $(NORDLAND_URL))

# The builder's sequence.yaml (the targets' protocol), rewritten from nordland.json without touching
# the frames whenever the builder is newer: a folder built before gets what the builder writes now.
$(NORDLAND)/sequence.yaml: $(NORDLAND)/nordland.json greenloop/datasets/nordland.py
	$(BIN)/python -m greenloop data nordland $(NORDLAND) --describe

gardenspoint: $(GARDENSPOINT)/sequence.yaml ## build data/gardenspoint: Gardens Point Walking, 3 traversals of 200 frames (640x360)

# As Nordland: built in a temporary folder and renamed, from GARDENSPOINT_SRC or a shallow clone.
$(GARDENSPOINT)/gardenspoint.json: | $(STAMP)
	$(BIN)/python -m greenloop data gardenspoint $(GARDENSPOINT) --overwrite \
	    $(if $(GARDENSPOINT_SRC),--src $(GARDENSPOINT_SRC),--url $(GARDENSPOINT_URL))

# As Nordland's: its sequence.yaml rewritten from gardenspoint.json when the builder is newer.
$(GARDENSPOINT)/sequence.yaml: $(GARDENSPOINT)/gardenspoint.json greenloop/datasets/gardenspoint.py
	$(BIN)/python -m greenloop data gardenspoint $(GARDENSPOINT) --describe

# The dataset a run needs: the synthetic default, data/nordland and data/gardenspoint are built
# when missing; any other folder must exist already.
ifeq ($(patsubst %/,%,$(DATASET)),$(SYNTHETIC))
DATA_DEP := $(SYNTHETIC)/synthetic.json
else ifeq ($(patsubst %/,%,$(DATASET)),$(NORDLAND))
DATA_DEP := $(NORDLAND)/sequence.yaml
else ifeq ($(patsubst %/,%,$(DATASET)),$(GARDENSPOINT))
DATA_DEP := $(GARDENSPOINT)/sequence.yaml
else
DATA_DEP := $(DATASET)
endif

# the tables across the committed results folders; `make quick` (a first look) leaves them alone
CROSS ?= results/datasets.md results/coverage.md results/verdict.md results/PROVENANCE.md results/summary.md
# The executed notebooks and their tables are the record; their rendered pages are not committed: `make book`
# builds them into build/ from the executed notebooks (nothing re-executed).
all: $(EXECUTED) $(RESULTS)/tables.md $(CROSS) ## run every notebook into results/, assemble results/tables.md (pages: make book)

# One table across every dataset that has results: results/ (synthetic) and results/<name>/.
DATASET_RESULTS := results $(filter-out results/quick,$(patsubst %/07_feature_baselines/,%,$(wildcard results/*/07_feature_baselines/)))
results/datasets.md: $(wildcard $(DATASET_RESULTS:%=%/*/summary.json)) $(RESULTS)/tables.md
	$(BIN)/python -m greenloop tables --datasets $@ $(DATASET_RESULTS)

# Which table and figure of the papers the results reproduce (greenloop.study.coverage), read from them.
results/coverage.md: $(wildcard $(DATASET_RESULTS:%=%/*/manifest.json)) greenloop/study/coverage.py
	$(BIN)/python -m greenloop tables --coverage $@ $(DATASET_RESULTS)

# Does each paper's claim hold, per dataset (greenloop.study.verdict), read from the tables; README.md's
# verdict block is refilled by `make readme`, not by a run.
results/verdict.md: $(wildcard $(DATASET_RESULTS:%=%/*/manifest.json)) $(RESULTS)/tables.md greenloop/study/verdict.py
	$(BIN)/python -m greenloop verdict --out $@ $(DATASET_RESULTS)

# Each notebook's git commit, environment hash, CPU, date (its manifest) and duration (papermill's, in
# the executed notebook), one table per results folder (greenloop.study.provenance). After tables.md, as
# datasets.md: in `make all` (-j too) it reads the manifests this run wrote. `make provenance` writes it
# from the folders as they are, running nothing.
results/PROVENANCE.md: $(wildcard $(DATASET_RESULTS:%=%/*/manifest.json)) $(RESULTS)/tables.md greenloop/study/provenance.py
	$(BIN)/python -m greenloop provenance --out $@ $(DATASET_RESULTS)

provenance: | $(STAMP) ## results/PROVENANCE.md: each notebook's commit, environment hash, CPU, date and duration
	$(BIN)/python -m greenloop provenance --out results/PROVENANCE.md $(DATASET_RESULTS)

# Every leaderboard row, the main paper's detector as a loop-closure detector, the detector's targets and
# the long-recording benchmark, read from the folders' tables (greenloop.study.summary). After tables.md,
# as PROVENANCE.md: in `make all` it reads the tables this run wrote. `make summary` runs nothing.
results/summary.md: $(wildcard $(foreach t,leaderboard comparisons targets,$(DATASET_RESULTS:%=%/13_leaderboard/$(t).csv)) $(DATASET_RESULTS:%=%/01_spot_grouping/table1.csv) \
		$(DATASET_RESULTS:%=%/06_speed/paper_vs_run.csv) results/bench/scale_decisions.csv results/bench/scale.md) \
		$(RESULTS)/tables.md greenloop/study/summary.py
	$(BIN)/python -m greenloop summary --out $@ $(DATASET_RESULTS)

summary: | $(STAMP) ## results/summary.md: every leaderboard row, the paper's detector, the targets, from the tables
	$(BIN)/python -m greenloop summary --out results/summary.md $(DATASET_RESULTS)

# `make verify RESULTS=DIR`: did a rerun reproduce the committed tables? Every NN_name/*.csv of the
# committed folder of DIR's dataset (REFERENCE, or REFERENCE/<dataset>) against DIR's, cell by cell,
# timing columns aside, trained models' numbers within the committed seed spread (greenloop.study.verify).
# Exits non-zero when a table differs or is missing from DIR.
REFERENCE ?= results
verify: | $(STAMP) ## did a rerun reproduce? RESULTS=DIR's tables vs the committed REFERENCE=results, outside timing
	@test "$(origin RESULTS)" = "command line" || { echo "make verify RESULTS=DIR: name the rerun's results folder (compared with REFERENCE=$(REFERENCE))"; exit 2; }
	$(BIN)/python -m greenloop verify $(REFERENCE) $(RESULTS)

default-choice: $(NORDLAND)/sequence.yaml $(GARDENSPOINT)/sequence.yaml | $(STAMP) ## the named default's centring windows, cell shift and threshold, chosen on tuning queries -> results/default_choice/
	$(BIN)/python -m greenloop default-choice --nordland $(NORDLAND) --gardenspoint $(GARDENSPOINT) \
		--synthetic $(SYNTHETIC) --out results/default_choice

readme: | $(STAMP) ## the README's verdict table, results/verdict.md, summary.md and coverage.md, from the results folders
	$(BIN)/python -m greenloop tables --coverage results/coverage.md $(DATASET_RESULTS)
	$(BIN)/python -m greenloop tables results
	$(BIN)/python -m greenloop summary --out results/summary.md --readme README.md $(DATASET_RESULTS)
	$(BIN)/python -m greenloop verdict --out results/verdict.md --readme README.md $(DATASET_RESULTS)

# Each notebook gets, in increasing precedence: what the dataset says of itself (its sequence.yaml,
# or an exclude that fits its ground truth: $(RESULTS)/sequence_params.yaml, written by
# greenloop.study.params), dataset and results_dir, the dataset's budget, then PARAMS. A notebook
# that scores loops on a ground truth without any loop at its exclude is not run: the same command
# writes an executed notebook saying why (and $(RESULTS)/<stem>/skipped.md), prints the reason and
# the fix, and make carries on. Else it merges those parameters into .tmp-<stem>.yaml, keeping only
# the names the notebook's parameters cell declares (papermill would warn "Passed unknown parameter"
# for each other one; a name no notebook declares gets one line: a typo?), and writes the other
# papermill options of PARAMS (--start-timeout 60, ...) to .tmp-<stem>.args, which xargs appends.
$(RESULTS)/%.ipynb: notebooks/%.ipynb $(SOURCES) $(DATA_DEP) $(wildcard $(DATASET)/sequence.yaml) | $(STAMP)
	@mkdir -p $(@D)
	@echo "== $*"
	@# the notebook's folder holds only what this run writes: no table or figure of an older version survives;
	@# the old executed notebook goes too, so that a run that fails is run again by the next make
	@rm -rf $@ $(@D)/.tmp-$*.ipynb $(@D)/.tmp-$*.yaml $(@D)/.tmp-$*.args $(RESULTS)/$*
	$(BIN)/python -m greenloop notebook-params $< $(DATASET) $(RESULTS) --out $(@D)/.tmp-$*.ipynb \
	    --params-out $(@D)/.tmp-$*.yaml --args-out $(@D)/.tmp-$*.args -- $(DATASET_PARAMS:%=-f %) $(PARAMS)
	@test -f $(@D)/.tmp-$*.ipynb || xargs -0 -a $(@D)/.tmp-$*.args $(BIN)/papermill -k $(KERNEL) \
	    --execution-timeout $(TIMEOUT) --log-output --progress-bar -f $(@D)/.tmp-$*.yaml $< $(@D)/.tmp-$*.ipynb
	@mv $(@D)/.tmp-$*.ipynb $@
	@rm -f $(@D)/.tmp-$*.yaml $(@D)/.tmp-$*.args

# results/tables.md also holds results/coverage.md, which every dataset's run may rewrite
$(RESULTS)/tables.md: $(EXECUTED) $(wildcard $(RESULTS)/coverage.md)
	$(BIN)/python -m greenloop tables $(RESULTS)

# RESULTS given on the command line wins (make quick RESULTS=results/mine); else results/quick/
QUICK_RESULTS := $(if $(filter command line,$(origin RESULTS)),$(RESULTS),results/quick)
quick: ## the same notebooks with few epochs and seeds into results/quick/ (or RESULTS=...; minutes)
	$(MAKE) all RESULTS=$(QUICK_RESULTS) PARAMS="-f params/quick.yaml $(PARAMS)" CROSS=

# `make sweep`: greenloop.study.sweep over Dask (python -m greenloop sweep --help). Each --grid is one
# word of SWEEP_GRID; points whose point.json says ok are skipped, so an interrupted sweep resumes.
sweep: $(DATA_DEP) | $(STAMP) ## Dask sweep of SWEEP_GRID over SWEEP_NOTEBOOK (default L = 40..80 in 01) -> results/sweep/
	$(BIN)/python -m greenloop sweep $(SWEEP_NOTEBOOK) $(foreach g,$(SWEEP_GRID),--grid '$(g)') \
	    --dataset $(DATASET) --out $(SWEEP_OUT) --scheduler $(SCHEDULER) $(if $(WORKERS),--workers $(WORKERS)) \
	    $(if $(SWEEP_METRIC),--metric '$(SWEEP_METRIC)') --timeout $(TIMEOUT) $(PARAMS)

bench: | $(STAMP) ## speed benchmark: streaming detector and training vs plain Keras -> results/bench/
	$(BIN)/python -m greenloop bench --out $(RESULTS)/bench --dataset $(DATASET)
	$(BIN)/python -m greenloop tables $(RESULTS)

# SCALE_NOTE: a sentence for scale.md's header, e.g. what else shared the cores during the run
SCALE_NOTE ?=
bench-scale: | $(STAMP) ## retrieval indexes and the named default's whole decision (candidate mode vs the exact scan) at 10^4..10^6 stored frames (augmented Nordland) -> results/bench/scale.md (about 25 min on 2 cores)
	test -d "$(NORDLAND_SRC)" || { echo "bench-scale needs Nordland's frames: set NORDLAND_SRC=path (summer/, winter/), e.g. from git clone --depth 1 $(NORDLAND_URL)"; exit 1; }
	OMP_NUM_THREADS=1 $(BIN)/python -m greenloop bench-scale --src $(NORDLAND_SRC) --out $(RESULTS)/bench --note "$(SCALE_NOTE)"

bench-stream: | $(STAMP) ## a 100,000-frame augmented Nordland recording streamed through `detect --index hnsw`, stopped and resumed -> results/bench/stream100k.json, scale.md's section (about 10 min, 0.7 GB in /tmp)
	test -d "$(NORDLAND_SRC)" || { echo "bench-stream needs Nordland's frames: set NORDLAND_SRC=path (summer/, winter/), e.g. from git clone --depth 1 $(NORDLAND_URL)"; exit 1; }
	$(BIN)/python -m greenloop bench-stream --src $(NORDLAND_SRC) --out $(RESULTS)/bench --note "$(SCALE_NOTE)"

# Optional, for the cross-checks against the torch originals only (GhostNet vs timm, the Lite0 port
# and checkpoint reader vs efficientnet_lite_pytorch and torch.load): a CPU torch wheel where the
# machine has one (never the multi-GB CUDA build from PyPI), timm without its torchvision dependency,
# and the Lite0 model code without its (unpinned) torch requirement.
TORCH_WHEEL := $(firstword $(wildcard /opt/wheels/torch-2.13.0*cpu*.whl))
# Debian's headless Chromium and its driver, for the book's browser test (tests/test_book.py), installed
# where apt-get can (as root); elsewhere that test says it is skipped and why.
browser:
	@command -v chromium >/dev/null && command -v chromedriver >/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing Debian's chromium and chromium-driver for the book's browser test"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
	      chromium chromium-driver >/dev/null; \
	  else echo "no chromium/chromedriver and no root apt-get: tests/test_book.py skips its browser check"; fi; }

book: | $(STAMP) ## a static site of every executed notebook of every dataset, the verdict table as its landing page -> build/book/ (nothing re-executed)
	$(BIN)/python -m greenloop book --out build/book $(DATASET_RESULTS)
	@echo "open build/book/index.html"

$(VENV)/.timm: $(STAMP)
ifneq ($(TORCH_WHEEL),)
	$(BIN)/python -m pip install -q $(TORCH_WHEEL)
	$(BIN)/python -m pip install -q --no-deps timm==1.0.31 efficientnet-lite-pytorch==0.1.0
else
	@echo "no local CPU torch wheel: the checks against timm and torch will be skipped"
endif
	@touch $@

# one thread per numerical library in each pytest-xdist worker and the notebook kernels it starts:
# two workers on two cores, no thread pools (OpenMP / oneDNN, OpenBLAS, TensorFlow's) spinning on the
# other worker's core (a whole run took about 12 % less wall time and 15 % less CPU time than without)
TEST_THREADS := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 TF_NUM_INTRAOP_THREADS=1 TF_NUM_INTEROP_THREADS=1

test: $(VENV)/.timm browser | $(STAMP) ## run the test suite (unit tests and every notebook on tiny parameters)
	$(TEST_THREADS) $(BIN)/python -m pytest -q -n auto --dist worksteal tests

clean-results: ## remove executed notebooks and tables (keeps the model cache)
	rm -rf $(EXECUTED) $(RESULTS)/tables.md
