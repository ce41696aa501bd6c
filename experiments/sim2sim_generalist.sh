#!/usr/bin/env bash
# Issue 25: the generalist (experiments/results/generalist/policy.onnx) in CPU MuJoCo through
# `mjx-stairs sim2sim`, one cell at a time (one process; the 2-core development machine).
# Cells: U-shaped test levels, down 1-6 and up 1, 3, 5; then (LATENCY=1) down 1-6 with 20 ms of
# action latency. One JSON per cell under experiments/results/sim2sim/generalist[_latency20]/,
# skipped when already there. N episodes per cell (default 50), seed 0, 20 s episodes, default
# robot (go2_full.xml, joint damping 2).
set -u
N=${N:-50}; ONNX=experiments/results/generalist/policy.onnx
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
  for lv in 1 2 3 4 5 6; do cell generalist_latency20 down $lv --latency-ms 20; done
else
  for lv in 1 2 3 4 5 6; do cell generalist down $lv; done
  for lv in 1 3 5; do cell generalist up $lv; done
fi
