# PuzzleBot stack: stable entry points (README.md documents each target).
# Every target installs what it needs first (scripts/setup.sh is idempotent).
SHELL := /bin/bash
ENV := scripts/env.sh
ARGS ?=

.PHONY: all setup build sim test test-unit test-ros clean

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

clean:
	rm -rf build devel install
