#!/usr/bin/env bash
# One experiment step on a lent GPU host (no package index there): install the wheelhouse that
# ../shared/gpu/wheelhouse.sh built into .whl, then run the named steps, writing under $OUT.
#   bash experiments/gpu/run.sh DEADLINE_S STEP [STEP ...]
# Steps (end with pack, since only 8 files come back): bench-quick, bench, bench4096, encoder,
# levers, bench4096-row, bench4096-fast, levers-nearest, bench4096-lean, stage1,
# stage2, ablation, stage2-fast, stage2-final-goal, stage2-pair (stage 2 and its
# ablation side by side on one GPU, same wall budget each), stage2-lean, eval-lean, stage1-lean,
# stage2-lean-s1, bench4096-nearest, bench16384-lean, straight-lean, l-shaped-lean, spiral-lean,
# transfer-lean, bench4096-values, bench4096-update-bound, update-profile,
# trace-chunk, trace-chunk-nocb, bench4096-graphs, bench4096-fused,
# bench4096-fused-abcr, stage2-lean-fused, bench4096-no-triton-gemm, bench4096-bf16,
# eval-committed, encoder-hlo, bench-lean, report. Each training step stops and
# checkpoints before DEADLINE_S seconds after the script started, and leaves in $OUT/<name>/ the
# policy, metrics, run facts and a packed state.npz (~11 MB for 4096 robots). To continue a run in
# the next command, copy that state.npz and metrics.jsonl to .carry/<name>/ (ignored by git) and
# carry .carry with .whl. Stage 2 starts from experiments/results/stage1/policy.npz: commit the
# stage-1 policy there first. TRAIN_ARGS (key=value ...) is added to every training command.
set -uo pipefail
T0=$(date +%s)
DEADLINE=$1; shift
if [ -z "${SKIP_INSTALL:-}" ]; then  # SKIP_INSTALL=1: the packages are already importable
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl >/dev/null 2>&1 || { echo "wheel install failed"; exit 1; }
fi
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
left() { echo $(( DEADLINE - ($(date +%s) - T0) )); }
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
python3 -c "import jax, mujoco; print('jax', jax.__version__, jax.devices(), 'mujoco', mujoco.__version__)"

train() {  # train NAME TOML [overrides...]; resumes from .carry/NAME/state.npz when carried
  local name=$1 toml=$2; shift 2
  local budget=$(( $(left) - 25 ))
  local resume=() prev=".carry/$name"
  [ -f "$prev/state.npz" ] && resume=(--resume "$prev/state.npz")
  echo "== $name: budget ${budget}s ${resume[*]}"
  python3 -m mjx_stairs train "$toml" train.log_dir=/tmp/runs train.progress=false \
    train.console=false train.checkpoint_env=packed train.time_budget_s=$budget \
    publish_dir="$OUT/$name" ${TRAIN_ARGS:-} "$@" "${resume[@]}" 2>&1 | grep -v -e "warp" -e "^$"
  local run; run=$(ls -td /tmp/runs/${name}__* | head -1)
  cp "$(ls "$run"/checkpoints/state_*.npz | tail -1)" "$OUT/$name/state.npz"
  mkdir -p /tmp/policies && cp "$OUT/$name/policy.npz" "/tmp/policies/$name.npz"  # for report
  if [ -f "$prev/metrics.jsonl" ]; then  # keep the whole curve across commands
    cat "$prev/metrics.jsonl" "$OUT/$name/metrics.jsonl" > "$OUT/$name/m.tmp" \
      && mv "$OUT/$name/m.tmp" "$OUT/$name/metrics.jsonl"
  fi
  python3 - "$OUT/$name/metrics.jsonl" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
for r in rows[:: max(1, len(rows) // 12)] + rows[-1:]:
    print(f"it {r['iteration']:5d} steps {r['env_steps']/1e6:7.1f}M  {r['perf/steps_per_s']/1e3:6.0f}k/s "
          f"ret {r.get('episode/return', 0):7.2f} level {r.get('level', 0):5.2f} "
          f"top {r.get('at_top', 0):.2f} succ {r.get('success', 0):.3f} "
          f"term {r.get('terminated', 0):.4f} lr {r.get('opt/lr', 0):.1e}")
PY
}

# The reference physics as eval overrides (keys under [env]), and the lean physics of
# stage2_u_lean.toml as training overrides.
REFERENCE="robot.terrain_contacts=mjx robot.shin_collision=true robot.ls_iterations=5"
LEAN="env.robot.terrain_contacts=nearest env.robot.shin_collision=false env.robot.ls_iterations=3"

bench() {  # bench OUT_FILE CONFIG [overrides and options...]
  local out=$1 toml=$2; shift 2; mkdir -p "$(dirname "$out")"
  python3 -m mjx_stairs bench --config "$toml" "$@" --out "$out" 2>&1 | grep -v warp
}

for step in "$@"; do
  case $step in
    bench-quick) bench "$OUT/bench_quick.json" experiments/stage2_u.toml --robots 4096 \
        --parts physics,env --repeats 3 ;;
    bench) bench "$OUT/bench.json" experiments/stage2_u.toml --robots 4096 16384 ;;
    stage1) train stage1 experiments/stage1.toml ;;
    stage2) train stage2_u experiments/stage2_u.toml ;;
    stage2-final-goal) train stage2_u_final_goal experiments/stage2_u_final_goal.toml ;;
    stage2-pair)  # two processes share the GPU: each gets under half of its memory
      XLA_PYTHON_CLIENT_MEM_FRACTION=0.45 train stage2_u experiments/stage2_u.toml \
        > >(sed 's/^/[stall] /') 2>&1 &
      XLA_PYTHON_CLIENT_MEM_FRACTION=0.45 train stage2_u_no_stall \
        experiments/stage2_u_no_stall.toml > >(sed 's/^/[no-stall] /') 2>&1 &
      wait ;;
    ablation) train stage2_u_no_stall experiments/stage2_u_no_stall.toml ;;
    stage2-fast)  # issue 7's fidelity check: stage 2 with the faster settings (row encoder, no
      # shin spheres, 3 line-search steps), then evaluated in the reference physics it was not
      # trained in (shins on, 5 line-search steps), 1000 robots per level
      train stage2_u_fast experiments/stage2_u_fast.toml
      python3 -m mjx_stairs eval --checkpoint /tmp/policies/stage2_u_fast.npz --robots 1000 \
        --env robot.shin_collision=true robot.ls_iterations=5 \
        --out "$OUT/stage2_u_fast/eval_reference_physics" 2>&1 | grep -v warp ;;
    bench4096) bench "$OUT/bench_4096.json" experiments/stage2_u.toml --robots 4096 ;;
    # issue 7's levers, all into $OUT/bench/ (one tar after pack): the encoder alone (xla vs row
    # convolutions), physics-only (a) for each physics setting, and (a)+(b)+(c) with the row
    # encoder, with and without the faster physics settings
    encoder) mkdir -p "$OUT/bench"; python3 experiments/gpu/encoder_bench.py --batch 49152 \
        --out "$OUT/bench/encoder.json" 2>&1 | grep -v warp ;;
    levers)
      for v in "noshin:env.robot.shin_collision=false" "ls3:env.robot.ls_iterations=3"; do
        bench "$OUT/bench/a_${v%%:*}.json" experiments/stage2_u.toml ${v#*:} --robots 4096 \
          --parts physics --repeats 3
      done ;;
    bench4096-row) bench "$OUT/bench/abc_row.json" experiments/stage2_u.toml \
        network.conv_impl=row --robots 4096 ;;
    bench4096-fast) bench "$OUT/bench/abc_fast.json" experiments/stage2_u_fast.toml \
        network.conv_impl=row --robots 4096 ;;
    # the nearest-point terrain collider (robot.terrain_contacts=nearest): physics only with the
    # reference settings otherwise, then (a)+(b)+(c) with the lean settings (stage2_u_lean.toml)
    levers-nearest) bench "$OUT/bench/a_nearest.json" experiments/stage2_u.toml \
        env.robot.terrain_contacts=nearest --robots 4096 --parts physics --repeats 3 ;;
    bench4096-lean) bench "$OUT/bench/abc_lean.json" experiments/stage2_u_lean.toml \
        --robots 4096 ;;
    bench4096-nearest) bench "$OUT/bench/abc_nearest.json" experiments/stage2_u.toml \
        env.robot.terrain_contacts=nearest --robots 4096 ;;
    # the critic's rollout values after the scan ('batched', the default) against inside it
    # ('per_step'), with the rollout alone (r) beside (a), (b), (c) to split an iteration
    bench4096-values)
      bench "$OUT/bench/abcr_lean.json" experiments/stage2_u_lean.toml --robots 4096
      bench "$OUT/bench/rc_lean_per_step.json" experiments/stage2_u_lean.toml \
        train.rollout_values=per_step --robots 4096 --parts rollout,train ;;
    # how far the ratio (c)/(a) can go with the paper's network when the update shrinks: one
    # epoch of 4 minibatches, and one gradient step per iteration (a change of algorithm; a bound)
    bench4096-update-bound)
      bench "$OUT/bench/ac_lean_1x4.json" experiments/stage2_u_lean.toml ppo.num_epochs=1 \
        --robots 4096 --parts physics,train
      bench "$OUT/bench/ac_lean_1x1.json" experiments/stage2_u_lean.toml ppo.num_epochs=1 \
        ppo.num_minibatches=1 --robots 4096 --parts physics,train ;;
    update-profile) mkdir -p "$OUT/bench"; python3 experiments/gpu/update_profile.py \
        --config experiments/stage2_u_lean.toml --out "$OUT/bench/update_profile.json" 2>&1 \
        | grep -v warp ;;
    trace-chunk) mkdir -p "$OUT/bench"; python3 experiments/gpu/trace_chunk.py \
        --config experiments/stage2_u_lean.toml --out "$OUT/bench/trace_chunk.json" 2>&1 \
        | grep -v warp ;;
    trace-chunk-nocb) mkdir -p "$OUT/bench"  # without CUDA graphs: every kernel attributed
      XLA_FLAGS=--xla_gpu_enable_command_buffer= python3 experiments/gpu/trace_chunk.py \
        --config experiments/stage2_u_lean.toml --out "$OUT/bench/trace_chunk_nocb.json" 2>&1 \
        | grep -v warp ;;
    bench4096-graphs)  # CUDA graphs for while loops and conditionals too (XLA's default
      # command buffers take fusions and library calls only)
      XLA_FLAGS=--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL \
        bench "$OUT/bench/abcr_lean_graphs.json" experiments/stage2_u_lean.toml --robots 4096 ;;
    # conv_impl=fused (mjx_stairs/fused_encoder.py): the encoder alone against the others, then
    # (a), (b), (r), (c) with it
    bench4096-fused) mkdir -p "$OUT/bench"; python3 experiments/gpu/encoder_bench.py \
        --batch 49152 --out "$OUT/bench/encoder_fused.json" 2>&1 | grep -v warp
      bench "$OUT/bench/abcr_lean_fused.json" experiments/stage2_u_lean.toml \
        network.conv_impl=fused --robots 4096 ;;
    bench4096-fused-abcr) bench "$OUT/bench/abcr_lean_fused_sums.json" \
        experiments/stage2_u_lean.toml network.conv_impl=fused --robots 4096 ;;
    # XLA's Triton GEMM fusions off (every matmul to cuBLAS): the encoder alone, then (a), (c)
    bench4096-no-triton-gemm) mkdir -p "$OUT/bench"
      XLA_FLAGS=--xla_gpu_enable_triton_gemm=false python3 experiments/gpu/encoder_bench.py \
        --batch 49152 --out "$OUT/bench/encoder_no_triton_gemm.json" 2>&1 | grep -v warp
      XLA_FLAGS=--xla_gpu_enable_triton_gemm=false bench \
        "$OUT/bench/ac_lean_fused_no_triton_gemm.json" experiments/stage2_u_lean.toml \
        --robots 4096 --parts physics,train ;;
    # conv_impl=fused_bf16: the encoder alone against the others, then (a), (b), (r), (c)
    bench4096-bf16) mkdir -p "$OUT/bench"; python3 experiments/gpu/encoder_bench.py \
        --batch 49152 --out "$OUT/bench/encoder_bf16.json" 2>&1 | grep -v warp
      bench "$OUT/bench/abcr_lean_fused_bf16.json" experiments/stage2_u_lean.toml \
        network.conv_impl=fused_bf16 --robots 4096 ;;
    # (a)+(b)+(r)+(c) of stage2_u_lean.toml as it stands, at 4096 and 16 384 robots
    bench-lean) bench "$OUT/bench/abcr_lean.json" experiments/stage2_u_lean.toml \
        --robots 4096 16384 ;;
    # stage 2 with the lean settings and conv_impl=fused (TRAIN_ARGS=train.total_iterations=290
    # for the budget of the other lean runs), then evaluated in the reference physics
    # (FUSED_NAME names the run, stage2_u_lean_fused unless set; CONV_IMPL another conv_impl)
    stage2-lean-fused)
      name=${FUSED_NAME:-stage2_u_lean_fused}
      train "$name" experiments/stage2_u_lean.toml network.conv_impl=${CONV_IMPL:-fused} \
        train.experiment="$name"
      python3 -m mjx_stairs eval --checkpoint "/tmp/policies/$name.npz" \
        --robots 1000 --env $REFERENCE \
        --out "$OUT/$name/eval_reference_physics" 2>&1 | grep -v warp ;;
    # committed policies (EVAL_RUNS: names under experiments/results/) in the reference physics,
    # loaded as a robot runs them (float32 encoder), into $OUT/eval/<name>
    eval-committed)
      for name in ${EVAL_RUNS:-}; do
        python3 -m mjx_stairs eval --checkpoint "experiments/results/$name/policy.npz" \
          --robots 1000 --env $REFERENCE --out "$OUT/eval/$name" 2>&1 | grep -v warp
      done ;;
    # the optimised HLO of the encoder's forward + backward (fused and fused_bf16), to read the
    # profile's kernel names back to ops
    encoder-hlo) mkdir -p "$OUT/bench"
      for impl in fused fused_bf16; do
        python3 experiments/gpu/encoder_hlo.py --impl $impl \
          --out "$OUT/bench/encoder_hlo_$impl.txt" 2>&1 | grep -v warp
      done ;;
    bench16384-lean) bench "$OUT/bench/abc_lean_16384.json" experiments/stage2_u_lean.toml \
        --robots 16384 ;;
    stage2-lean) train stage2_u_lean experiments/stage2_u_lean.toml ;;
    stage1-lean) train stage1_lean experiments/stage1_lean.toml ;;
    stage2-lean-s1)  # stage 2 with the lean settings from the lean stage 1, then evaluated in the
      # reference physics
      s1=/tmp/policies/stage1_lean.npz; [ -f "$s1" ] || s1=.carry/stage1_lean/policy.npz
      train stage2_u_lean_s1 experiments/stage2_u_lean.toml init_from="$s1" \
        train.experiment=stage2_u_lean_s1
      python3 -m mjx_stairs eval --checkpoint /tmp/policies/stage2_u_lean_s1.npz --robots 1000 \
        --env $REFERENCE \
        --out "$OUT/stage2_u_lean_s1/eval_reference_physics" 2>&1 | grep -v warp ;;
    # the transfer matrix with the lean physics: each family's model trained as stage2_u_lean
    # (from the reference stage-1 policy; TRAIN_ARGS=train.total_iterations=290 for its budget),
    # then every model on every family at test levels 3-4, all evaluated in the reference physics
    straight-lean|l-shaped-lean|spiral-lean)
      fam=${step%-lean}; fam=${fam//-/_}
      train "$fam" "experiments/$fam.toml" $LEAN ;;
    transfer-lean)
      models=/tmp/transfer_models.toml; echo "[models]" > $models
      echo "u_shaped = \"experiments/results/stage2_u_lean/policy.npz\"" >> $models
      for fam in straight l_shaped spiral; do
        p=/tmp/policies/$fam.npz; [ -f "$p" ] || p=.carry/$fam/policy.npz
        echo "$fam = \"$p\"" >> $models
      done
      python3 -m mjx_stairs transfer-matrix --config $models --robots 1000 \
        --env $REFERENCE \
        --out "$OUT/transfer_lean" 2>&1 | grep -v warp ;;
    eval-lean)  # the lean-trained policy in the reference physics, and the reference policy in
      # the lean physics's collider (shins on, 5 line-search steps), 1000 robots per level
      p=/tmp/policies/stage2_u_lean.npz; [ -f "$p" ] || p=.carry/stage2_u_lean/policy.npz
      python3 -m mjx_stairs eval --checkpoint "$p" --robots 1000 \
        --env $REFERENCE \
        --out "$OUT/stage2_u_lean/eval_reference_physics" 2>&1 | grep -v warp
      python3 -m mjx_stairs eval --checkpoint experiments/results/stage2_u/policy.npz \
        --robots 1000 --env robot.terrain_contacts=nearest \
        --out "$OUT/stage2_u_lean/eval_stage2_u_in_nearest" 2>&1 | grep -v warp ;;
    report)  # the policies trained in this command (train copies them to /tmp/policies), else
      # the committed ones; REPORT_STAGE2 / REPORT_ABLATION name others; a missing ablation is
      # left out
      p2=experiments/results/stage2_u/policy.npz; pa=experiments/results/stage2_u_no_stall/policy.npz
      [ -f /tmp/policies/stage2_u.npz ] && p2=/tmp/policies/stage2_u.npz
      [ -f /tmp/policies/stage2_u_no_stall.npz ] && pa=/tmp/policies/stage2_u_no_stall.npz
      p2=${REPORT_STAGE2:-$p2}; pa=${REPORT_ABLATION:-$pa}
      abl=(); [ -f "$pa" ] && abl=(--ablation "$pa")
      python3 -m mjx_stairs exp1-report --stage2 "$p2" "${abl[@]}" --out "$OUT/exp1" 2>&1 \
        | grep -v warp ;;
    pack)  # only 8 files come back from a device command: one tar per output folder
      shopt -s nullglob; for d in "$OUT"/*/; do d=${d%/}; tar -C "$OUT" -cf "$d.tar" "$(basename "$d")" && rm -r "$d"; done
      ls -la "$OUT" ;;
    *) echo "unknown step $step"; exit 2 ;;
  esac
  echo "== $step done at $(( $(date +%s) - T0 ))s"
done
