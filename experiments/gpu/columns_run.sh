#!/usr/bin/env bash
# Issue 19: the columns collider against the ground truth (one GPU command, <= 10 min).
# MJX on the GPU (columns, columns_converged; 1000 robots/cell) while the host's CPUs run the
# ground truth with 1000 episodes on the cells where success is neither ~0 nor ~100 %;
# then the physics-only rate of each collider at 4096 robots.
set -u
R=${OUT:-/tmp/out}/r; mkdir -p "$R"
( JAX_PLATFORMS=cpu timeout 540 python experiments/gpu/fidelity.py gt "$R/gt1000" --robots 1000 \
    --workers 14 --cells 7,8,9,14,15,16,17 > "$R/gt1000.log" 2>&1 ) &
python experiments/gpu/fidelity.py mjx "$R/mjx_columns" --options columns,columns_converged \
  > "$R/mjx_columns.log" 2>&1
for p in "reference" "reference env.robot.terrain_contacts=columns" "lean" \
         "lean env.robot.terrain_contacts=columns"; do
  set -- $p; name=$(echo "$p" | tr ' =.' '___')
  timeout 100 python -m mjx_stairs bench --config experiments/stage2_u_lean.toml --robots 4096 \
    --parts physics --repeats 3 env.robot.physics=$1 ${2:-} --out "$R/bench_$name.json" \
    >> "$R/bench.log" 2>&1
done
wait
tar czf "$OUT/columns.tgz" -C "$R" .
