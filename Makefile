# Newcomer entry points. `make run`: install deps, build, start the daemon on a demo mesh and the
# studio (a browser client). `make test`: install deps, build, run the test suite.
# `make install PREFIX=DIR`: programs and the Python package into DIR. `make fuzz`: the clang fuzz
# targets (fuzz/) in $(BUILD_DIR)/fuzz.
BUILD_DIR ?= build
FUZZ_DIR ?= $(BUILD_DIR)/fuzz
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc)

.PHONY: all deps configure build test test-large-meshes fuzz install run format clean

all: build

deps:
	./.ci/install-deps

$(BUILD_DIR)/build.ninja:
	cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)

configure: deps $(BUILD_DIR)/build.ninja

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

# The suite, then a few seconds of every fuzz target (fuzz/run.sh --smoke). It needs no mesh
# files: its meshes are made in code (tests/testing/test_meshes.h).
test: build fuzz
	cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS) --timeout 900 -LE large-mesh
	cd $(FUZZ_DIR) && ctest --output-on-failure

# The large-mesh checks: the real meshes of MESH_DIR (up to 1.8M faces), not part of `make test`.
MESH_DIR ?= $(abspath ../shared/meshes)
test-large-meshes: configure
	cmake -S . -B $(BUILD_DIR) -DFIELDSPACE_LARGE_MESH_CHECKS=ON -DFIELDSPACE_MESH_DIR=$(MESH_DIR)
	cmake --build $(BUILD_DIR) -j $(JOBS)
	cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS) --timeout 900 -L large-mesh

# Fuzz targets with clang, ASan and UBSan (fuzz/CMakeLists.txt); ccache when installed.
$(FUZZ_DIR)/build.ninja:
	cmake -S fuzz -B $(FUZZ_DIR) -G Ninja -DCMAKE_CXX_COMPILER=clang++ \
	    $(if $(shell command -v ccache),-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)

fuzz: deps $(FUZZ_DIR)/build.ninja
	cmake --build $(FUZZ_DIR) -j $(JOBS)

# Installs fieldspaced, fieldspace and fieldspace-bench into $(PREFIX)/bin and the Python package
# into $(PREFIX)/lib/python3/dist-packages/fieldspace (put $(PREFIX)/lib/python3/dist-packages on
# PYTHONPATH).
PREFIX ?= /usr/local
install: build
	cmake --install $(BUILD_DIR) --prefix $(PREFIX)

# Starts the daemon on loopback with the bundled demo mesh (a ~49k-face torus-knot tube made by
# core/mesh/shapes.h), stored under STORE; its default vector basis builds in the background.
# LoadMesh reads below DATA_ROOT (the shared meshes next to the checkout) when that folder exists.
# With Node.js, the studio's gateway (client/web, docs/studio.md) serves the studio on STUDIO and
# prints "studio: http://HOST:PORT/"; both stop together (the daemon in its own session, so that
# Ctrl-C reaches it once, through the trap, and it drains).
STORE ?= $(HOME)/.local/share/fieldspace
LISTEN ?= 127.0.0.1:50051
STUDIO ?= 127.0.0.1:8750
DATA_ROOT ?= $(abspath ../shared/meshes)
DAEMON_RUN = $(BUILD_DIR)/bin/fieldspaced --listen $(LISTEN) --store $(STORE) --demo \
    $(if $(wildcard $(DATA_ROOT)),--data-root $(DATA_ROOT))
run: build
	mkdir -p $(STORE)
ifneq ($(shell command -v node),)
	@setsid $(DAEMON_RUN) & daemon=$$!; \
	trap 'kill $$daemon 2>/dev/null; wait $$daemon; trap - EXIT; exit' EXIT INT TERM; \
	node client/web/gateway/main.mjs --listen $(STUDIO) --daemon $(LISTEN)
else
	@echo "node not found: starting the daemon without the studio"
	$(DAEMON_RUN)
endif

format:
	clang-format -i $$(git ls-files '*.h' '*.cc')

clean:
	rm -rf $(BUILD_DIR)
