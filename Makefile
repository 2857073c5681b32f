# Newcomer entry points. `make run`: install deps, build, start the daemon on a demo mesh.
# `make test`: install deps, build, run the test suite.
BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc)
LISTEN ?= 127.0.0.1:50051
STORE ?= $(HOME)/.local/share/fieldspace

.PHONY: all deps configure build test run format clean

all: build

deps:
	./.ci/install-deps

$(BUILD_DIR)/build.ninja:
	cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)

configure: deps $(BUILD_DIR)/build.ninja

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS) --timeout 900

run: build
	$(BUILD_DIR)/bin/fieldspaced --listen $(LISTEN) --store $(STORE) --demo

format:
	clang-format -i $$(git ls-files '*.h' '*.cc')

clean:
	rm -rf $(BUILD_DIR)
