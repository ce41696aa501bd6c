#!/usr/bin/env bash
# One GPU command (issue 19: the published tables re-evaluated in the named evaluation physics;
# issue 25: sim-to-sim with 20 ms action latency on the host CPUs beside it). Everything is
# written under /tmp/r4 and packed into $OUT/eval4.tgz by a deadline, finished or not.
set -u
R=/tmp/r4; mkdir -p "$R"; T0=$(date +%s); DEADLINE=${DEADLINE:-560}
MJX=experiments/results/ground_truth/mjx_eval/mjx_evaluation.json
( JAX_PLATFORMS=cpu timeout $((DEADLINE - 20)) python experiments/gpu/sim2sim_table.py \
    --cells u_shaped --episodes 50 --workers 14 --chunk 5 --latency-ms 20 \
    --out "$R/s2s_latency20" --mjx-json $MJX > "$R/s2s_latency20.log" 2>&1 ) &
( timeout $((DEADLINE - 20)) python -m mjx_stairs transfer-matrix \
    --config experiments/results/transfer_lean/models.toml --robots 1000 \
    --out "$R/transfer_lean_eval" > "$R/transfer.log" 2>&1
  timeout $((DEADLINE - 20)) python -m mjx_stairs eval --checkpoint \
    experiments/results/stage2_u_no_stall/policy.npz \
    experiments/results/stage2_u_final_goal/policy.npz \
    experiments/results/stage2_u_final_goal_no_stall/policy.npz \
    --robots 1000 --out "$R/rq_eval" > "$R/rq_eval.log" 2>&1 ) &
while [ $(( $(date +%s) - T0 )) -lt "$DEADLINE" ] && [ -n "$(jobs -r)" ]; do sleep 5; done
rm -f "$R"/s2s_*/policy.onnx*
tar czf "$OUT/eval4.tgz" -C "$R" . && echo "packed at $(( $(date +%s) - T0 )) s"
