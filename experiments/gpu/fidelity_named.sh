#!/usr/bin/env bash
# Issue 19: the candidate evaluation physics on every cell (columns collider, converged solver,
# float64 physics) while the host's CPUs complete the ground truth at 1000 episodes per cell;
# then the same physics in float32 where time is left.
set -u
R=${OUT:-/tmp/out}/r; mkdir -p "$R"
( JAX_PLATFORMS=cpu timeout 560 python experiments/gpu/fidelity.py gt "$R/gt1000" --robots 1000 \
    --workers 14 --cells 0,1,2,3,4,5,6,10,11,12,13 > "$R/gt1000b.log" 2>&1 ) &
JAX_ENABLE_X64=1 timeout 420 python experiments/gpu/fidelity.py mjx "$R/mjx_x64" \
  --options columns_converged > "$R/mjx_x64_all.log" 2>&1
timeout 120 python experiments/gpu/fidelity.py mjx "$R/mjx_columns" --options columns_converged \
  --cells 8,9,15,16,17 > "$R/mjx_columns_converged.log" 2>&1
wait
tar czf "$OUT/named.tgz" -C "$R" .
