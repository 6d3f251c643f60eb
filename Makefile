# Everything runs inside .venv, created on first use by scripts/setup.sh.
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: setup demo test test-slow test-ros-peers test-all lint docs bench figures clean

$(BIN)/semattnet: pyproject.toml scripts/setup.sh
	VENV=$(VENV) bash scripts/setup.sh
	@touch $@

setup: $(BIN)/semattnet

demo: setup
	$(BIN)/semattnet demo

# The default suite on two workers (pytest-xdist), the tests handed out one by one (--dist loadgroup: a test marked
# xdist_group would keep its group on one worker). --dist loadfile took 18 min 49 s here against 9 min this way:
# a few long files held one worker while the other idled (user time 13 min of 19).
WORKERS ?= 2

test: setup
	$(BIN)/python -m pytest -n $(WORKERS) --dist loadgroup

# What the default suite leaves out as slow (minutes each); CI runs it after the default suite.
test-slow: setup
	$(BIN)/python -m pytest -m "slow and not ros_peers" -n $(WORKERS) --dist loadgroup

# The ROS 2 node against Fast DDS and Cyclone DDS C peers (their Debian packages: scripts/setup-ros-peers.sh).
# The ROS nodes against implementations that are not ours (Fast DDS, Cyclone DDS C, Debian's roscore/rostopic).
test-ros-peers: setup
	bash scripts/setup-ros-peers.sh
	bash scripts/setup-ros1-peers.sh
	SEMATTNET_REQUIRE_ROS_PEERS=1 SEMATTNET_REQUIRE_ROS1=1 $(BIN)/python -m pytest -m ros_peers tests/robotics/peers tests/robotics/ros

test-all: setup
	$(BIN)/python -m pytest -m "slow or not slow" -n $(WORKERS) --dist loadgroup

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
