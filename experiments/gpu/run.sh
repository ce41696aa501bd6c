#!/usr/bin/env bash
# One experiment step on a lent GPU host (no package index there): install the wheelhouse that
# ../shared/gpu/wheelhouse.sh built into .whl, then run the named steps, writing under $OUT.
#   bash experiments/gpu/run.sh DEADLINE_S STEP [STEP ...]
# Steps (end with pack, since only 8 files come back), each reproducing a published result
# (docs/results.md names the steps that produced each number; one-off exploratory steps are in
# git show 699f1d5:experiments/gpu/run.sh): stage1, stage2, ablation, stage2-final-goal, report
# (EXP1: Figure 2, RQ1, Figure 4), stage1-lean, stage2-lean, eval-lean (the lean physics and its
# check in the reference physics), straight-lean, l-shaped-lean, spiral-lean, transfer-lean
# (Tables 1-2), bench (make bench: the reference physics), bench-lean (stage2_u_lean.toml),
# scaling (bench --devices over the GPUs visible), two-processes (one process on two GPUs against
# two processes through jax.distributed), eval-committed (committed policies in the reference
# physics), code-suite (issue 23: the code suite baseline), pack. Each training step stops and
# checkpoints before DEADLINE_S seconds after the script started, and leaves in $OUT/<name>/ the
# policy, metrics, run facts and a packed state.npz (~11 MB for 4096 robots). To continue a run in
# the next command, copy that state.npz and metrics.jsonl to .carry/<name>/ (ignored by git) and
# carry .carry with .whl. Stage 2 starts from experiments/results/stage1/policy.npz: commit the
# stage-1 policy there first. TRAIN_ARGS (key=value ...) is added to every training command.
set -uo pipefail
T0=$(date +%s)
DEADLINE=$1; shift
if [ -z "${SKIP_INSTALL:-}" ]; then  # SKIP_INSTALL=1: the packages are already importable;
  # WHL=.whl_slim: another wheelhouse folder (one without the CUDA wheels the host has)
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site ${WHL:-.whl}/*.whl >/dev/null 2>&1 || { echo "wheel install failed"; exit 1; }
fi
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
left() { echo $(( DEADLINE - ($(date +%s) - T0) )); }
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
python3 -c "import jax, mujoco; print('jax', jax.__version__, jax.devices(), 'mujoco', mujoco.__version__)"

train() {  # train NAME TOML [overrides...]; resumes from .carry/NAME/state.npz when carried
  local name=$1 toml=$2; shift 2
  local budget=$(( $(left) - 25 ))  # TRAIN_BUDGET_S: less, to leave time for later steps
  [ -n "${TRAIN_BUDGET_S:-}" ] && [ "$TRAIN_BUDGET_S" -lt "$budget" ] && budget=$TRAIN_BUDGET_S
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

two_processes() {  # the same short stage-2 run: one process on GPUs 0,1, then two processes of
  # one GPU each through jax.distributed (NCCL; NCCL_NVLS_ENABLE stays as the host sets it: 0)
  local d="$OUT/two_processes" port=$(( 20000 + RANDOM % 20000 ))
  local args=(experiments/stage2_u_lean.toml train.log_dir=/tmp/runs train.progress=false
    train.console=false "train.num_envs=${TWO_ROBOTS:-8192}"
    "train.total_iterations=${TWO_ITERATIONS:-30}" train.checkpoint_every=0 publish_dir=
    ${TRAIN_ARGS:-})
  mkdir -p "$d"
  echo "== one process, two GPUs"
  python3 -m mjx_stairs train "${args[@]}" --run-dir /tmp/runs/one 2>&1 | grep -v warp
  echo "== two processes, one GPU each (coordinator localhost:$port)"
  for i in 0 1; do
    MJX_STAIRS_COORDINATOR=localhost:$port MJX_STAIRS_NUM_PROCESSES=2 MJX_STAIRS_PROCESS_ID=$i \
      JAX_LOCAL_DEVICE_IDS=$i python3 -m mjx_stairs train "${args[@]}" --run-dir /tmp/runs/two \
      > "$d/process_$i.log" 2>&1 &
  done
  wait
  grep -v warp "$d/process_0.log" | tail -3
  cp /tmp/runs/one/metrics.jsonl "$d/one_process.jsonl"
  cp /tmp/runs/two/metrics.jsonl "$d/two_processes.jsonl"
  python3 experiments/compare_runs.py /tmp/runs/one /tmp/runs/two --out "$d/compare.json"
}

for step in "$@"; do
  case $step in
    # EXP1 (docs/results.md sections 1-3): stage 1, stage 2 (waypoint goal), its no-stall
    # ablation, the paper's final-goal stage 2; report evaluates them (below)
    stage1) train stage1 experiments/stage1.toml ;;
    stage2) train stage2_u experiments/stage2_u.toml ;;
    ablation) train stage2_u_no_stall experiments/stage2_u_no_stall.toml ;;
    stage2-final-goal) train stage2_u_final_goal experiments/stage2_u_final_goal.toml ;;
    # the lean physics (stage1_lean.toml, stage2_u_lean.toml; TRAIN_ARGS=train.total_iterations=290
    # for stage 2's published budget) and its check: the lean-trained policy in the reference
    # physics, and the reference policy with the nearest-point collider, 1000 robots per level
    stage1-lean) train stage1_lean experiments/stage1_lean.toml ;;
    stage2-lean) train stage2_u_lean experiments/stage2_u_lean.toml ;;
    eval-lean)
      p=/tmp/policies/stage2_u_lean.npz; [ -f "$p" ] || p=.carry/stage2_u_lean/policy.npz
      python3 -m mjx_stairs eval --checkpoint "$p" --robots 1000 \
        --env $REFERENCE \
        --out "$OUT/stage2_u_lean/eval_reference_physics" 2>&1 | grep -v warp
      python3 -m mjx_stairs eval --checkpoint experiments/results/stage2_u/policy.npz \
        --robots 1000 --env robot.terrain_contacts=nearest \
        --out "$OUT/stage2_u_lean/eval_stage2_u_in_nearest" 2>&1 | grep -v warp ;;
    # the transfer matrix (Tables 1-2) with the lean physics: each family's model trained as
    # stage2_u_lean (from the reference stage-1 policy; TRAIN_ARGS=train.total_iterations=290 for
    # its budget), then every model on every family at test levels 3-4, all evaluated in the
    # reference physics
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
    # issue 24: the generalist (experiments/generalist.toml, from the stage-1 policy, evaluation
    # physics); resumes from .carry/generalist/. bench-generalist: its physics-only rate at 4096
    # robots on its own atlas, for the training rate the run logs
    generalist) train generalist experiments/generalist.toml ;;
    # the generalist (trained in this command, else carried) on the paper's test levels of the
    # four families, 1000 robots per level, up then down (GEN_DIRECTIONS), each cut at the deadline
    eval-generalist)
      p=/tmp/policies/generalist.npz; [ -f "$p" ] || p=.carry/generalist/policy.npz
      for dir in ${GEN_DIRECTIONS:-up down}; do
        [ "$(left)" -lt 90 ] && { echo "no time left for $dir"; break; }
        timeout $(( $(left) - 15 )) python3 -m mjx_stairs eval --checkpoint "$p" --robots 1000 \
          --family straight l_shaped u_shaped spiral --direction "$dir" \
          --out "$OUT/generalist_eval/$dir" 2>&1 | grep -v warp
      done ;;
    bench-generalist) bench "$OUT/bench/generalist_physics.json" experiments/generalist.toml \
        --robots 4096 --parts physics ;;
    # throughput: (a) physics, (b) env, (r) rollout, (c) training at 4096 and 16 384 robots, in the
    # reference physics (make bench) and with the lean settings of stage2_u_lean.toml
    bench) bench "$OUT/bench.json" experiments/stage2_u.toml --robots 4096 16384 ;;
    bench-lean) bench "$OUT/bench/abcr_lean.json" experiments/stage2_u_lean.toml \
        --robots 4096 16384 ;;
    # scale-out (issue 26): rows over one GPU and all N visible (SCALING_DEVICES=1,2,4 to
    # choose; each row compiles physics and the chunk, ~1.5 min), at 4096 robots per GPU (weak)
    # and 16 384 in all (strong), physics-only and training, each with its efficiency against
    # one GPU and the chunk's compile time
    scaling)
      n=$(nvidia-smi -L | wc -l)
      bench "$OUT/scaling/scaling_${n}gpu.json" experiments/stage2_u_lean.toml \
        --devices "${SCALING_DEVICES:-1,$n}" ;;
    two-processes) two_processes ;;
    # committed policies (EVAL_RUNS: names under experiments/results/) in the reference physics,
    # loaded as a robot runs them (float32 encoder), into $OUT/eval/<name>
    eval-committed)
      for name in ${EVAL_RUNS:-}; do
        python3 -m mjx_stairs eval --checkpoint "experiments/results/$name/policy.npz" \
          --robots 1000 --env $REFERENCE --out "$OUT/eval/$name" 2>&1 | grep -v warp
      done ;;
    # issue 23: the committed policies on the code suite (up and down, 1000 robots per case), and
    # eval --mesh against eval --family on U-shaped test level 3; CODE_SUITE_ARGS (e.g. --steps
    # suite --policies stage1,stage2_u) picks a part; finished files are kept when re-run
    code-suite)
      python3 experiments/gpu/code_suite.py "$OUT/code_suite" ${CODE_SUITE_ARGS:-} 2>&1 \
        | grep -v warp ;;
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
    pack)  # only 8 files of at most 16 MiB come back from a device command: one tar per output
      # folder, cut in 15 MiB parts (NAME.tar.00, .01: cat them back together) where larger
      shopt -s nullglob; for d in "$OUT"/*/; do d=${d%/}; tar -C "$OUT" -cf "$d.tar" "$(basename "$d")" && rm -r "$d"
        if [ "$(stat -c %s "$d.tar")" -gt 15728640 ]; then split -b 15M -d "$d.tar" "$d.tar." && rm "$d.tar"; fi
      done
      ls -la "$OUT" ;;
    *) echo "unknown step $step"; exit 2 ;;
  esac
  echo "== $step done at $(( $(date +%s) - T0 ))s"
done
