# Two commands for a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test suite-cost fuzz bench bench-solver bench-looks bench-footprint examples install kernels bytecode clean lock compose photoreal

# The pinned packages installed by uv (~21 s here against pip's ~55 s: parallel downloads and installs), pip where uv
# cannot be had or fails; either installs exactly constraints.txt, byte-compiled (where PYTHONDONTWRITEBYTECODE=1 is
# set, a package installed without its bytecode is compiled again by every process that imports it).
UV_VERSION := 0.9.7
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	($(PY) -m pip install --quiet "uv==$(UV_VERSION)" && \
	 $(PY) -m uv pip install --quiet --compile-bytecode --python $(PY) -c constraints.txt -e ".[dev]") || \
	($(PY) -m pip install --quiet --upgrade "pip>=24" && $(PY) -m pip install --quiet -c constraints.txt -e ".[dev]")
	touch $(STAMP)

# The search's kernels compiled ahead of time (docs/design.md §2, "Compiled kernels"; ~27 s on a fresh clone here,
# instant when current): an agent then runs without numba's JIT (~110 MB less resident). Without them, or after a
# kernel's source changed and before this runs again, the same kernels run through the JIT.
kernels: $(STAMP)
	@$(PY) -m evopose.kernel_build

# The project's own modules byte-compiled once (~2 s): where PYTHONDONTWRITEBYTECODE=1 is set (this machine), no
# process keeps what it compiles, and every agent or CLI process started compiled them again (0.3 s of its start).
bytecode: $(STAMP)
	@$(PY) -m compileall -q -j 0 agents evopose evopose_errors vision protocol scenarios geometry benchmarks examples

install: $(STAMP) kernels bytecode

# Blender's bpy (Cycles, the photoreal renderer: docs/datasets.md) in its own interpreter: bpy 4.5 needs Python 3.11
# and numpy < 2, the project pins numpy 2. EVOPOSE_BPY_PYTHON may name another Python that has bpy 4.5.
PHOTOREAL := .venv-photoreal
photoreal: $(PHOTOREAL)/.installed

$(PHOTOREAL)/.installed: constraints-photoreal.txt
	$(PYTHON) -m venv $(PHOTOREAL)
	$(PHOTOREAL)/bin/pip install --quiet -c constraints-photoreal.txt bpy==4.5.15
	touch $@

# The demo's fleet listens on tcp/127.0.0.1:$(PORT): `make demo PORT=7448` when another fleet has 7447.
PORT ?= 7447
demo: $(STAMP) kernels bytecode
	@if $(PY) -c "import sys; from agents.transport.ports import listening; sys.exit(listening('tcp/127.0.0.1:$(PORT)'))"; \
	then :; else echo "port $(PORT) is in use (another fleet or router?): run make demo PORT=$$(($(PORT) + 1))" >&2; exit 2; fi
	$(VENV)/bin/evopose scenario run exp2a-features --listen tcp/127.0.0.1:$(PORT)

# Two passes (tests/conftest.py): everything but the real-time tests on two workers, then those one at a time.
test: $(STAMP) kernels bytecode
	EVOPOSE_REQUIRE_AOT=1 $(PY) -m pytest -q -n 2 -m "not realtime"
	EVOPOSE_REQUIRE_AOT=1 $(PY) -m pytest -q -m realtime

# Where the suite's time goes, per module and test: wall, CPU, the processes started, waiting (a few minutes: both
# passes of `make test`, timed).
suite-cost: $(STAMP) kernels bytecode
	$(PY) -m benchmarks.suite_cost

# The fuzz tests with many more (and random) examples than `make test` runs (a few minutes).
fuzz: $(STAMP)
	EVOPOSE_FUZZ_EXAMPLES=3000 EVOPOSE_FUZZ_RANDOM=1 $(PY) -m pytest -q tests/test_fuzz.py

# Regenerate the example pose-problem files from seeded synthetic problems.
examples: $(STAMP)
	$(PY) -m examples.make_examples

# Long (tens of minutes): each benchmark writes benchmarks/results/<name>.md, then BENCHMARKS.md is assembled.
bench: $(STAMP) kernels
	NUMBA_NUM_THREADS=1 $(PY) -m benchmarks.run_solvers
	NUMBA_NUM_THREADS=1 $(PY) -m benchmarks.bench_kernels
	$(PY) -m benchmarks.bench_features
	$(PY) -m benchmarks.bench_fleet
	$(PY) -m benchmarks.bench_latency
	NUMBA_NUM_THREADS=1 $(PY) -m benchmarks.bench_confidence
	NUMBA_NUM_THREADS=1 $(PY) -m benchmarks.bench_weights
	NUMBA_NUM_THREADS=1 $(PY) -m benchmarks.bench_image_only
	NUMBA_NUM_THREADS=1 $(PY) -m benchmarks.bench_time_budget
	$(PY) -m benchmarks.bench_capacity
	$(PY) -m benchmarks.bench_flood
	$(PY) -m benchmarks.bench_blas_threads
	$(PY) -m benchmarks.bench_photoreal_features tests/data/photoreal/paper tests/data/photoreal/telephoto
	$(PY) -m benchmarks.report

# The solver on a fixed problem set against the committed figures (benchmarks/results/solver_regression.json):
# fails on a drop in success or accuracy, more evaluations, or a slower median beyond the measured noise (~1 min).
# After a change meant to move them: $(PY) -m benchmarks.solver_regression --update
bench-solver: $(STAMP) kernels
	NUMBA_NUM_THREADS=1 $(PY) -m benchmarks.solver_regression

# The mark front-ends through eight camera looks (~1 h here: renders the Cycles worlds of the Pioneer and the second
# robot once, keeping their radiance, then develops each frame through every look of scenarios/looks.py).
bench-looks: $(STAMP) photoreal
	$(PY) -m benchmarks.photoreal_worlds --render --frames 4 --out datasets/photoreal
	$(PY) -m benchmarks.photoreal_worlds --set husky --render --frames 4 --out datasets/photoreal-husky
	$(PY) -m benchmarks.bench_photoreal_looks datasets/photoreal/photoreal-*-g*
	$(PY) -m benchmarks.bench_photoreal_looks datasets/photoreal-husky/photoreal-husky-*-g* \
		--front-ends contrast,contrast-fixed,marks --out benchmarks/results/photoreal_looks_husky.md
	$(PY) -m benchmarks.report

# Three agent pairs for 10 minutes each (30 min): memory and CPU over time.
bench-footprint: $(STAMP) kernels
	$(PY) -m benchmarks.bench_footprint --minutes 10
	$(PY) -m benchmarks.report

# Re-pin every dependency to what is installed in the venv now.
lock: $(STAMP)
	$(PY) -m pip freeze --exclude-editable | grep -v '^evopose' > constraints.txt

# Regenerate docker-compose.yml (exp2a-features), docker-compose.secure.yml (the same with TLS, mTLS and the ACL)
# and compose/<scenario>.yml for every shipped fleet scenario.
compose: $(STAMP)
	$(VENV)/bin/evopose scenario compose exp2a-features --out docker-compose.yml
	$(VENV)/bin/evopose scenario compose exp2a-features --secure --out docker-compose.secure.yml
	mkdir -p compose
	rm -f compose/*.yml
	for f in scenarios/fleet/*.yaml; do \
		name=$$(basename $$f .yaml); \
		$(VENV)/bin/evopose scenario compose $$name --context .. --out compose/$$name.yml || exit 1; \
	done

clean:
	rm -rf $(VENV) *.egg-info
