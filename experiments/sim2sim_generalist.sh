#!/usr/bin/env bash
# Issue 25: a policy (experiments/results/$POLICY/policy.onnx, POLICY default generalist) in CPU
# MuJoCo through `mjx-stairs sim2sim`, one cell at a time (one process; the 2-core development machine).
# Cells: U-shaped test levels, down 1-6 and up 1-6; with LATENCY=1 the same 12 cells with 20 ms
# of action latency. One JSON per cell under experiments/results/sim2sim/$POLICY[_latency20]/,
# skipped when already there; then the folder's table.md (experiments/sim2sim_generalist_table.py).
# N episodes per cell (default 50), seed 0, 20 s episodes, default robot (go2_full.xml, joint
# damping 2). LEVELS="1 3 5" restricts the levels (default 1-6), DIRS="up" the directions (default
# "down up"). POLICY=generalist_line: the second run, trained with the stair-aware low ending
# env.low_line_m=0.3; its sidecar carries evaluation.low_line_m, which sim2sim's fall rule reads.
# The first generalist run's cells (its policy now generalist/first_run/policy.onnx) are under
# experiments/results/sim2sim/generalist_first_run*/, made by this script's earlier version
# (git show 5810c2a:experiments/sim2sim_generalist.sh).
set -u
POLICY=${POLICY:-generalist}; N=${N:-50}; ONNX=experiments/results/$POLICY/policy.onnx
LEVELS=${LEVELS:-1 2 3 4 5 6}; DIRS=${DIRS:-down up}
cell() {  # dir direction level extra...
  local d=$1 dir=$2 lv=$3; shift 3
  local f=experiments/results/sim2sim/$d/u_shaped_test_${dir}_L${lv}.json
  [ -f "$f" ] && return
  mkdir -p "$(dirname "$f")"; local t0=$(date +%s)
  python -m mjx_stairs sim2sim --onnx $ONNX --family u_shaped --schedule test \
    --direction "$dir" --level "$lv" --episodes "$N" --seed 0 --out "$f" "$@" 2>&1 | grep -v warp
  echo "$d $dir L$lv: $(( $(date +%s) - t0 )) s wall"
}
if [ "${LATENCY:-0}" = 1 ]; then
  d=${POLICY}_latency20; extra=(--latency-ms 20); how="with LATENCY=1 "
else
  d=$POLICY; extra=(); how=""
fi
for dir in $DIRS; do
  for lv in $LEVELS; do cell $d $dir $lv "${extra[@]}"; done
done
python experiments/sim2sim_generalist_table.py experiments/results/sim2sim/$d \
  --note "Policy: $ONNX. Made by experiments/sim2sim_generalist.sh $how(N=$N)."
