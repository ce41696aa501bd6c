#!/usr/bin/env bash
# Issue 19 + 23 on one GPU: the named evaluation physics on every fidelity cell, then the code
# suite baseline (issue 23) of the policies given in CODE_POLICIES, in that physics.
set -u
R=${OUT:-/tmp/out}/r; mkdir -p "$R"
if [ -z "${SKIP_FIDELITY:-}" ]; then
  timeout 300 python experiments/gpu/fidelity.py mjx "$R/mjx_eval" --options evaluation \
    > "$R/mjx_eval.log" 2>&1
fi
python experiments/gpu/code_suite.py "$R/code" --steps ${CODE_STEPS:-suite} \
  --policies "${CODE_POLICIES:-stage2_u}" > "$R/code_${CODE_POLICIES:-stage2_u}.log" 2>&1
tar czf "$OUT/eval.tgz" -C "$R" .
