#!/usr/bin/env bash
# One GPU command, two halves in parallel:
# - host CPUs (issue 25): sim-to-sim of stage2_u on the U-shaped test levels, two variants:
#   the training damping (0.1 instead of the description's 2) and 20 ms of action latency;
#   compared with the named evaluation physics (ground_truth/mjx_eval).
# - the GPU (issue 23): the code suite for stage2_u_lean and stage1, and the U3 mesh-vs-family
#   points, in the evaluation physics.
set -u
R=${OUT:-/tmp/out}/r; mkdir -p "$R"
MJX=experiments/results/ground_truth/mjx_eval/mjx_evaluation.json
sed 's/damping="2"/damping="0.1"/' mjx_stairs/sim/assets/go2_full.xml \
  > mjx_stairs/sim/assets/go2_full_damping01.xml
S2S_EPISODES=${S2S_EPISODES:-50}
( timeout ${S2S_TIMEOUT:-540} python experiments/gpu/sim2sim_table.py --cells u_shaped \
    --episodes "$S2S_EPISODES" --workers 7 --chunk 5 --robot mjx_stairs/sim/assets/go2_full_damping01.xml \
    --out "$R/s2s_damping01" --mjx-json $MJX > "$R/s2s_damping01.log" 2>&1 ) &
( timeout ${S2S_TIMEOUT:-540} python experiments/gpu/sim2sim_table.py --cells u_shaped \
    --episodes "$S2S_EPISODES" --workers 7 --chunk 5 --latency-ms 20 \
    --out "$R/s2s_latency20" --mjx-json $MJX > "$R/s2s_latency20.log" 2>&1 ) &
python experiments/gpu/code_suite.py "$R/code" --steps ${CODE_STEPS:-suite,mesh} \
  --policies "${CODE_POLICIES:-stage2_u_lean,stage1}" > "$R/code.log" 2>&1
wait
rm -f "$R"/s2s_*/policy.onnx*
tar czf "$OUT/eval3.tgz" -C "$R" .
