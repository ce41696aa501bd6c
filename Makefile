# mjx_stairs. Every target sets itself up: a missing virtualenv is created and the package
# installed into it first. On a machine with an NVIDIA GPU the CUDA build of JAX is installed.
#   make exp1            the main job: stage 1, stage 2, the stall ablation, evaluation, figures
#   make test            the CPU test suite (what CI runs)
# Override PY to use an existing interpreter instead of the virtualenv, e.g. on a GPU host with
# the wheelhouse on PYTHONPATH:  make train-stage1 PY=python3 SETUP=

VENV ?= .venv
PY ?= $(VENV)/bin/python
SETUP ?= $(VENV)/.installed
HAS_GPU := $(shell command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1 && echo 1)
comma := ,
EXTRAS := dev$(if $(HAS_GPU),$(comma)cuda)
ARGS ?=
# make test's pytest-xdist workers (0: all in one process). Files are handed out whole
# (--dist loadfile), so a module's fixtures (a trained policy, a compiled env) are built once.
TEST_WORKERS ?= 2
# Without a GPU, training and evaluation compile with XLA's CPU fusion emitters off and LLVM at
# level 1: half the compile time, no slower to run (make exp1 on 2 CPU cores: 4.2 min instead
# of 5.8). Flags already in XLA_FLAGS come after these, so they win. bench keeps the defaults.
CPU_XLA := $(if $(HAS_GPU),,XLA_FLAGS="--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=1 $$XLA_FLAGS")

.PHONY: setup test lint train-stage1 train-stage2 train-stage2-fast train-stage2-paper train-stage2-robot train-generalist ablation eval exp1 transfer-matrix bench time-to-climber clean-venv

$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(VENV)/bin/pip install -q --upgrade pip
	$(VENV)/bin/pip install -q -e ".[$(EXTRAS)]"
	touch $@

setup: $(SETUP)

test: $(SETUP)
	JAX_PLATFORMS=cpu $(PY) -m pytest tests -n $(TEST_WORKERS) --dist loadfile

lint: $(SETUP)
	$(PY) -m ruff check .

train-stage1: $(SETUP)
	$(CPU_XLA) $(PY) -m mjx_stairs train experiments/stage1.toml $(ARGS)

train-stage2: $(SETUP)
	$(CPU_XLA) $(PY) -m mjx_stairs train experiments/stage2_u.toml $(ARGS)

train-stage2-fast: $(SETUP)  # lean settings (issue 7): 417 k vs 187 k env steps/s on an H100 (stage-2 success: experiments/README.md)
	$(CPU_XLA) $(PY) -m mjx_stairs train experiments/stage2_u_lean.toml $(ARGS)

train-stage2-paper: $(SETUP)  # issue 21: stage 2 as the paper has it (final goal drawn on the stairs, evaluation physics)
	$(CPU_XLA) $(PY) -m mjx_stairs train experiments/stage2_u_paper.toml $(ARGS)

train-stage2-robot: $(SETUP)  # issue 25: stage 2 fine-tuned for a real Go2's joints (damping 0.1-2, implicit; 0-20 ms delay)
	$(CPU_XLA) $(PY) -m mjx_stairs train experiments/stage2_u_robot.toml $(ARGS)

train-generalist: $(SETUP)  # issue 24: building stairs up and down, robust to a real Go2 (from stage 1)
	$(CPU_XLA) $(PY) -m mjx_stairs train experiments/generalist.toml $(ARGS)

ablation: $(SETUP)
	$(CPU_XLA) $(PY) -m mjx_stairs train experiments/stage2_u_no_stall.toml $(ARGS)

eval: $(SETUP)
	$(CPU_XLA) $(PY) -m mjx_stairs eval --checkpoint experiments/results/stage2_u/policy.npz \
	  --out experiments/results/eval $(ARGS)

exp1: $(SETUP)
	$(CPU_XLA) $(PY) -m mjx_stairs exp1 $(ARGS)

transfer-matrix: $(SETUP)
	$(CPU_XLA) $(PY) -m mjx_stairs transfer-matrix $(ARGS)

# issue 22: the lean training physics beside the evaluation physics (4096 robots, physics only
# and full training), then the measured time to a trained climber as a row (a GPU job: minutes)
bench: $(SETUP)
	$(PY) -m mjx_stairs bench --config experiments/stage2_u_lean.toml --robots 4096 \
	  --parts physics,train --out runs/bench/lean.json $(ARGS)
	$(PY) -m mjx_stairs bench --config experiments/stage2_u.toml env.robot.physics=evaluation \
	  --robots 4096 --parts physics,train --out runs/bench/evaluation.json $(ARGS)
	$(PY) experiments/bench_table.py runs/bench/lean.json runs/bench/evaluation.json \
	  --climber experiments/results/time_to_climber/time_to_climber.json

time-to-climber: $(SETUP)  # issue 22: stage 1 + stage 2 from nothing (lean physics), timed, judged (GPU; CPU smoke: ARGS="--stage1-iterations 2 --stage2-iterations 2 --robots 4")
	$(CPU_XLA) $(PY) experiments/gpu/time_to_climber.py runs/time_to_climber \
	  $(if $(HAS_GPU),--set network.conv_impl=fused_bf16,) $(ARGS)

clean-venv:
	rm -rf $(VENV)
