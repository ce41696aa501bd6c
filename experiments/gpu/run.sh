#!/usr/bin/env bash
# One experiment step on a lent GPU host (no package index there): install the wheelhouse that
# ../shared/gpu/wheelhouse.sh built into .whl, then run the named steps, writing under $OUT.
#   bash experiments/gpu/run.sh DEADLINE_S STEP [STEP ...]
# On a host of several GPUs a step argument gpuN:TOKEN,TOKEN,... runs its steps in turn on GPU N
# alone (gpuN+M:...: on GPUs N and M together), in the background beside the other arguments (a
# TOKEN KEY=VALUE sets a variable for the group's later steps), e.g. gpu0:SEED=0,paper
# gpu1:SEED=1,paper pack: device time is counted
# per machine, so two GPUs train two runs for the price of one (gpus: what a group sees).
# Steps (end with pack, since only 8 files come back), each reproducing a published result
# (docs/results.md names the steps that produced each number; one-off exploratory steps are in
# git show 699f1d5:experiments/gpu/run.sh; the one-off session scripts folded into the steps below
# are in git show b53571c:experiments/gpu/, e.g. session_eval4.sh): stage1, stage2, ablation,
# stage2-final-goal, report (EXP1: Figure 2, RQ1, Figure 4), stage1-lean, stage2-lean, eval-lean
# (the lean physics and its check in the reference physics), straight-lean, l-shaped-lean,
# spiral-lean, transfer-lean (Tables 1-2), generalist, generalist-history, generalist-lean,
# generalist-lean-finish, train-toml, eval-generalist,
# bench-generalist (issue 24), time-to-climber (issue 22),
# bench (make bench: the reference physics), bench-lean (stage2_u_lean.toml), scaling (bench
# --devices over the GPUs visible), two-processes (one process on two GPUs against two processes
# through jax.distributed), eval-committed (committed policies in the reference physics), code-suite
# (issue 23: the code suite baseline), fidelity, fidelity-x64, bench-colliders (issue 19: MJX
# physics options against the ground truth, their speed), transfer-eval, rq1-eval (the transfer
# matrix and the RQ1 policies in the evaluation physics), paper, paper-no-stall, eval-paper,
# eval-paper-committed
# (issue 21: stage 2 as the paper has it, SEED=N), straight-paper, l-shaped-paper, spiral-paper,
# transfer-paper (RQ2 in the paper's setting), eval-names (named policies at 1000 robots; EVAL_SEED=N: the resets' seed, 0 unless set), bench-options (issue 22: the speed of
# physics between columns and the evaluation physics), stage2-physics, eval-physics (issue 22:
# stage 2 trained in one physics option, judged in the evaluation physics), warp (MuJoCo Warp's
# speed and success), wait-policy (a group waits for a run another GPU trains), gpus, pack; and
# on the host's CPUs beside the
# GPU steps: ground-truth (issue 19: CPU MuJoCo on box stairs), sim2sim, sim2sim-damping01,
# sim2sim-latency20 (issue 25: the sim-to-sim table of docs/deploy.md), stage2-robot and
# sim2sim-policy (issue 25: stage 2 for a real Go2's joints, a policy's sim-to-sim table with MJX
# columns of the same starts), stage2-robot-corner, stage2-robot-history, stage2-robot-latency20
# and delay-grid (issue 25: the damping x delay corner, a policy on the whole grid in MuJoCo
# itself). Each training step stops and
# checkpoints before DEADLINE_S seconds after the script started, and leaves in $OUT/<name>/ the
# policy, metrics, run facts and a packed state.npz (compressed, observation buffer zeroed: ~6 MB
# for the generalist's 4096 robots). To continue a run in
# the next command on the same warm machine, run the same step again: it resumes from the state
# and whole curve it left in $KEEP/<name>/ (FRESH=1 starts over); on a fresh machine, copy that
# state.npz and metrics.jsonl to .carry/<name>/ (ignored by git) and carry .carry with .whl.
# The tracked tree alone passed the 64 MiB a call carries (67.7 MB, 2026-11-28): before a call,
# experiments/gpu/slim_tree.sh out [RUN ...] holds docs/ and the results no step needs outside it.
# Stage 2 starts from experiments/results/stage1/policy.npz: commit the stage-1 policy there
# first. TRAIN_ARGS (key=value ...) is added to every training command. The CPU
# steps start a background job and return at once; pack (or the end of the script) waits for them
# until 10 s before the deadline and copies what they wrote to $OUT/<name>/.
set -uo pipefail
T0=$(date +%s)
DEADLINE=$1; shift
if [ -z "${SKIP_INSTALL:-}" ]; then  # SKIP_INSTALL=1: the packages are already importable;
  # WHL=.whl_slim: another wheelhouse folder (one without the CUDA wheels the host has)
  # (.whl_min, 21 MB: .whl_slim plus glfw and pyopengl, which `import mujoco` loads; enough for
  # training, eval and the CPU MuJoCo steps but sim2sim's onnxruntime: with the tracked tree at
  # ~34 MB it fits the 64 MiB a call carries, where the 34 MB .whl_train no longer does;
  # .whl_lean, 18.5 MB: .whl_min without pyopengl and glfw, which `import mujoco` only tries
  # (training, eval and the code suite ran without them, 2026-11-27), for a call that carries a
  # state too: with the tree at ~41 MB, .whl_lean plus a 5.7 MB compressed state fit)
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site ${WHL:-.whl}/*.whl >/dev/null 2>&1 || { echo "wheel install failed"; exit 1; }
fi
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
left() { echo $(( DEADLINE - ($(date +%s) - T0) )); }
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
python3 -c "import jax, mujoco; print('jax', jax.__version__, jax.devices(), 'mujoco', mujoco.__version__)"

# Where the trainings log (RUNS) and where each keeps its newest state and whole curve for the
# next command on the same warm machine (KEEP; a fresh machine starts empty)
RUNS=${RUNS:-/tmp/runs}
KEEP=${KEEP:-/tmp/keep}

train() {  # train NAME TOML [overrides...]; resumes from $KEEP/NAME/ (what an earlier command on
  # this machine left), else from .carry/NAME/state.npz when carried (FRESH=1: start over). The
  # kept state first: a carried .carry stays on a warm machine after the command that carried it,
  # and would take the run back to where it started
  local name=$1 toml=$2; shift 2
  # TRAIN_BUDGET_S: less, to leave time for later steps. The margin covers what runs outside the
  # trainer's budget (atlas build, publish, ONNX export, the state copy): 25 s, 60 s for a large
  # atlas (generalist: its state missed a 570 s command's pack by ~20 s at 25, 2026-11-27)
  local budget=$(( $(left) - ${TRAIN_MARGIN_S:-25} ))
  [ -n "${TRAIN_BUDGET_S:-}" ] && [ "$TRAIN_BUDGET_S" -lt "$budget" ] && budget=$TRAIN_BUDGET_S
  local resume=() prev=""  # where the run goes on from: kept here, else carried, else nowhere
  # RESUME_FROM (a folder holding state.npz): where a run starts when nothing of its own is kept
  # or carried, e.g. a variant resumed from another run's carried state (one state, two runs)
  [ -z "${FRESH:-}" ] && for prev in "$KEEP/$name" ".carry/$name" ${RESUME_FROM:-} ""; do
    [ -f "$prev/state.npz" ] && break
  done
  [ -n "$prev" ] && resume=(--resume "$prev/state.npz")
  echo "== $name: budget ${budget}s ${resume[*]}"
  python3 -m mjx_stairs train "$toml" train.log_dir="$RUNS" train.progress=false \
    train.console=false train.checkpoint_env=packed train.time_budget_s=$budget \
    publish_dir="$OUT/$name" ${TRAIN_ARGS:-} "$@" "${resume[@]}" 2>&1 | grep -v -e "warp" -e "^$"
  local rc=${PIPESTATUS[0]}
  if [ "$rc" != 0 ]; then  # e.g. a config error, or the trainer stopping on a diverged update
    echo "== $name: train failed ($rc); nothing published, no state copied"; return 0
  fi
  local run; run=$(ls -td "$RUNS"/${name}__* | head -1)
  cp "$(ls "$run"/checkpoints/state_*.npz | tail -1)" "$OUT/$name/state.npz"
  mkdir -p /tmp/policies && cp "$OUT/$name/policy.npz" "/tmp/policies/$name.npz"  # for report
  if [ -n "$prev" ] && [ -f "$prev/metrics.jsonl" ]; then  # the whole curve across commands
    cat "$prev/metrics.jsonl" "$OUT/$name/metrics.jsonl" > "$OUT/$name/m.tmp" \
      && mv "$OUT/$name/m.tmp" "$OUT/$name/metrics.jsonl"
  fi
  mkdir -p "$KEEP/$name" && cp "$OUT/$name/state.npz" "$OUT/$name/metrics.jsonl" "$KEEP/$name/"
  # The copy that comes back: compressed, its observation buffer zeroed (the generalist's 15.7 ->
  # 5.8 MB), so that four runs' states fit the 64 MiB one call returns (with three or four runs
  # one state was left out, 2026-11-28); carried back, the run's first step acts on zeros
  python3 - "$OUT/$name/state.npz" <<'PY' || echo "== $name: state left uncompressed"
import sys
from mjx_stairs.rl.checkpoint import compact
compact(sys.argv[1], sys.argv[1], zero=(".env_state['obs']",))
PY
  python3 - "$OUT/$name/metrics.jsonl" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
def g(r, k):  # a NaN is logged as null: show it as nan, not as a crash
    v = r.get(k, 0)
    return float("nan") if v is None else v
for r in rows[:: max(1, len(rows) // 12)] + rows[-1:]:
    print(f"it {r['iteration']:5d} steps {r['env_steps']/1e6:7.1f}M  {r['perf/steps_per_s']/1e3:6.0f}k/s "
          f"ret {g(r, 'episode/return'):7.2f} level {g(r, 'level'):5.2f} "
          f"top {g(r, 'at_top'):.2f} succ {g(r, 'success'):.3f} "
          f"term {g(r, 'terminated'):.4f} nan_reset {g(r, 'nan_reset'):.4f} lr {g(r, 'opt/lr'):.1e}")
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

# Background jobs on the host's CPUs (the ground truth, sim-to-sim) write under $BG, outside
# $OUT, and are copied to $OUT by collect.
BG=/tmp/bg.$$

trained_policy() {  # trained_policy NAME: the policy of run NAME trained in this command, else
  # the one carried in .carry/NAME/
  local p=/tmp/policies/$1.npz; [ -f "$p" ] || p=.carry/$1/policy.npz; echo "$p"
}

any_policy() {  # any_policy NAME: trained_policy NAME, else experiments/results/NAME/ (committed)
  local p; p=$(trained_policy "$1"); [ -f "$p" ] || p=experiments/results/$1/policy.npz; echo "$p"
}

background() {  # background NAME CMD...: CMD with JAX_PLATFORMS=cpu, in the background, stopped
  # 20 s before the deadline; it writes $BG/NAME/, its log goes to $BG/NAME.log
  local name=$1; shift
  local budget=$(( $(left) - 20 ))
  [ "$budget" -lt 60 ] && { echo "no time left for $name"; return; }
  mkdir -p "$BG/$name"
  ( JAX_PLATFORMS=cpu timeout "$budget" "$@" > "$BG/$name.log" 2>&1 & echo $! > "$BG/$name.pid" )
  echo "== $name: on the CPUs in the background, ${budget}s, log $name.log"
}

collect() {  # wait for the background jobs (until 10 s before the deadline), then copy each one's
  # folder and log to $OUT/NAME/ and $OUT/NAME.log, finished or not (files are written whole)
  [ -d "$BG" ] || return 0
  local f p name alive
  while [ "$(left)" -gt 10 ]; do
    alive=0
    for f in $(find "$BG" -name '*.pid'); do kill -0 "$(cat "$f")" 2>/dev/null && alive=1; done
    [ "$alive" = 0 ] && break
    sleep 5
  done
  for f in $(find "$BG" -name '*.pid'); do
    name=${f#"$BG"/}; name=${name%.pid}; p=$(cat "$f")
    kill -0 "$p" 2>/dev/null && echo "$name still running: copying what it wrote"
    mkdir -p "$OUT/$name" && cp -r "$BG/$name/." "$OUT/$name/" \
      && cp "$BG/$name.log" "$OUT/$name.log"
    rm -f "$OUT/$name"/policy.onnx* "$f"  # sim2sim's ONNX export is committed
    echo "== $name collected at $(( $(date +%s) - T0 ))s"; tail -3 "$OUT/$name.log"
  done
}

fidelity_mjx() {  # fidelity_mjx OPTION [x64]: fidelity.py mjx (1000 robots per cell) into the
  # option's published folder under $OUT/ground_truth/, FIDELITY_CELLS (default: every cell)
  local opt=$1 x64=${2:-} dir env=() cells=${FIDELITY_CELLS:-}
  case $opt in
    reference|lean|nearest_full) dir=mjx ;; columns|columns_converged) dir=mjx_columns ;;
    evaluation) dir=mjx_eval ;; *) dir=mjx_$opt ;;
  esac
  [ -n "$x64" ] && { dir=mjx_x64; env=(JAX_ENABLE_X64=1); }
  [ "$(left)" -lt 90 ] && { echo "no time left for $opt"; return; }
  mkdir -p "$OUT/ground_truth"
  env "${env[@]}" timeout $(( $(left) - 15 )) python3 experiments/gpu/fidelity.py mjx \
    "$OUT/ground_truth/$dir" --options "$opt" --cells "${cells//+/,}" 2>&1 | grep -v warp \
    | tee -a "$OUT/ground_truth/$dir.log"
}

option_overrides() {  # option_overrides NAME: fidelity.py's physics option NAME as training overrides
  python3 -c "import sys; sys.path.insert(0, 'experiments/gpu'); import fidelity; \
print(' '.join('env.' + o for o in fidelity.OPTIONS['$1']))"
}

paper_eval() {  # paper_eval POLICY NAME RADII...: POLICY on the U test levels, 1000 robots, the
  # evaluation physics, at each success radius, into $OUT/paper_eval/NAME/success_<R>m/
  local p=$1 name=$2 r; shift 2
  for r in "$@"; do
    [ "$(left)" -lt 90 ] && { echo "no time left for $name at $r m"; break; }
    timeout $(( $(left) - 15 )) python3 -m mjx_stairs eval --checkpoint "$p" \
      --family u_shaped --robots 1000 --env "success_distance=$r" \
      --out "$OUT/paper_eval/$name/success_${r}m" 2>&1 | grep -v warp
  done
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
      CUDA_VISIBLE_DEVICES=$i timeout "${TWO_TIMEOUT_S:-240}" python3 -m mjx_stairs train \
      "${args[@]}" --run-dir /tmp/runs/two \
      > "$d/process_$i.log" 2>&1 &
  done
  wait
  grep -v warp "$d/process_0.log" | tail -3
  cp /tmp/runs/one/metrics.jsonl "$d/one_process.jsonl"
  cp /tmp/runs/two/metrics.jsonl "$d/two_processes.jsonl"
  python3 experiments/compare_runs.py /tmp/runs/one /tmp/runs/two --out "$d/compare.json"
}

paper_models() {  # paper_models FILE: the [models] of the paper-setting transfer matrix, each
  # committed, else trained in this command, else carried
  local fam n p; echo "[models]" > "$1"
  for fam in u_shaped straight l_shaped spiral; do
    n=${fam}_paper; [ $fam = u_shaped ] && n=stage2_u_paper
    p=experiments/results/$n/policy.npz; [ -f "$p" ] || p=$(trained_policy "$n")
    echo "$fam = \"$p\"" >> "$1"
  done
}

# an evaluation of named policies (EVAL_NAMES a+b: trained here, carried, else committed) on
# EVAL_FAMILIES (a+b, default u_shaped), EVAL_DIRECTION (up), 1000 robots, the evaluation
# physics, into $OUT/eval/<name>[_<direction>][_<EVAL_TAG>]/<families joined by ->/ (one folder
# per family set: two groups judging one policy on different families, gpu0 u_shaped and gpu1
# spiral, wrote one folder, the second's results over the first's, 2026-11-28); EVAL_ENV (a+b of
# key=value under [env], e.g. robot.joint_damping=2.0+robot.implicit_damping=true) changes the
# robot judged
eval_names() {
  local name p env=() out
  [ -n "${EVAL_ENV:-}" ] && env=(--env ${EVAL_ENV//+/ })
  for name in ${EVAL_NAMES//+/ }; do
    p=$(any_policy "$name")
    out=$OUT/eval/$name${EVAL_DIRECTION:+_$EVAL_DIRECTION}${EVAL_TAG:+_$EVAL_TAG}${EVAL_SEED:+_seed$EVAL_SEED}/${EVAL_FAMILIES//+/-}
    [ "$(left)" -lt 90 ] && { echo "no time left for $name"; break; }
    timeout $(( $(left) - 15 )) python3 -m mjx_stairs eval --checkpoint "$p" --robots 1000 \
      --family ${EVAL_FAMILIES//+/ } --direction "${EVAL_DIRECTION:-up}" "${env[@]}" \
      --seed "${EVAL_SEED:-0}" --out "$out" 2>&1 | grep -v warp
  done
}

wait_policy() {  # wait_policy NAME: wait (until 60 s before the deadline) for run NAME, trained
  # on another GPU in this command, to publish: /tmp/policies/NAME.npz written after this command
  # started (an older one from an earlier command on the warm machine does not count)
  local f=/tmp/policies/$1.npz
  fresh() { [ -f "$f" ] && [ "$(stat -c %Y "$f")" -ge "$T0" ]; }
  while ! fresh && [ "$(left)" -gt 60 ]; do sleep 5; done
  if fresh; then sleep 2; echo "== $f is in"; else echo "no new $f in time"; fi
}

GPU_JOBS=()
gpu_group() {  # gpuN:TOKEN,...: on GPU N alone (CUDA_VISIBLE_DEVICES=N), in the background beside
  # the other groups, each TOKEN in turn: KEY=VALUE sets a variable for the group's later steps
  # (SEED=2, TRAIN_ARGS=...), anything else is a step. Its log: $OUT/logs/gpuN.log. gpuN+M:...:
  # on GPUs N and M together (a training splits its robots over them)
  local n=${1%%:*} tokens=${1#*:} count g
  n=${n#gpu}; count=$(nvidia-smi -L 2>/dev/null | wc -l)
  for g in ${n//+/ }; do
    if [ "$count" -gt 0 ] && [ "$g" -ge "$count" ]; then echo "no GPU $g on this host ($count)"; return; fi
  done
  mkdir -p "$OUT/logs"
  (
    export CUDA_VISIBLE_DEVICES=${n//+/,}
    IFS=, read -ra toks <<< "$tokens"
    for t in "${toks[@]}"; do
      case $t in
        *=*) export "${t?}" ;;
        *) run_step "$t"; echo "== gpu$n: $t done at $(( $(date +%s) - T0 ))s" ;;
      esac
    done
  ) > "$OUT/logs/gpu$n.log" 2>&1 &
  GPU_JOBS+=($!)
  echo "== gpu$n: $tokens in the background, log logs/gpu$n.log"
}

wait_gpu_groups() {  # wait for the GPU groups (until 10 s before the deadline); show each log's end
  local p alive f
  [ ${#GPU_JOBS[@]} -eq 0 ] && return 0
  while [ "$(left)" -gt 10 ]; do
    alive=0
    for p in "${GPU_JOBS[@]}"; do kill -0 "$p" 2>/dev/null && alive=1; done
    [ "$alive" = 0 ] && break
    sleep 5
  done
  for p in "${GPU_JOBS[@]}"; do kill -0 "$p" 2>/dev/null && echo "GPU group $p still running"; done
  GPU_JOBS=()
  for f in "$OUT"/logs/gpu*.log; do echo "== ${f##*/}:"; grep -v warp "$f" | tail -25; done
}

run_step() {
  local step=$1
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
      p=$(trained_policy stage2_u_lean)
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
        p=$(trained_policy "$fam")
        echo "$fam = \"$p\"" >> $models
      done
      python3 -m mjx_stairs transfer-matrix --config $models --robots 1000 \
        --env $REFERENCE \
        --out "$OUT/transfer_lean" 2>&1 | grep -v warp ;;
    # issue 24: the generalist (experiments/generalist.toml, from the stage-1 policy, evaluation
    # physics); resumes from .carry/generalist/. bench-generalist: its physics-only rate at 4096
    # robots on its own atlas, for the training rate the run logs
    # (generalist-history: the same with 3 steps of observation history)
    generalist|generalist-history) TRAIN_TOML=experiments/${step//-/_}.toml run_step train-toml ;;
    # the generalist in the lean physics (generalist_lean.toml, resumed from .carry/generalist_lean/),
    # then generalist-lean-finish: the same run resumed in the evaluation physics (float32
    # encoder) for the rest of its command (TRAIN_BUDGET_S to bound it)
    generalist-lean) TRAIN_MARGIN_S=${TRAIN_MARGIN_S:-60} train generalist_lean \
        experiments/generalist_lean.toml ;;
    generalist-lean-finish) TRAIN_MARGIN_S=${TRAIN_MARGIN_S:-60} train generalist_lean \
        experiments/generalist_lean.toml env.robot.physics=evaluation network.conv_impl=auto ;;
    # any experiment file whose train.experiment is its file name (TRAIN_TOML=experiments/X.toml,
    # resumed as every training is), e.g. the generalist's variants generalist_std05, generalist_noent
    train-toml) n=$(basename "${TRAIN_TOML:?TRAIN_TOML names an experiment file}" .toml)
      TRAIN_MARGIN_S=${TRAIN_MARGIN_S:-60} train "$n" "$TRAIN_TOML" ;;
    # the generalist (GEN_POLICY, else the one trained in this command, else carried) on the
    # paper's test levels of the four families, 1000 robots per level, up then down
    # (GEN_DIRECTIONS), each cut at the deadline
    eval-generalist)
      p=${GEN_POLICY:-$(trained_policy generalist)}
      for dir in ${GEN_DIRECTIONS:-up down}; do
        [ "$(left)" -lt 90 ] && { echo "no time left for $dir"; break; }
        timeout $(( $(left) - 15 )) python3 -m mjx_stairs eval --checkpoint "$p" --robots 1000 \
          --family straight l_shaped u_shaped spiral --direction "$dir" \
          --out "$OUT/generalist_eval/$dir" 2>&1 | grep -v warp
      done ;;
    # issue 22: from nothing to a stage-2 climber, timed end to end (experiments/gpu/
    # time_to_climber.py: stage 1 TTC_STAGE1 iterations, stage 2 TTC_STAGE2, each its own
    # process, compile included; then the U test levels, 1000 robots, evaluation physics), with
    # the lean configs (TTC_CONFIGS "stage1.toml+stage2.toml" for others) into $OUT/time_to_climber/
    time-to-climber)
      cfg=${TTC_CONFIGS:-experiments/stage1_lean.toml+experiments/stage2_u_lean.toml}
      timeout $(( $(left) - 15 )) python3 experiments/gpu/time_to_climber.py \
        "$OUT/time_to_climber${TTC_NAME:+_$TTC_NAME}" --stage1 "${cfg%%+*}" --stage2 "${cfg##*+}" \
        --stage1-iterations "${TTC_STAGE1:-600}" --stage2-iterations "${TTC_STAGE2:-290}" \
        --log-dir /tmp/ttc_runs --set network.conv_impl=fused_bf16 ${TRAIN_ARGS:-} 2>&1 \
        | grep -v warp ;;
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
    # issue 22: the physics-only and training rates (4096 robots, stage2_u.toml's U atlas) of
    # the candidate physics between "columns" and the evaluation physics (fidelity.py's
    # columns_n2, columns_n3, columns_n4, columns_noshin_n3; BENCH_OPTIONS to choose), beside
    # the evaluation physics itself and evaluation_exit (issue 19's sunk-exit rule: its cost);
    # their fidelity: step fidelity with FIDELITY_OPTIONS=...
    bench-options)
      for opt in ${BENCH_OPTIONS:-evaluation evaluation_exit columns_n2 columns_n3 columns_n4 columns_noshin_n3}; do
        [ "$(left)" -lt 120 ] && { echo "no time left for $opt"; break; }
        ov=$(option_overrides "$opt")
        timeout $(( $(left) - 15 )) python3 -m mjx_stairs bench --config experiments/stage2_u.toml \
          --robots 4096 --parts physics,train $ov --out "$OUT/bench/options_$opt.json" 2>&1 \
          | grep -v warp
      done ;;
    # issue 22, one physics option at a time: stage 2 (stage2_u.toml, PHYSICS_ITERATIONS, default
    # 290 as stage2_u was published) trained in fidelity.py's option PHYSICS_OPTION
    # (evaluation_exit: the evaluation physics itself, the baseline; columns_n4, columns_n4_dt10,
    # ...), seed SEED, as stage2_u_<option>_s<SEED>; eval-physics: every such policy trained in
    # this command (else carried) on the U-shaped and straight `extended` levels and the `code`
    # suite (up and down, 30 s), 1000 robots, in the evaluation physics (5 ms steps, the policy's
    # 50 Hz), into $OUT/physics_eval/<name>/; a part already there is skipped
    stage2-physics)
      opt=${PHYSICS_OPTION:?PHYSICS_OPTION names a fidelity.py option}
      name=stage2_u_${opt}_s${SEED:-0}
      # shellcheck disable=SC2046
      train "$name" experiments/stage2_u.toml $(option_overrides "$opt") \
        "train.total_iterations=${PHYSICS_ITERATIONS:-290}" "train.seed=${SEED:-0}" \
        "train.experiment=$name" ;;
    eval-physics)
      shopt -s nullglob
      for p in /tmp/policies/stage2_u_*_s[0-9]*.npz .carry/stage2_u_*_s[0-9]*/policy.npz; do
        name=$(basename "$p" .npz); [ "$name" = policy ] && name=$(basename "$(dirname "$p")")
        case $name in stage2_u_paper*) continue ;; esac
        # PHYSICS_NAMES (a+b): only those (two GPUs judging two policies)
        [ -n "${PHYSICS_NAMES:-}" ] && [[ "+$PHYSICS_NAMES+" != *"+$name+"* ]] && continue
        d="$OUT/physics_eval/$name"; mkdir -p "$d"
        for fam in u_shaped straight; do
          [ -f "$d/$fam/results.json" ] && continue
          [ "$(left)" -lt 90 ] && { echo "no time left for $name $fam"; break 2; }
          timeout $(( $(left) - 15 )) python3 -m mjx_stairs eval --checkpoint "$p" --family $fam \
            --schedule extended --robots 1000 --out "$d/$fam" 2>&1 | grep -v warp
        done
        [ -f "$d/code.json" ] || [ "${PHYSICS_CODE:-1}" = 0 ] && continue  # 0: extended only
        [ "$(left)" -lt 240 ] && { echo "no time left for $name code"; break; }
        timeout $(( $(left) - 15 )) python3 -m mjx_stairs eval --checkpoint "$p" --suite code \
          --robots 1000 --episode-s 30 --out "$d/code.json" 2>&1 | grep -v warp
      done ;;
    # committed policies (EVAL_RUNS: names under experiments/results/) in the reference physics,
    # loaded as a robot runs them (float32 encoder), into $OUT/eval/<name>
    eval-names) EVAL_FAMILIES=${EVAL_FAMILIES:-u_shaped} eval_names ;;
    eval-committed)
      for name in ${EVAL_RUNS:-}; do
        python3 -m mjx_stairs eval --checkpoint "experiments/results/$name/policy.npz" \
          --robots 1000 --env $REFERENCE --out "$OUT/eval/$name" 2>&1 | grep -v warp
      done ;;
    # issue 23: the committed policies on the code suite (up and down, 1000 robots per case), and
    # eval --mesh against eval --family on U-shaped test level 3; CODE_SUITE_ARGS (e.g. --steps
    # suite --policies stage1,stage2_u) picks a part; finished files are kept when re-run. The
    # published table (docs/results.md section 7): CODE_SUITE_ARGS="--steps suite --policies
    # stage2_u", then "--steps suite,mesh --policies stage2_u_lean,stage1"; CODE_MESH (a+b):
    # the mesh step for those policies (NAME=FILE as CODE_POLICIES)
    code-suite)
      args=${CODE_SUITE_ARGS:-}; args=(${args//+/ })  # CODE_SUITE_ARGS: a+b, as a gpuN:
      # token holds no space (unsplit, --env+k=v reached argparse whole, 2026-11-29);
      # CODE_POLICIES (a+b, NAME=FILE for an uncommitted one; a gpuN: token cannot hold a
      # comma): the suite step for those policies only
      # both: one --steps suite,mesh (a second --steps flag replaced the first: 2026-11-27's
      # CODE_POLICIES=generalist_robot,CODE_MESH=generalist_robot ran the mesh step only)
      steps=(); [ -n "${CODE_POLICIES:-}" ] && steps+=(suite); [ -n "${CODE_MESH:-}" ] && steps+=(mesh)
      [ ${#steps[@]} -gt 0 ] && args+=(--steps "$(IFS=,; echo "${steps[*]}")")
      [ -n "${CODE_POLICIES:-}" ] && args+=(--policies "${CODE_POLICIES//+/,}")
      [ -n "${CODE_MESH:-}" ] && args+=(--mesh-policies "${CODE_MESH//+/,}")
      # CODE_ENV (a+b, as EVAL_ENV): the env overrides; CODE_SUITE_ARGS=--env=a+b split into
      # --env=a b, and argparse refused b (2026-11-30, a GPU's half call lost)
      [ -n "${CODE_ENV:-}" ] && args+=(--env ${CODE_ENV//+/ })
      [ "$(left)" -lt 90 ] && { echo "no time left for $step"; return; }
      timeout $(( $(left) - 15 )) python3 experiments/gpu/code_suite.py "$OUT/code_suite" \
        "${args[@]}" 2>&1 | grep -v warp
      # a suite cut at the deadline writes nothing (a 235 s command with the install: 2026-11-28)
      [ "${PIPESTATUS[0]}" = 124 ] && echo "== code-suite: cut at the deadline, nothing written";;
    # issue 19 (docs/results.md section 5b): the published policies in MJX physics options on the
    # 36 fidelity cells, into the published folders under $OUT/ground_truth/. FIDELITY_OPTIONS
    # (default evaluation: mjx_eval/, section 1's evaluation-physics row and the fidelity table's
    # last row; columns,columns_converged: mjx_columns/; reference,lean,nearest_full: mjx/;
    # mjx_converged: mjx_converged/), FIDELITY_CELLS (indices into fidelity.py's CELLS, a+b; default
    # every one; the published float32 columns_converged: 8,9,15,16,17). fidelity-x64: the same
    # with the physics in float64 (JAX_ENABLE_X64=1; default columns_converged on every cell,
    # mjx_x64/). fidelity_table.py (no GPU) rebuilds ground_truth/table.md from the folders
    fidelity|fidelity-x64)
      x64=; opts=${FIDELITY_OPTIONS:-evaluation}
      [ "$step" = fidelity-x64 ] && { x64=1; opts=${FIDELITY_OPTIONS:-columns_converged}; }
      for opt in ${opts//,/ }; do fidelity_mjx "$opt" $x64; done ;;
    # the ground truth of section 5b: CPU MuJoCo on box stairs, 1000 episodes per cell
    # (ground_truth/gt1000/), on the host's CPUs beside the GPU steps. Longer than one command:
    # GT_CELLS splits it (published: 7,8,9,14,15,16,17 beside fidelity with FIDELITY_OPTIONS=
    # columns,columns_converged and bench-colliders, then 0,1,2,3,4,5,6,10,11,12,13 beside
    # fidelity-x64 and fidelity with FIDELITY_OPTIONS=columns_converged
    # FIDELITY_CELLS=8,9,15,16,17); CPU_WORKERS (14 of 16 cores)
    ground-truth)
      # gt1000/ was published at go2.xml's contact (0.02 s): --timeconst 0 reproduces it
      # (GT_TIMECONST=0.01: today's evaluation physics, gt_supported_stiff1000/'s contact)
      background ground_truth/gt1000 python3 experiments/gpu/fidelity.py gt \
        "$BG/ground_truth/gt1000" --robots 1000 --workers "${CPU_WORKERS:-14}" \
        --cells "${GT_CELLS:-}" --timeconst "${GT_TIMECONST:-0}" ;;
    # section 5b's speed: physics-only env steps/s of the reference and lean physics, each with its
    # own collider and with the columns collider, 4096 robots (stage2_u_lean.toml), 3 repeats,
    # into $OUT/ground_truth/bench_colliders/
    bench-colliders)
      for p in "reference" "reference env.robot.terrain_contacts=columns" "lean" \
               "lean env.robot.terrain_contacts=columns"; do
        [ "$(left)" -lt 115 ] && { echo "no time left for $p"; break; }
        read -r phys extra <<< "$p"; name=$(echo "$p" | tr ' =.' '___')
        mkdir -p "$OUT/ground_truth/bench_colliders"
        timeout 100 python3 -m mjx_stairs bench --config experiments/stage2_u_lean.toml \
          --robots 4096 --parts physics --repeats 3 "env.robot.physics=$phys" $extra \
          --out "$OUT/ground_truth/bench_colliders/bench_$name.json" 2>&1 | grep -v warp
      done ;;
    # issue 25, docs/deploy.md's sim-to-sim table: stage2_u's committed ONNX export
    # (experiments/results/sim2sim/stage2_u/) in CPU MuJoCo with the full-geometry Go2 on the
    # U-shaped test levels, on the host's CPUs beside the GPU steps, into $OUT/sim2sim/<folder>:
    # sim2sim (the description's joint damping 2, 200 episodes per level: stage2_u/), sim2sim-
    # damping01 (training's damping 0.1 in go2_full_damping01.xml, a copy of go2_full.xml written
    # beside it, untracked: stage2_u_damping01/),
    # sim2sim-latency20 (20 ms action latency: stage2_u_latency20/), 50 episodes per level
    # (S2S_EPISODES). S2S_WORKERS: 14 (published: 7 each for two at once). The MJX column comes
    # from the committed fidelity runs (reference physics for sim2sim, evaluation physics for the
    # others). The wheelhouse needs onnxruntime (../shared/gpu/wheelhouse.sh DIR
    # onnxruntime==1.32.0)
    sim2sim|sim2sim-damping01|sim2sim-latency20)
      s2s=(--mjx-json experiments/results/ground_truth/mjx_eval/mjx_evaluation.json --chunk 5)
      case $step in
        sim2sim) name=stage2_u; eps=200
          s2s=(--mjx-json experiments/results/ground_truth/mjx/mjx_reference.json) ;;
        sim2sim-damping01) name=stage2_u_damping01; eps=50
          sed 's/damping="2"/damping="0.1"/' mjx_stairs/sim/assets/go2_full.xml \
            > mjx_stairs/sim/assets/go2_full_damping01.xml
          s2s+=(--robot mjx_stairs/sim/assets/go2_full_damping01.xml) ;;
        sim2sim-latency20) name=stage2_u_latency20; eps=50; s2s+=(--latency-ms 20) ;;
      esac
      mkdir -p "$BG/sim2sim/$name"
      cp experiments/results/sim2sim/stage2_u/policy.onnx* "$BG/sim2sim/$name/"
      background "sim2sim/$name" python3 experiments/gpu/sim2sim_table.py --cells u_shaped \
        --episodes "${S2S_EPISODES:-$eps}" --workers "${S2S_WORKERS:-14}" \
        --out "$BG/sim2sim/$name" "${s2s[@]}" ;;
    # issue 25: stage 2 fine-tuned for a real Go2's joints (experiments/stage2_u_robot.toml:
    # damping 0.1-2 N m s/rad integrated implicitly, 0-20 ms delay; from stage2_u's policy)
    stage2-robot) train stage2_u_robot experiments/stage2_u_robot.toml ;;
    # issue 25: stage2_u_robot fine-tuned on the damping x delay corner it fails
    # (stage2_u_robot_corner.toml); then delay-grid: a policy (GRID_POLICY, default
    # stage2_u_robot_corner: trained in this command, carried, or committed) on the grid of damping
    # 0.1-2 x delay 0-20 ms in MuJoCo itself (U L5 up, 200 robots per cell), on the host's CPUs
    # in the background, into $OUT/delay_grid/<policy>/
    stage2-robot-corner) train stage2_u_robot_corner experiments/stage2_u_robot_corner.toml ;;
    # issue 25: stage2_u_robot fine-tuned for a measured 15-20 ms latency over every damping
    # (stage2_u_robot_latency20.toml); judge it with GRID_POLICY=stage2_u_robot_latency20 delay-grid
    stage2-robot-latency20) train stage2_u_robot_latency20 experiments/stage2_u_robot_latency20.toml ;;
    # issue 25: stage2_u_robot with 3 steps of observation history (stage2_u_robot_history.toml);
    # judge it with GRID_POLICY=stage2_u_robot_history delay-grid
    stage2-robot-history) train stage2_u_robot_history experiments/stage2_u_robot_history.toml ;;
    delay-grid)
      name=${GRID_POLICY:-stage2_u_robot_corner}
      p=$(any_policy "$name")
      background "delay_grid/$name" python3 experiments/damping_gt.py "$BG/delay_grid/$name" \
        --policy "$p" --cell u_shaped:test:5 --robots 200 --what gt --configs grid \
        --jobs "${GRID_JOBS:-10}" ;;
    # issue 25: a policy's sim-to-sim table (S2S_POLICY: a run trained in this command, carried
    # in .carry/ or committed, default stage2_u_robot) on the paper's test levels (S2S_CELLS,
    # default u_shaped; S2S_DIRECTION up|down), S2S_EPISODES (200) per level: its two MJX
    # columns of the very starts
    # here on the GPU first (the evaluation physics; "robot": the sim2sim robot's joints, damping
    # 2 integrated implicitly), then sim2sim on the host's CPUs in the background, into
    # $OUT/sim2sim/<policy>_<direction>/. S2S_CELLS=code: the code cases, paired (their MJX
    # starts); S2S_ONNX (a folder): its policy.onnx and sidecar are the export run (e.g. a wall-rule
    # export, experiments/results/<run>/wallrule); S2S_ARGS (a+b): more sim2sim_table.py flags,
    # e.g. --contact-timeconst+0.01+--robot+FILE+--mjx-column+wall=height_map.occlusion_samples=32.
    # S2S_MJX=0: without the two default MJX columns (then no GPU is used unless S2S_ARGS names a
    # --mjx-column: MuJoCo only while the GPUs train, a later call adds the columns); S2S_FROM (a
    # folder an earlier call brought back): its cells and MJX columns are kept, only what is
    # missing runs
    sim2sim-policy)
      name=${S2S_POLICY:-stage2_u_robot}; dir=${S2S_DIRECTION:-up}
      p=$(any_policy "$name")
      d="$BG/sim2sim/${name}_$dir"; mkdir -p "$d"
      [ -n "${S2S_FROM:-}" ] && cp -r "$S2S_FROM"/. "$d/"
      [ -n "${S2S_ONNX:-}" ] && cp "$S2S_ONNX"/policy.onnx* "$d/"
      s2s=(--policy "$p" --out "$d" --cells ${S2S_CELLS:-u_shaped} --direction "$dir"
           --episodes "${S2S_EPISODES:-200}")
      [ "${S2S_MJX:-1}" = 0 ] || s2s+=(--mjx
           --mjx-column "robot=robot.joint_damping=2.0,robot.implicit_damping=true")
      [ -n "${S2S_ARGS:-}" ] && s2s+=(${S2S_ARGS//+/ })
      [[ " ${s2s[*]} " == *" --mjx"* ]] &&
        python3 experiments/gpu/sim2sim_table.py "${s2s[@]}" --mjx-only 2>&1 | grep -v warp
      background "sim2sim/${name}_$dir" python3 experiments/gpu/sim2sim_table.py "${s2s[@]}" \
        --workers "${S2S_WORKERS:-14}" ;;
    # issue 19: tables of the reference physics re-evaluated in the evaluation physics (every
    # evaluation's default), 1000 robots per cell: transfer-eval, the lean transfer matrix (Tables
    # 1-2, experiments/results/transfer_lean/models.toml) into $OUT/transfer_lean_eval; rq1-eval,
    # the RQ1 policies beside stage2_u (whose re-evaluation is step fidelity's mjx_eval/): the
    # no-stall ablation and the paper's final goal with and without the stall penalty, into
    # $OUT/rq_eval
    transfer-eval)  # resumes from the committed cells (transfer_lean/evaluation*/cells/: a cell
      # judged in other physics than the preset's today is judged again); TE_ROWS (a+b): those
      # models' rows only (one GPU's part; the run without it assembles the kept cells)
      [ "$(left)" -lt 90 ] && { echo "no time left for $step"; return; }
      mkdir -p "$OUT/transfer_lean_eval"
      for d in experiments/results/transfer_lean/evaluation*/cells; do
        [ -d "$d" ] && cp -rn "$d" "$OUT/transfer_lean_eval/"
      done
      part=(); [ -n "${TE_ROWS:-}" ] && part+=(--rows ${TE_ROWS//+/ })
      timeout $(( $(left) - 15 )) python3 -m mjx_stairs transfer-matrix \
        --config experiments/results/transfer_lean/models.toml --robots 1000 \
        --out "$OUT/transfer_lean_eval" "${part[@]}" 2>&1 | grep -v warp ;;
    rq1-eval)
      [ "$(left)" -lt 90 ] && { echo "no time left for $step"; return; }
      timeout $(( $(left) - 15 )) python3 -m mjx_stairs eval --checkpoint \
        experiments/results/stage2_u_no_stall/policy.npz \
        experiments/results/stage2_u_final_goal/policy.npz \
        experiments/results/stage2_u_final_goal_no_stall/policy.npz \
        --robots 1000 --out "$OUT/rq_eval" 2>&1 | grep -v warp ;;
    # issue 21: stage 2 as the paper has it (stage2_u_paper.toml), with and without the stall
    # penalty; SEED (default 0) names the run, stage2_u_paper[_no_stall]_s<SEED>, and its carry
    # folder. eval-paper: every such policy trained in this command (else carried) on the U
    # test levels, 1000 robots, the evaluation physics, 20 s, at the policy's success radius
    # (0.8 m, the authors') and at 0.5 m (every other table's), into $OUT/paper_eval/<name>/
    paper|paper-no-stall)
      cfg=stage2_u_paper; [ "$step" = paper-no-stall ] && cfg=stage2_u_paper_no_stall
      train "${cfg}_s${SEED:-0}" "experiments/$cfg.toml" "train.seed=${SEED:-0}" \
        "train.experiment=${cfg}_s${SEED:-0}" ;;
    # RQ2 in the paper's setting: the family models (experiments/<family>_paper.toml, resumed
    # from .carry/<family>_paper/), then transfer-paper: transfer_matrix_paper.toml's matrix
    # (committed models, else the ones trained here or carried), 1000 robots per cell, kept
    # cells carried in .carry/transfer_paper/cells/; TP_ROWS / TP_COLUMNS: a part of it, e.g.
    # a row split over the GPUs (gpuN:TP_WAIT=spiral_paper,TP_ROWS=spiral,TP_COLUMNS=straight,
    # transfer-paper: after the spiral model trained on another GPU), then transfer-paper alone
    # assembles the matrix
    straight-paper|l-shaped-paper|spiral-paper)
      fam=${step%-paper}; fam=${fam//-/_}
      train "${fam}_paper" "experiments/${fam}_paper.toml" ;;
    transfer-paper)
      [ -n "${TP_WAIT:-}" ] && wait_policy "$TP_WAIT"  # a run trained on another GPU here
      models=/tmp/transfer_paper.$BASHPID.toml; paper_models "$models"  # one per GPU group
      part=()  # TP_ROWS / TP_COLUMNS (a+b): only those cells (one GPU's part of the matrix)
      [ -n "${TP_ROWS:-}" ] && part+=(--rows ${TP_ROWS//+/ })
      [ -n "${TP_COLUMNS:-}" ] && part+=(--columns ${TP_COLUMNS//+/ })
      if [ ${#part[@]} -eq 0 ] && [ -d .carry/transfer_paper/cells ]; then  # an earlier command's
        mkdir -p "$OUT/transfer_paper" && cp -rn .carry/transfer_paper/cells "$OUT/transfer_paper/"
      fi
      [ "$(left)" -lt 60 ] && { echo "no time left for $step"; return; }
      timeout $(( $(left) - 15 )) python3 -m mjx_stairs transfer-matrix \
        --config "$models" --robots 1000 --out "$OUT/transfer_paper" "${part[@]}" \
        2>&1 | grep -v warp ;;
    # eval-paper-committed: the committed RQ1 policies (experiments/results/stage2_u_paper*/) in
    # today's evaluation physics at the authors' 0.8 m (PAPER_RADII), into $OUT/paper_eval/<name>/
    eval-paper-committed)
      for p in experiments/results/stage2_u_paper*/policy.npz; do
        paper_eval "$p" "$(basename "$(dirname "$p")")" ${PAPER_RADII:-0.8}
      done ;;
    eval-paper)
      shopt -s nullglob
      for p in /tmp/policies/stage2_u_paper*.npz .carry/stage2_u_paper*/policy.npz; do
        name=$(basename "$p" .npz); [ "$name" = policy ] && name=$(basename "$(dirname "$p")")
        [ -d "$OUT/paper_eval/$name" ] && continue  # trained here and carried: once
        paper_eval "$p" "$name" 0.8 0.5
      done ;;
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
    warp)  # issues 22 and 19: MuJoCo Warp (experiments/gpu/warp_physics.py). warp-lang's wheel
      # (~149 MB) comes in four parts carried by four earlier calls on the same warm machine
      # (.whl_warp_a .. _d, each ~37 MB beside the ~18 MB tree: an ignored path a later call does
      # not carry stays there); here they are joined and installed. WARP_CELLS (fidelity.CELLS indices) for the success table.
      w=/tmp/warp_lang-1.19.0-py3-none-manylinux_2_28_x86_64.whl
      cat .whl_warp_a/warp_lang.part.00 .whl_warp_b/warp_lang.part.01 \
        .whl_warp_c/warp_lang.part.02 .whl_warp_d/warp_lang.part.03 > $w \
        || { echo "warp parts missing"; return; }
      python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site $w \
        .whl_warp_d/mujoco_warp-*.whl >/dev/null 2>&1 || { echo "warp install failed"; return; }
      mkdir -p "$OUT/warp"
      python3 experiments/gpu/warp_physics.py rate "$OUT/warp/rate_4096.json" --robots 4096 \
        2>&1 | grep -v -e "^Module" -e "took" -e "overflow" -e "iterations limit"
      python3 experiments/gpu/warp_physics.py success "$OUT/warp/success.json" --robots 1000 \
        --cells "${WARP_CELLS:-8,9,15,16,3,5}" 2>&1 | grep -v -e "^Module" -e "took" -e "overflow" -e "iterations limit" ;;
    wait-policy) wait_policy "${WAIT_POLICY:?WAIT_POLICY names a run}" ;;  # see wait_policy
    gpus)  # what this step sees: its GPU(s) and seed (a check of gpuN: groups)
      echo "CUDA_VISIBLE_DEVICES=${CUDA_VISIBLE_DEVICES:-unset} SEED=${SEED:-unset}"
      nvidia-smi -L 2>/dev/null || true ;;
    pack)  # only 8 files of at most 16 MiB come back from a device command: one tar per output
      # folder, cut in 15 MiB parts (NAME.tar.00, .01: cat them back together) where larger; the
      # background jobs' output first
      wait_gpu_groups; collect
      shopt -s nullglob; for d in "$OUT"/*/; do d=${d%/}; tar -C "$OUT" -cf "$d.tar" "$(basename "$d")" && rm -r "$d"
        if [ "$(stat -c %s "$d.tar")" -gt 15728640 ]; then split -b 15M -d "$d.tar" "$d.tar." && rm "$d.tar"; fi
      done
      ls -la "$OUT" ;;
    *) echo "unknown step $step"  # one argument: VAR=...,step is a group's syntax
      [[ "$step" == *=* ]] && echo "(KEY=VALUE,step tokens run in a gpuN: group, e.g. gpu0:$step;" \
        "or export KEY=VALUE before run.sh)"
      exit 2 ;;
  esac
}

for step in "$@"; do
  case $step in
    gpu[0-9]*:*) gpu_group "$step" ;;
    *) run_step "$step"; echo "== $step done at $(( $(date +%s) - T0 ))s" ;;
  esac
done
wait_gpu_groups
collect  # background jobs started after the last pack (or with no pack)
