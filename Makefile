# Everything runs inside .venv, created on first use by scripts/setup.sh.
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: setup demo test test-ros-peers test-all lint docs bench figures clean

$(BIN)/semattnet: pyproject.toml scripts/setup.sh
	VENV=$(VENV) bash scripts/setup.sh
	@touch $@

setup: $(BIN)/semattnet

demo: setup
	$(BIN)/semattnet demo

test: setup
	$(BIN)/python -m pytest

# The ROS 2 node against Fast DDS and Cyclone DDS C peers (their Debian packages: scripts/setup-ros-peers.sh).
test-ros-peers: setup
	bash scripts/setup-ros-peers.sh
	SEMATTNET_REQUIRE_ROS_PEERS=1 $(BIN)/python -m pytest -m ros_peers tests/robotics/peers

test-all: setup
	$(BIN)/python -m pytest -m "slow or not slow"

lint: setup
	$(BIN)/ruff check src tests benchmarks hubconf.py
	$(BIN)/ruff format --check src tests benchmarks hubconf.py
	$(BIN)/mypy

docs: setup
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict --site-dir site

bench: setup
	$(BIN)/semattnet bench

# The README's and docs home's figure, from the trained weights shipped in the package (about 10 minutes).
figures: setup
	$(BIN)/python scripts/docs-figures.py --out docs

clean:
	rm -rf build dist site .pytest_cache .ruff_cache semattnet-demo
