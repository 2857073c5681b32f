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

# Until the daemon lands in the build, `make run` generates the demo mesh (a torus-knot tube made
# by core/mesh/shapes.h), reports its topology and the lowest Hodge-Laplacian eigenvalues (two
# near zero: the harmonic fields of a genus-1 surface).
DEMO_MESH = $(BUILD_DIR)/demo/torus_knot.ply
run: build
	mkdir -p $(BUILD_DIR)/demo
	$(BUILD_DIR)/bin/fieldspace-bench shape torus-knot --out $(DEMO_MESH)
	$(BUILD_DIR)/bin/fieldspace-bench mesh $(DEMO_MESH)
	$(BUILD_DIR)/bin/fieldspace-bench spectrum $(DEMO_MESH) --field vector --count 6

format:
	clang-format -i $$(git ls-files '*.h' '*.cc')

clean:
	rm -rf $(BUILD_DIR)
