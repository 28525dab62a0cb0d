# gainsched — developer entry points (GNU make).
# `make tables` and `make test` are all a fresh checkout needs.

PY   ?= $(shell command -v python3.11 || command -v python3)
VENV  = .venv
BIN   = $(VENV)/bin
STAMP = $(VENV)/.stamp

PYTEST_ARGS ?=
# The suite runs in parallel (pytest-xdist), one worker per core, a test module whole on
# one worker: its tests share what its module fixtures build (flown campaigns, compiled
# runtimes, tables). (Not --dist loadgroup: xdist 3.8 cannot tag nodes of pytest 9.)
# PYTEST_WORKERS=0 runs in-process.
PYTEST_WORKERS ?= auto
PYTEST_XDIST = -n $(PYTEST_WORKERS) --dist loadfile

.PHONY: venv lint test test-fast test-count tables bench bench-quick paper clean distclean firmware-example firmware-size fuzz \
	interrupt-trials fresh-machine test-wheel

# (Re)create the virtualenv whenever the dependencies or their tested lock change: the
# package's ranges (pyproject.toml) at the versions make test ran (.ci/constraints.txt).
$(STAMP): pyproject.toml .ci/constraints.txt
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install -c .ci/constraints.txt -e '.[dev,dask]'
	touch $@

venv: $(STAMP)

# ruff, the layer contract, and MISRA C:2012 on the hand-written C (cppcheck's MISRA
# addon, gainsched/firmware/host/misra.py). cppcheck is installed first where it is missing and
# apt-get is usable (.ci/install-tools, the install step .ci/run has; GAINSCHED_INSTALL_TOOLS=0
# turns it off); where it cannot be, the MISRA check is skipped in one line, and with
# CI=true (.ci/run) lint fails in one line instead.
lint: $(STAMP)
	@bash .ci/install-tools lint
	$(BIN)/ruff check gainsched tests bench examples
	$(BIN)/lint-imports --no-cache
	$(BIN)/python -m gainsched.firmware.host.misra

# The package byte-compiled once first: with PYTHONDONTWRITEBYTECODE set (as on these
# machines) every process of the suite (about 300: workers, commands) compiled what it
# imported, 0.15-0.2 s each; it reads the compiled files whatever that variable says.
test: $(STAMP) lint
	$(BIN)/python -m compileall -q gainsched
	$(BIN)/python -m pytest $(PYTEST_XDIST) $(PYTEST_ARGS)

# The fast tier for iterating: the suite without the tests marked slow (README, Tests).
test-fast: $(STAMP) lint
	$(BIN)/python -m compileall -q gainsched
	$(BIN)/python -m pytest $(PYTEST_XDIST) -m "not slow" $(PYTEST_ARGS)

# The wheel a user installs, beside numpy and scipy at the low ends of the package's
# ranges (not the lock), passes the fast tier from a clean clone (.ci/test-wheel).
test-wheel:
	PY=$(PY) bash .ci/test-wheel

# The README's promise on a machine with only Python, a C compiler and make: a fresh clone
# of HEAD, `make tables`, then `make test-fast` with cppcheck, arm-none-eabi-* and qemu-*
# hidden from the PATH and no package manager (tests/fresh_machine.py; a few minutes).
fresh-machine:
	$(PY) tests/fresh_machine.py

# How many tests and assertions the suite has (tests/tally.py; `python tests/tally.py REV`
# counts a revision's assertions).
test-count: $(STAMP)
	$(BIN)/python tests/tally.py

tables: $(STAMP)
	$(BIN)/gainsched build configs/paper.toml -o tables/

bench: $(STAMP)
	$(BIN)/python -m bench

# The benchmarks' quick mode, for slices of work (bench/__init__.py).
bench-quick: $(STAMP)
	$(BIN)/python -m bench --quick

paper: $(STAMP)
	$(BIN)/gainsched paper -o reports/paper

# A real build killed by SIGINT/SIGKILL at 60 random moments (tests/test_interrupt.py).
INTERRUPT_TRIALS ?= 60
interrupt-trials: $(STAMP)
	GAINSCHED_INTERRUPT_TRIALS=$(INTERRUPT_TRIALS) $(BIN)/python -m pytest -s -p no:cacheprovider \
		tests/test_interrupt.py

clean:
	rm -rf build dist *.egg-info .pytest_cache .ruff_cache
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)

# ---- firmware: C header + runtime (docs/runtime.md) ----------------------------
FW_TABLE  ?= tables/paper.h5
FW_DIR    ?= build/firmware
# the C prefix of FW_TABLE's symbols (paper_table, PAPER_N_STATE): the examples are built
# for any table (examples/firmware/any_table.h); read only by the firmware targets
# (empty for a table inspect cannot read: the target's export-c then says why, in one line)
FW_NAME    = $(shell $(BIN)/gainsched inspect $(FW_TABLE) --json 2>/dev/null \
	| $(BIN)/python -c "import json, sys; t = sys.stdin.read(); print(json.loads(t)['c_prefix'] if t else '')")
FW_NAMES   = -DGS_NAME=$(FW_NAME) -DGS_NAME_UC=$(shell echo $(FW_NAME) | tr a-z A-Z)
FW_CFLAGS ?= -std=c99 -Wall -Wextra -Wpedantic -Werror -O2
M4F_FLAGS  = -mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard -Os -ffunction-sections -fdata-sections
FUZZ_RUNS    ?= 5000000
FUZZ_SECONDS ?= 60
SAN_FLAGS  = -g -O1 -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer
CLANG     ?= $(firstword $(foreach c,clang clang-19 clang-18 clang-17 clang-16 clang-15 clang-14,$(shell command -v $(c) 2>/dev/null)))

# The examples: headers from FW_TABLE, runtime and controller copied beside them, strict
# builds, run: the lookup loop (main.c) and the whole 1 kHz control loop (control_loop.c).
firmware-example: $(STAMP)
	$(BIN)/gainsched export-c $(FW_TABLE) -o $(FW_DIR)
	$(CC) $(FW_CFLAGS) $(FW_NAMES) -I$(FW_DIR) examples/firmware/main.c $(FW_DIR)/gainsched_runtime.c \
		-o $(FW_DIR)/firmware_example
	$(FW_DIR)/firmware_example
	$(CC) $(FW_CFLAGS) $(FW_NAMES) -I$(FW_DIR) examples/firmware/control_loop.c \
		$(FW_DIR)/gainsched_control.c $(FW_DIR)/gainsched_runtime.c -o $(FW_DIR)/control_loop
	$(FW_DIR)/control_loop

# Cortex-M4F section sizes of the runtime, the controller and the table (needs
# arm-none-eabi-gcc).
firmware-size: $(STAMP)
	$(BIN)/gainsched export-c $(FW_TABLE) -o $(FW_DIR)/dense --format dense --no-code-size
	@rm -rf $(FW_DIR)/compact; \
	$(BIN)/gainsched export-c $(FW_TABLE) -o $(FW_DIR)/compact --format compact --no-code-size \
		|| echo "firmware-size: no compact table of $(FW_TABLE) (why: the line above); the dense one alone"
	@set -e; \
	if command -v arm-none-eabi-gcc >/dev/null 2>&1; then \
		CC_SIZE="arm-none-eabi-gcc $(FW_CFLAGS) $(M4F_FLAGS)"; SIZE=arm-none-eabi-size; \
		TARGET="Cortex-M4F ($(M4F_FLAGS))"; \
	else \
		echo "firmware-size: arm-none-eabi-gcc not found (Debian: apt-get install gcc-arm-none-eabi);"; \
		CC_SIZE="$(CC) $(FW_CFLAGS) -Os -ffunction-sections -fdata-sections"; SIZE=size; \
		TARGET="host ($(CC) -Os)"; \
	fi; \
	for fmt in dense compact; do \
		[ -f $(FW_DIR)/$$fmt/gainsched_runtime.c ] || continue; \
		$$CC_SIZE -I$(FW_DIR)/$$fmt -c $(FW_DIR)/$$fmt/gainsched_runtime.c -o $(FW_DIR)/$$fmt/runtime.o; \
		$$CC_SIZE -I$(FW_DIR)/$$fmt -c $(FW_DIR)/$$fmt/gainsched_control.c -o $(FW_DIR)/$$fmt/control.o; \
		$$CC_SIZE $(FW_NAMES) -I$(FW_DIR)/$$fmt -c examples/firmware/size_probe.c -o $(FW_DIR)/$$fmt/table.o; \
		echo "$$fmt table, $$TARGET: code (runtime.o, control.o) + data (table.o .rodata), bytes"; \
		$$SIZE -A $(FW_DIR)/$$fmt/runtime.o $(FW_DIR)/$$fmt/control.o $(FW_DIR)/$$fmt/table.o \
			| grep -Ev '^\.(comment|ARM\.attributes|debug)|^ *$$' ; \
		$$SIZE $(FW_DIR)/$$fmt/runtime.o $(FW_DIR)/$$fmt/control.o $(FW_DIR)/$$fmt/table.o; \
	done

# Fuzz gs_lookup, then gs_ctrl_update: libFuzzer when clang is there (FUZZ_SECONDS
# each), else the bounded random drivers (FUZZ_RUNS queries, steps); all under
# AddressSanitizer + UBSan.
fuzz: $(STAMP)
	$(BIN)/gainsched export-c $(FW_TABLE) -o $(FW_DIR) --no-code-size
	@if [ -n "$(CLANG)" ] && echo 'int LLVMFuzzerTestOneInput(const char *d, long n){(void)d;(void)n;return 0;}' \
		| $(CLANG) -x c - -fsanitize=fuzzer -o $(FW_DIR)/.fuzzprobe >/dev/null 2>&1; then \
		set -e; mkdir -p $(FW_DIR)/fuzz-corpus; \
		echo "fuzz: libFuzzer ($(CLANG)), $(FUZZ_SECONDS) s"; \
		$(CLANG) $(FW_CFLAGS) $(FW_NAMES) $(SAN_FLAGS) -fsanitize=fuzzer -DGS_LIBFUZZER -I$(FW_DIR) \
			examples/firmware/fuzz_lookup.c $(FW_DIR)/gainsched_runtime.c -o $(FW_DIR)/fuzz_lookup_libfuzzer; \
		$(FW_DIR)/fuzz_lookup_libfuzzer -max_total_time=$(FUZZ_SECONDS) -max_len=12 $(FW_DIR)/fuzz-corpus; \
		mkdir -p $(FW_DIR)/fuzz-corpus-control; \
		$(CLANG) $(FW_CFLAGS) $(FW_NAMES) $(SAN_FLAGS) -fsanitize=fuzzer -DGS_LIBFUZZER -I$(FW_DIR) \
			examples/firmware/fuzz_control.c $(FW_DIR)/gainsched_control.c \
			$(FW_DIR)/gainsched_runtime.c -o $(FW_DIR)/fuzz_control_libfuzzer; \
		$(FW_DIR)/fuzz_control_libfuzzer -max_total_time=$(FUZZ_SECONDS) -max_len=4800 \
			$(FW_DIR)/fuzz-corpus-control; \
	else \
		set -e; echo "fuzz: no clang with libFuzzer; bounded random drivers, $(FUZZ_RUNS) queries"; \
		$(CC) $(FW_CFLAGS) $(FW_NAMES) $(SAN_FLAGS) -I$(FW_DIR) examples/firmware/fuzz_lookup.c \
			$(FW_DIR)/gainsched_runtime.c -o $(FW_DIR)/fuzz_lookup; \
		$(FW_DIR)/fuzz_lookup $(FUZZ_RUNS) 1; \
		$(CC) $(FW_CFLAGS) $(FW_NAMES) $(SAN_FLAGS) -I$(FW_DIR) examples/firmware/fuzz_control.c \
			$(FW_DIR)/gainsched_control.c $(FW_DIR)/gainsched_runtime.c -o $(FW_DIR)/fuzz_control; \
		$(FW_DIR)/fuzz_control $(FUZZ_RUNS) 1; \
	fi
