# Two commands do all set-up on a fresh Debian/Ubuntu machine with Python 3.11 and make:
#   make demo   - runs the main job on the bundled real data
#   make test   - runs the test suite
# Both create/update the virtual environment .venv from environment.txt on first use.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
OUT ?= outputs

.PHONY: demo test bench notebooks docs learning system-deps clean

$(STAMP): environment.txt pyproject.toml
	@$(MAKE) --no-print-directory system-deps
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@echo "installing the Python packages into $(VENV) (about 1.5 minutes, 2.9 GB) ..."
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r environment.txt
	$(BIN)/python -m pip install --quiet --no-deps -e .
	@# dash (open3d's dependency) ships a JupyterLab source extension that makes JupyterLab ask for a
	@# build on every start; nothing here uses dash in JupyterLab.
	@rm -f $(VENV)/share/jupyter/lab/extensions/dash-jupyterlab.tgz
	@touch $(STAMP)

# open3d needs the system library libusb-1.0: install it when missing (as root), else say how.
system-deps:
	@if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then \
	  if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then \
	    echo "installing libusb-1.0-0 (needed by open3d) with apt-get"; \
	    (apt-get install -y -q libusb-1.0-0 >/dev/null 2>&1 || \
	     (apt-get update -q >/dev/null && apt-get install -y -q libusb-1.0-0 >/dev/null)) || \
	     { echo "apt-get install libusb-1.0-0 failed"; exit 1; }; \
	  else \
	    echo "open3d needs the system library libusb-1.0. Run:  sudo apt-get install -y libusb-1.0-0"; \
	    exit 1; \
	  fi; \
	fi
	@if [ ! -x /usr/bin/chromium ]; then \
	  if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then \
	    echo "installing chromium (the browser of tests/test_site.py) with apt-get"; \
	    (DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null 2>&1 || \
	     (apt-get update -q >/dev/null 2>&1 && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium >/dev/null 2>&1)) || \
	     echo "apt-get install chromium failed: tests/test_site.py will be skipped (set-up goes on)"; \
	  else \
	    echo "no /usr/bin/chromium: tests/test_site.py will be skipped; for it:  sudo apt-get install -y chromium"; \
	  fi; \
	fi

demo: $(STAMP)
	$(BIN)/tpvp demo --output $(OUT)/demo

# Bytecode is cached even where the environment says not to (PYTHONDONTWRITEBYTECODE): the two workers,
# the notebooks' kernels and the commands the tests start import the same modules hundreds of times.
test: $(STAMP)
	env -u PYTHONDONTWRITEBYTECODE $(BIN)/python -m pytest -n 2 tests

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -r benchmarks/requirements.txt
	$(BIN)/python benchmarks/sensor_bench.py
	$(BIN)/python benchmarks/oracle_bench.py
	$(BIN)/python benchmarks/plant_realism.py
	$(BIN)/python benchmarks/planning_bench.py
	$(BIN)/python benchmarks/registration_bench.py
	$(BIN)/python benchmarks/row_realism.py
	$(BIN)/python benchmarks/row_case_bench.py
	$(BIN)/python benchmarks/row_registration_bench.py
	$(BIN)/python benchmarks/blockwise_nbv_bench.py
	$(BIN)/python benchmarks/learned_inference_bench.py
	$(BIN)/python benchmarks/import_graph.py
	$(BIN)/python benchmarks/first_run.py

# Every notebook in full mode (the paper's protocol): executed .ipynb + HTML + the exported figures and
# tables under $(OUT)/notebooks, published whole; make test runs them in reader's mode.
notebooks: $(STAMP)
	$(BIN)/python -m tools.notebooks --full --output $(OUT)/notebooks

# The documentation site (README, docs/, the executed notebooks; offline) into $(OUT)/site. Notebooks
# that make notebooks published stay; the others are published in reader's mode first, copied from the
# executions make test keeps (outputs/cache/notebooks) or executed when the notebook or library changed.
docs: $(STAMP)
	@start=$$(date +%s); \
	$(BIN)/python -m tools.notebooks --keep-full --output $(OUT)/notebooks || exit $$?; \
	$(BIN)/python -m tools.site --notebooks $(OUT)/notebooks --output $(OUT)/site || exit $$?; \
	echo "make docs: $$(( $$(date +%s) - start )) s in all; open $(OUT)/site/index.html"

# Regenerate the learned planners' dataset and retrain both networks from scratch (~55 min on 2 cores);
# the shipped weights stay in tpvp/data/learning unless OUT points there.
learning: $(STAMP)
	$(BIN)/python -m tpvp.learning all --out $(OUT)/learning

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
