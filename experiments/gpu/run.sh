#!/usr/bin/env bash
# One experiment step on a lent GPU host (no package index there): install the wheelhouse that
# ../shared/gpu/wheelhouse.sh built into .whl, then run the named steps, writing under $OUT.
#   bash experiments/gpu/run.sh DEADLINE_S STEP [STEP ...]
# Steps: bench-quick, bench, stage1, stage2, ablation, eval, figs. Each training step stops and
# checkpoints before DEADLINE_S seconds after the script started.
set -uo pipefail
T0=$(date +%s)
DEADLINE=$1; shift
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
  --target /tmp/site .whl/*.whl >/dev/null 2>&1 || { echo "wheel install failed"; exit 1; }
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=egl
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
left() { echo $(( DEADLINE - ($(date +%s) - T0) )); }
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
python3 -c "import jax, mujoco; print('jax', jax.__version__, jax.devices(), 'mujoco', mujoco.__version__)"

train() {  # train NAME TOML [overrides...]
  local name=$1 toml=$2; shift 2
  local budget=$(( $(left) - 25 ))
  echo "== $name: budget ${budget}s"
  python3 -m mjx_stairs train "$toml" train.log_dir=/tmp/runs train.progress=false \
    train.console=false train.time_budget_s=$budget "$@" 2>&1 | grep -v -e "warp" -e "^$"
  local run; run=$(ls -td /tmp/runs/${name}__* | head -1)
  mkdir -p "$OUT/$name"
  cp "$run/policy.npz" "$run/metrics.jsonl" "$run/config.json" "$OUT/$name/" 2>/dev/null
  [ -f "$run/resume.npz" ] && cp "$run/resume.npz" "$OUT/$name/"
  python3 - "$OUT/$name/metrics.jsonl" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
for r in rows[:: max(1, len(rows) // 12)] + rows[-1:]:
    print(f"it {r['iteration']:5d} steps {r['env_steps']/1e6:7.1f}M  {r['perf/steps_per_s']/1e3:6.0f}k/s "
          f"ret {r.get('episode/return', 0):7.2f} level {r.get('level', 0):5.2f} "
          f"top {r.get('at_top', 0):.2f} succ {r.get('success', r.get('episode_success', 0)):.3f} "
          f"term {r.get('terminated', 0):.4f} lr {r.get('opt/lr', 0):.1e}")
PY
}

for step in "$@"; do
  case $step in
    bench-quick) python3 -m mjx_stairs bench --config experiments/stage2_u.toml --robots 4096 \
        --parts physics,env --repeats 3 --out "$OUT/bench_quick.json" 2>&1 | grep -v warp ;;
    bench) python3 -m mjx_stairs bench --config experiments/stage2_u.toml --robots 4096 16384 \
        --out "$OUT/bench.json" 2>&1 | grep -v warp ;;
    stage1) train stage1 experiments/stage1.toml ;;
    stage2) train stage2_u experiments/stage2_u.toml ;;
    ablation) train stage2_u_no_stall experiments/stage2_u_no_stall.toml ;;
    *) echo "unknown step $step"; exit 2 ;;
  esac
  echo "== $step done at $(( $(date +%s) - T0 ))s"
done
