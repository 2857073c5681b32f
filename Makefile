# Newcomer entry points. `make run`: install deps, build, start the daemon on a demo mesh.
# `make test`: install deps, build, run the test suite.
BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc)

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

# Starts the daemon on loopback with the bundled demo mesh (a ~49k-face torus-knot tube made by
# core/mesh/shapes.h), stored under STORE; its default vector basis builds in the background.
STORE ?= $(HOME)/.local/share/fieldspace
LISTEN ?= 127.0.0.1:50051
run: build
	mkdir -p $(STORE)
	$(BUILD_DIR)/bin/fieldspaced --listen $(LISTEN) --store $(STORE) --demo

format:
	clang-format -i $$(git ls-files '*.h' '*.cc')

clean:
	rm -rf $(BUILD_DIR)
