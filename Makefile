# Two commands do all set-up on a fresh machine with Python 3.11:
#   make demo   - the main job
#   make test   - the test suite
# Both bootstrap .venv/ (pinned versions in requirements/pins.txt) and re-run fast when nothing
# changed. With a system ROS 2 (rclpy importable by $(PYTHON)) the venv sees the system packages
# and no ROS wheels are installed, so the system install is never shadowed.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.bootstrapped
PLOTS := $(VENV)/.plots
RECORD := $(VENV)/.record
CAMPAIGNS := $(VENV)/.campaigns
ANALYSIS := $(VENV)/.analysis
DOCS := $(VENV)/.docs
INTERFACES := $(VENV)/.interfaces
PIP := $(PY) -m pip install --disable-pip-version-check -q -c requirements/pins.txt

# Every rclpy process: discovery on loopback only, a per-run domain, logs in a temp dir.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
# (a domain id from 1-101: the ROS 2 documentation's safe range on Linux; higher ids map to
# ports inside the ephemeral range; 0, the default, is left to other users of the machine)
export ROS_DOMAIN_ID ?= $(shell echo $$(( $$$$ % 101 + 1 )))
export ROS_LOG_DIR ?= $(shell mktemp -d /tmp/daddy-roslog.XXXXXX)
export ROS_PYTHON_CHECK_FIELDS := 1

.PHONY: interfaces demo test test-slow bench monte-carlo reliability robustness venv clean docs docs-screenshot

venv: $(STAMP)

interfaces: $(INTERFACES)

$(STAMP): requirements/pins.txt requirements/core.txt requirements/ros.txt setup.py setup.cfg package.xml
	@set -e; \
	if $(PYTHON) -c "import rclpy" >/dev/null 2>&1; then \
	  echo "bootstrap: system rclpy found, venv with system site-packages"; \
	  [ -x $(PY) ] || $(PYTHON) -m venv --system-site-packages $(VENV); \
	  $(PIP) -r requirements/core.txt; \
	else \
	  echo "bootstrap: no system rclpy, installing the pinned ROS 2 Jazzy wheels"; \
	  [ -x $(PY) ] || $(PYTHON) -m venv $(VENV); \
	  $(PIP) -r requirements/core.txt -r requirements/ros.txt; \
	fi; \
	$(PY) -m pip install --disable-pip-version-check -q --no-deps -e .; \
	touch $@

# The node's own interfaces (daddy_interfaces: the Replan action; bond, where ROS 2 has none:
# the lifecycle manager's heartbeat), generated with the rosidl tools: a system ROS 2's
# (sourced), or the registry's wheels (requirements/interfaces.txt). Without them the node runs
# without its action and bond (it says so) and their tests skip.
$(INTERFACES): $(STAMP) requirements/interfaces.txt interfaces/build.py $(wildcard interfaces/*/* interfaces/*/*/*)
	@([ -n "$$AMENT_PREFIX_PATH" ] || $(PIP) -r requirements/interfaces.txt) && \
	  $(PY) interfaces/build.py && touch $@ || \
	  echo "interfaces: daddy_interfaces could not be built; the node will offer no Replan action"

# The plots extra (matplotlib): the demo's figure; the tests check it. Without it (e.g. an offline
# machine) everything runs and the demo says it skipped its plot.
$(PLOTS): $(STAMP) requirements/plots.txt
	@$(PIP) -r requirements/plots.txt && touch $@ || \
	  echo "plots: matplotlib could not be installed; the demo will skip its plot"

# The record extra (mcap): gnc_demo --record FILE.mcap; the tests read a recording back.
$(RECORD): $(STAMP) requirements/record.txt
	@$(PIP) -r requirements/record.txt && touch $@ || \
	  echo "record: mcap could not be installed; gnc_demo --record will say so"

# The campaigns extra (Dask, tqdm): daddy_campaign run --executor dask and its progress bar; the
# tests run a loopback LocalCluster.
$(CAMPAIGNS): $(STAMP) requirements/campaigns.txt
	@$(PIP) -r requirements/campaigns.txt && touch $@ || \
	  echo "campaigns: dask could not be installed; --executor dask will say so"

# The analysis extra (pyarrow, pandas, oem): a campaign's results as a Parquet table, read with
# pandas, and exported OEMs read back by the oem package, in the tests.
$(ANALYSIS): $(STAMP) requirements/analysis.txt
	@$(PIP) -r requirements/analysis.txt && touch $@ || \
	  echo "analysis: pyarrow could not be installed; campaigns will write no Parquet table"

# The docs extra (MkDocs, Material, mkdocstrings): the documentation site; the tests build it.
$(DOCS): $(STAMP) requirements/docs.txt
	@$(PIP) -r requirements/docs.txt && touch $@ || \
	  echo "docs: mkdocs could not be installed; make docs cannot build the site"

DEMO_CASE ?= halo_l2_l1
demo: $(STAMP) $(PLOTS) $(INTERFACES)
	$(VENV)/bin/gnc_demo --case $(DEMO_CASE)

test: $(STAMP) $(PLOTS) $(RECORD) $(CAMPAIGNS) $(ANALYSIS) $(DOCS) $(INTERFACES)
	$(PY) -m pytest -q test

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow test --run-slow

# a dispersion campaign of the demo's loop: results file, summary and plot in out/
# (EXECUTOR=dask: on a loopback Dask LocalCluster; JOBS: workers)
MC_OUT := out/monte-carlo-$(DEMO_CASE).jsonl
monte-carlo: $(STAMP) $(PLOTS) $(ANALYSIS) $(if $(filter dask,$(EXECUTOR)),$(CAMPAIGNS))
	$(VENV)/bin/daddy_campaign run --case $(DEMO_CASE) --runs $(or $(RUNS),100) \
	  --out $(MC_OUT) --overwrite --executor $(or $(EXECUTOR),local) \
	  $(if $(JOBS),--jobs $(JOBS)) --plot $(MC_OUT:.jsonl=.png)

reliability: $(STAMP)
	cd test && ../$(PY) -m reliability $(if $(QUICK),--quick)

# random initial guesses per case (bench/bench_robustness.py): GUESSES per case, CAP s per solve;
# PEER=1: the same guesses also to the CasADi + IPOPT transcription (casadi: requirements/optional.txt)
robustness: $(STAMP)
	cd bench && for c in double_integrator earth_mars dro_dro; do \
	  ../$(PY) bench_robustness.py $$c --guesses $(or $(GUESSES),100) --cap $(or $(CAP),60) $(if $(PEER),--peer) || exit 1; done; \
	for c in halo_l2_l1 lyapunov_l1_l2; do \
	  ../$(PY) bench_robustness.py $$c --guesses $(or $(CR3BP_GUESSES),30) --cap $(or $(CAP),60) $(if $(PEER),--peer) || exit 1; done

bench: $(STAMP)
	cd bench && ../$(PY) bench_da.py && ../$(PY) bench_solver.py && ../$(PY) bench_replan.py

# the documentation site in out/site (warnings are errors); docs-screenshot: the front page and
# an API page in headless Chromium (Debian: apt-get install chromium), PNGs in out/
docs: $(DOCS)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict
	@echo "site: out/site/index.html"

docs-screenshot: docs
	$(PY) docs/screenshot.py

clean:
	rm -rf $(VENV) build install log *.egg-info
