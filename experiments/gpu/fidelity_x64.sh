#!/usr/bin/env bash
# Issue 19: is MJX's remaining gap to the ground truth its float32? The converged solver with the
# columns collider in float64 (JAX_ENABLE_X64=1) on the cells that disagree, the same in float32
# on every cell, and (issue 25, on the host's CPUs meanwhile) the sim-to-sim table of stage 2.
set -u
R=${OUT:-/tmp/out}/r; mkdir -p "$R/sim2sim/stage2_u"
cp experiments/results/sim2sim/stage2_u/policy.onnx* "$R/sim2sim/stage2_u/"
( JAX_PLATFORMS=cpu timeout 560 python experiments/gpu/sim2sim_table.py --cells u_shaped \
    --episodes 200 --workers 13 --out "$R/sim2sim/stage2_u" \
    --mjx-json experiments/results/ground_truth/mjx/mjx_reference.json --mjx-policy stage2_u \
    > "$R/sim2sim.log" 2>&1 ) &
JAX_ENABLE_X64=1 timeout 250 python experiments/gpu/fidelity.py mjx "$R/mjx_x64" \
  --options columns_converged --cells 8,9,15,16,17 > "$R/mjx_x64.log" 2>&1
timeout 200 python experiments/gpu/fidelity.py mjx "$R/mjx_columns" --options columns_converged \
  > "$R/mjx_columns_converged.log" 2>&1
JAX_ENABLE_X64=1 timeout 100 python experiments/gpu/fidelity.py mjx "$R/mjx_x64" \
  --options mjx_converged --cells 8,15,16 >> "$R/mjx_x64.log" 2>&1
wait
rm -f "$R/sim2sim/stage2_u/policy.onnx"
tar czf "$OUT/x64.tgz" -C "$R" .
