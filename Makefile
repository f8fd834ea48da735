# isoserve: build, test and benchmark. `make` builds build/isoserve; `make test` installs
# what is missing (scripts/setup.sh), builds normal and sanitizer variants and runs every
# test, ending with an "N passed, N failed" line.

CC       ?= gcc
CXX      ?= g++
WARN     := -Wall -Wextra -Werror -Wshadow -Wstrict-prototypes -Wmissing-prototypes \
            -Wpointer-arith -Wcast-qual -Wvla
OPT      ?= -O2 -g
CFLAGS   := $(OPT) -std=c11 -D_DEFAULT_SOURCE -D_POSIX_C_SOURCE=200809L $(WARN) -pthread -Icore -Iproto -I/usr/include/nifti
# GDCM (DICOM, core/io/dicom_gdcm.cc) ships CMake files but no pkg-config file on Debian 12.
GDCM_INC := /usr/include/gdcm-3.0
GDCM_LIBS := -lgdcmMSFF -lgdcmDSED -lgdcmCommon
CXXFLAGS := $(OPT) -std=c++17 -Wall -Wextra -Werror -Icore -Iproto $(shell pkg-config --cflags draco 2>/dev/null) \
            -isystem $(GDCM_INC)
LIBS     := $(shell pkg-config --libs libmicrohttpd jansson libcurl 2>/dev/null) \
            -lnifti2 -ldraco -lmeshoptimizer $(GDCM_LIBS) -lz -lm -pthread -lstdc++

BUILD    ?= build
SAN_BUILD := build/san
SAN_FLAGS := -O1 -g -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all

CORE_SRC   := $(sort $(wildcard core/*/*.c))
CORE_CXX   := $(sort $(wildcard core/*/*.cc))
PROTO_SRC  := $(sort $(wildcard proto/*.c))
PROTO_CXX  := $(sort $(wildcard proto/*.cc))
SERVER_SRC := $(sort $(wildcard server/*.c))
TEST_SRC   := $(sort $(wildcard tests/unit/test_*.c))
TEST_SUPPORT := $(sort $(wildcard tests/support/*.c))
# The failing allocator replaces malloc: only the allocation-failure sweeps link it.
ALLOC_FAIL_OBJ = $(BUILD)/tests/support/alloc/alloc_fail.o

LIB_OBJ    = $(CORE_SRC:%.c=$(BUILD)/%.o) $(CORE_CXX:%.cc=$(BUILD)/%.o) $(PROTO_SRC:%.c=$(BUILD)/%.o) $(PROTO_CXX:%.cc=$(BUILD)/%.o)
SERVER_OBJ = $(SERVER_SRC:%.c=$(BUILD)/%.o)
SUPPORT_OBJ = $(TEST_SUPPORT:%.c=$(BUILD)/%.o)
TEST_BIN   = $(TEST_SRC:tests/unit/%.c=$(BUILD)/tests/%)

# Objects of the test support must survive between runs (they are not final targets).
.SECONDARY:

.PHONY: all setup test test-asan unit-tests bench run clean sanitize node-deps web fuzz fuzz-build fuzz-lib image test-image
all: $(BUILD)/isoserve web

$(BUILD)/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -MMD -MP -c $< -o $@

$(BUILD)/%.o: %.cc
	@mkdir -p $(dir $@)
	$(CXX) $(CXXFLAGS) -MMD -MP -c $< -o $@

$(BUILD)/libisoserve.a: $(LIB_OBJ)
	@rm -f $@
	ar rcs $@ $^

$(BUILD)/isoserve: $(SERVER_OBJ) $(BUILD)/libisoserve.a
	$(CC) $(CFLAGS) $^ $(LIBS) -o $@

# TEST_EXTRA: what a unit test links beyond the library and the test support, named with
# its prerequisites below.
$(BUILD)/tests/%: tests/unit/%.c $(SUPPORT_OBJ) $(BUILD)/libisoserve.a
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -Itests/support -Itests/support/alloc -Iserver -MMD -MP $< $(SUPPORT_OBJ) $(TEST_EXTRA) $(BUILD)/libisoserve.a $(LIBS) -o $@

# The allocation-failure sweeps link the failing allocator; the HTTP layer's sweep and the
# collection's eviction test (white-box) the server's objects, all but main.
SERVER_TEST_OBJ = $(filter-out $(BUILD)/server/main.o,$(SERVER_OBJ))
$(BUILD)/tests/test_oom: TEST_EXTRA = $(ALLOC_FAIL_OBJ)
$(BUILD)/tests/test_oom: $(ALLOC_FAIL_OBJ)
$(BUILD)/tests/test_http_oom: TEST_EXTRA = $(ALLOC_FAIL_OBJ) $(SERVER_TEST_OBJ)
$(BUILD)/tests/test_http_oom: $(ALLOC_FAIL_OBJ) $(SERVER_TEST_OBJ)
$(BUILD)/tests/test_collection: TEST_EXTRA = $(SERVER_TEST_OBJ)
$(BUILD)/tests/test_collection: $(SERVER_TEST_OBJ)

# test_march again over the kernel built without SSE2 (as on a machine without it): the
# row-by-row paths then classify every brick, full ones included.
$(BUILD)/scalar/core/extract/march.o: core/extract/march.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -U__SSE2__ -MMD -MP -c $< -o $@

$(BUILD)/tests/test_march_scalar: tests/unit/test_march.c $(SUPPORT_OBJ) $(BUILD)/scalar/core/extract/march.o $(BUILD)/libisoserve.a
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -Itests/support $< $(SUPPORT_OBJ) $(BUILD)/scalar/core/extract/march.o $(BUILD)/libisoserve.a $(LIBS) -o $@

unit-tests: $(TEST_BIN) $(BUILD)/tests/test_march_scalar

setup:
	bash scripts/setup.sh

# The sanitizer variant is the same tree built into build/san with ASan and UBSan.
sanitize:
	$(MAKE) BUILD=$(SAN_BUILD) OPT="$(SAN_FLAGS)" all unit-tests

# libFuzzer targets (tests/fuzz/fuzz_*.c) over the library built by clang into build/fuzz
# (UBSan without vptr: its C++ runtime would need a clang++ link for the Draco shim alone)
# with ASan and UBSan: the query parser, the NRRD, NIfTI and MetaImage loaders (one source,
# three suffixes), the hierarchy-file reader and the Draco decoder shim.
FUZZ_BUILD  := build/fuzz
FUZZ_FLAGS  := -O1 -g -fsanitize=address,undefined -fno-sanitize=vptr -fno-sanitize-recover=all -fno-omit-frame-pointer
FUZZ_TARGETS := query nrrd nifti metaimage tree draco
FUZZ_BIN    := $(FUZZ_TARGETS:%=$(FUZZ_BUILD)/fuzz_%)
FUZZ_SECONDS ?= 60

# The library's objects get the fuzzer's coverage instrumentation (fuzzer-no-link).
fuzz-lib:
	$(MAKE) BUILD=$(FUZZ_BUILD) CC=clang CXX=clang++ OPT="$(FUZZ_FLAGS) -fsanitize=fuzzer-no-link" $(FUZZ_BUILD)/libisoserve.a

FUZZ_LINK = clang $(FUZZ_FLAGS) -fsanitize=fuzzer -std=c11 -D_DEFAULT_SOURCE $(WARN) -Icore -Iproto
$(FUZZ_BUILD)/fuzz_query $(FUZZ_BUILD)/fuzz_tree $(FUZZ_BUILD)/fuzz_draco: $(FUZZ_BUILD)/fuzz_%: tests/fuzz/fuzz_%.c fuzz-lib
	$(FUZZ_LINK) $< $(FUZZ_BUILD)/libisoserve.a $(LIBS) -o $@
$(FUZZ_BUILD)/fuzz_nrrd: SUFFIX := .nrrd
$(FUZZ_BUILD)/fuzz_nifti: SUFFIX := .nii
$(FUZZ_BUILD)/fuzz_metaimage: SUFFIX := .mha
$(FUZZ_BUILD)/fuzz_nrrd $(FUZZ_BUILD)/fuzz_nifti $(FUZZ_BUILD)/fuzz_metaimage: tests/fuzz/fuzz_load.c fuzz-lib
	$(FUZZ_LINK) -DFUZZ_SUFFIX='"$(SUFFIX)"' $< $(FUZZ_BUILD)/libisoserve.a $(LIBS) -o $@

fuzz-build: $(FUZZ_BIN)

# Each target for FUZZ_SECONDS (default 60) from seeds made at run time; crashes are
# written to build/fuzz/crashes/ and fail the run (keep small ones in tests/fuzz/regressions/).
fuzz: setup fuzz-build
	bash tests/fuzz/run.sh $(FUZZ_SECONDS)

# npm packages (three.js; draco3d and playwright-core for the tests), pinned by
# web/package-lock.json: installed with npm ci
# when missing or older than the lockfile. No network, no packages: the build says so.
web/node_modules/.package-lock.json: web/package-lock.json web/package.json
	cd web && npm ci --no-audit --no-fund || { echo "npm ci failed in web/ (no network?)"; exit 1; }

node-deps: web/node_modules/.package-lock.json

# The web client: web/src plus the npm files it imports, copied into $(BUILD)/web, which
# the server serves at / (nothing is loaded from another host). three.module.js imports
# ./three.core.js; DRACOLoader's decoder (js + wasm) runs in a worker from libs/draco;
# GLTFLoader (with the two utils it imports) and MeshoptDecoder read glb-meshopt.
WEB_SRC := $(sort $(wildcard web/src/*))
THREE   := web/node_modules/three
$(BUILD)/web/.stamp: $(WEB_SRC) web/node_modules/.package-lock.json
	rm -rf $(BUILD)/web
	mkdir -p $(BUILD)/web/three/addons/controls $(BUILD)/web/three/addons/loaders $(BUILD)/web/three/addons/libs
	cp $(WEB_SRC) $(BUILD)/web/
	cp $(THREE)/build/three.module.js $(THREE)/build/three.core.js $(BUILD)/web/three/
	cp $(THREE)/examples/jsm/controls/OrbitControls.js $(BUILD)/web/three/addons/controls/
	cp $(THREE)/examples/jsm/loaders/DRACOLoader.js $(BUILD)/web/three/addons/loaders/
	cp $(THREE)/examples/jsm/loaders/GLTFLoader.js $(BUILD)/web/three/addons/loaders/
	mkdir -p $(BUILD)/web/three/addons/utils
	cp $(THREE)/examples/jsm/utils/BufferGeometryUtils.js $(THREE)/examples/jsm/utils/SkeletonUtils.js $(BUILD)/web/three/addons/utils/
	cp $(THREE)/examples/jsm/libs/meshopt_decoder.module.js $(BUILD)/web/three/addons/libs/
	cp -r $(THREE)/examples/jsm/libs/draco $(BUILD)/web/three/addons/libs/
	touch $@

web: $(BUILD)/web/.stamp

# The whole suite twice: against the normal build, then against the ASan/UBSan build
# (tests/run.sh's asan pass; `make test-asan` runs that pass alone).
test: setup
	$(MAKE) node-deps
	$(MAKE) all unit-tests
	$(MAKE) sanitize
	$(MAKE) fuzz-build
	bash tests/run.sh all

test-asan: setup
	$(MAKE) node-deps
	$(MAKE) sanitize
	bash tests/run.sh asan

bench: setup all
	bash tests/bench/run.sh

# The README's run command: the server on the default collection (scripts/run.sh).
run: setup all
	bash scripts/run.sh

clean:
	rm -rf build

-include $(shell find build -name '*.d' 2>/dev/null)

# The container images (isoserve, isoserve-front) with docker or podman, whichever can run
# them here (docker/image.sh); test-image builds them, runs one replica and the compose
# stack and checks them (slow, so not part of `make test`; it says SKIP where nothing can
# run containers).
image:
	bash docker/image.sh

test-image:
	bash tests/image/check_image.sh
