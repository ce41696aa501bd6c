#!/usr/bin/env bash
# Issue 24's video: a generalist (P, default experiments/results/generalist_d2/policy.npz, the
# README's policy for building-code stairs; the first video, 2026-11-24, was generalist/) going
# up, then down, the `code` suite's commercial U-shaped staircase (risers 17.8 cm, treads
# 27.9 cm, width 1.12 m, left turn), exported to STL and played through `mjx-stairs play --mesh`
# (one robot, seed 0, its first episode, tracking camera; no selection of episodes). Writes
# docs/generalist_code_u.mp4 (up then down) and docs/generalist_code_u.png (four frames of
# each). ~8 min per direction on a 2-core CPU (software rendering).
#   [P=experiments/results/NAME/policy.npz] bash experiments/generalist_video.sh
#   (JAX_PLATFORMS=cpu is set here)
set -euo pipefail
export JAX_PLATFORMS=cpu
PY=${PY:-.venv/bin/python}; TMP=$(mktemp -d); P=${P:-experiments/results/generalist_d2/policy.npz}
"$PY" - "$TMP" <<'EOF'
import sys
from mjx_stairs.study import cases
from terrains.suites import write_case
code = dict(cases.suite_cases("code", 0.025))
for n in ("code_commercial_u_left_up", "code_commercial_u_left_down"):
    write_case(code[n], sys.argv[1], n)
EOF
pose() {  # pose CASE start|goal -> x,y,yaw of the case's JSON
  "$PY" -c "import json,sys; r=json.load(open(sys.argv[1]))[sys.argv[2]]; print(f'{r[0]},{r[1]},{r[3]}')" \
    "$TMP/$1.json" "$2"
}
for dir in up down; do
  c=code_commercial_u_left_$dir; secs=16; [ "$dir" = down ] && secs=12
  "$PY" -m mjx_stairs play --checkpoint "$P" --mesh "$TMP/$c.stl" --start "$(pose "$c" start)" \
    --goal "$(pose "$c" goal)" --robots 1 --seconds "$secs" --episode-s 30 --seed 0 \
    --video "$TMP/$dir.mp4" 2>&1 | grep -v warp
done
FF=$("$PY" -c "import imageio_ffmpeg; print(imageio_ffmpeg.get_ffmpeg_exe())")
printf "file '%s'\nfile '%s'\n" "$TMP/up.mp4" "$TMP/down.mp4" > "$TMP/list.txt"
"$FF" -loglevel error -y -f concat -safe 0 -i "$TMP/list.txt" -c:v libx264 -crf 32 -preset slow \
  -pix_fmt yuv420p -movflags +faststart docs/generalist_code_u.mp4
frames() {  # frames DIR N1 N2 N3 N4: four frames (50 per second) side by side
  "$FF" -loglevel error -y -i "$TMP/$1.mp4" -frames:v 1 -vf \
    "select='eq(n\,$2)+eq(n\,$3)+eq(n\,$4)+eq(n\,$5)',scale=320:-1,tile=4x1" "$TMP/$1.png"
}
frames up 100 300 550 790; frames down 150 200 250 300  # climbing, the landing, the top; going down
"$FF" -loglevel error -y -i "$TMP/up.png" -i "$TMP/down.png" -filter_complex vstack \
  docs/generalist_code_u.png
rm -rf "$TMP"
ls -la docs/generalist_code_u.mp4 docs/generalist_code_u.png
