# PuzzleBot stack: stable entry points (README.md documents each target).
# Every target installs what it needs first (scripts/setup.sh is idempotent).
SHELL := /bin/bash
ENV := scripts/env.sh
ARGS ?=

.PHONY: all setup build sim test test-unit test-ros bench experiments clean

all: build

setup:
	@scripts/setup.sh deps

build: setup
	@scripts/setup.sh build

## make sim [ARGS="scenario:=goto3 rviz:=true"]: run the default scenario headless and print its summary
sim: build
	@scripts/run_sim.sh $(ARGS)

## make test: pytest on the ROS-free cores, then every rostest; non-zero on any failure
test: build
	@scripts/run_tests.sh

test-unit: build
	@scripts/run_tests.sh unit

test-ros: build
	@scripts/run_tests.sh ros

## make bench: MPC step time for N = 2..256 at Hm = 10 (and Hm = 3, 5 up to 32 robots; Hc = 3), IPOPT at N = 8;
## tables on screen and in docs/mpc.md, JSON in build/bench and docs
bench: build
	@$(ENV) rosrun puzzlebot_mpc bench --grid --out build/bench/mpc_bench.json --out docs/mpc_bench.json --page docs/mpc.md

## make experiments [ARGS="--trials 20"]: the paper's experiments (coupling vs offset, decoupling, MPC time,
## force profile, chain down the step); resumable; rewrites the figures and tables of docs/results.md
experiments: bench
	@$(ENV) rosrun puzzlebot_experiments experiments $(ARGS)

clean:
	rm -rf build devel install
