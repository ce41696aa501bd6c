#!/usr/bin/env bash
# Keep a device call's copy of the working tree under the 64 MiB one call carries (the tracked
# tree passed it on 2026-11-28: 67.7 MB, most of it experiments/results/ and docs/).
#   bash experiments/gpu/slim_tree.sh out [RUN ...]   # before the first device call
#   bash experiments/gpu/slim_tree.sh back            # right after it (or after the last call)
# out: moves docs/ and every experiments/results/<folder>/ that is not named (RUN: a folder name
# under experiments/results/, e.g. a policy that a step evaluates or resumes from; stage1,
# stage2_u and generalist_d2 always stay: training's init_from files) to $HOLD
# (/tmp/mjx_stairs_hold), and prints the tree's size then. back: moves them back. A later device
# call on a warm machine still carries the tree it is given, so move back only once the calls
# that need the slim tree are done, or call `out` again before the next call.
set -euo pipefail
HOLD=${HOLD:-/tmp/mjx_stairs_hold}
cd "$(git rev-parse --show-toplevel)"
case "${1:-}" in
  out)
    shift
    [ -e "$HOLD" ] && { echo "slim_tree: $HOLD exists: run 'back' first"; exit 1; }
    keep=" stage1 stage2_u generalist_d2 $* "
    mkdir -p "$HOLD/results"
    mv docs "$HOLD/docs"
    for d in experiments/results/*/; do
      name=$(basename "$d")
      [[ "$keep" == *" $name "* ]] || mv "$d" "$HOLD/results/$name"
    done
    size=$( { git ls-files -z | xargs -0 du -cb 2>/dev/null || true; } | tail -1 | cut -f1)  # the
    # files moved out are missing, which du reports
    echo "slim_tree: held in $HOLD; the tracked tree here is $((size / 1000000)) MB";;
  back)
    [ -d "$HOLD" ] || { echo "slim_tree: nothing held in $HOLD"; exit 1; }
    for d in "$HOLD"/results/*/; do
      name=$(basename "$d")
      [ -e "experiments/results/$name" ] && { echo "slim_tree: experiments/results/$name exists"; exit 1; }
    done
    [ -e docs ] && { echo "slim_tree: docs/ exists"; exit 1; }
    mv "$HOLD/docs" docs
    for d in "$HOLD"/results/*/; do mv "$d" "experiments/results/$(basename "$d")"; done
    rmdir "$HOLD/results" "$HOLD"
    echo "slim_tree: moved back; git status:"; git status --short | head -5;;
  *) echo "usage: bash experiments/gpu/slim_tree.sh out [RUN ...] | back"; exit 2;;
esac
