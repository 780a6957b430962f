PY ?= python3.11
EXTRAS ?= test
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench lint fuzz clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[$(EXTRAS)]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/gatmo demo --out demo-out

test: $(STAMP)
	$(BIN)/ruff check gatmo tests benchmarks
	$(BIN)/python -m pytest -n 2 tests

bench: $(STAMP)
	$(BIN)/pip install -q -e '.[bench]'
	$(BIN)/python -m benchmarks

FUZZ_SECONDS ?= 60
fuzz: $(STAMP)
	$(BIN)/pip install -q -e '.[fuzz]'
	for t in carmen wean tum map amcl objects rosbag sniff; do \
		$(BIN)/python fuzz/fuzz_readers.py $$t -max_total_time=$(FUZZ_SECONDS) || exit 1; \
	done

lint: $(STAMP)
	$(BIN)/ruff check gatmo tests benchmarks

clean:
	rm -rf $(VENV) demo-out .pytest_cache
