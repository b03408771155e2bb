#!/usr/bin/env bash
# Frames of finished runs' transition videos as one picture: a row per run, a column per frame
# (e.g. the frames half-way between training views, where a transition tears first).
#
#   scripts/midpath_frames.sh OUT.jpg FRAMES RUN_DIR...      (FRAMES: e.g. 20,60)
#
# Needs ffmpeg. Each RUN_DIR must hold transition.mp4 (`fewview fusion` writes it).
set -euo pipefail
out="${1:?usage: $0 OUT.jpg FRAMES RUN_DIR...}"
frames="${2:?usage: $0 OUT.jpg FRAMES RUN_DIR...}"
shift 2
[[ $# -ge 1 ]] || { echo "give at least one run folder" >&2; exit 2; }
IFS=, read -r -a picks <<< "$frames"
select=$(printf "eq(n\\\\,%s)+" "${picks[@]}")
select="${select%+}"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
rows=()
for run in "$@"; do
  video="$run/transition.mp4"
  [[ -f "$video" ]] || { echo "$video: missing (not a finished fusion run?)" >&2; exit 1; }
  row="$tmp/row${#rows[@]}.png"
  ffmpeg -loglevel error -y -i "$video" \
    -vf "select=$select,tile=${#picks[@]}x1" -frames:v 1 "$row"
  rows+=("$row")
done
inputs=()
for r in "${rows[@]}"; do inputs+=(-i "$r"); done
if [[ ${#rows[@]} -eq 1 ]]; then
  ffmpeg -loglevel error -y -i "${rows[0]}" -q:v 3 "$out"
else
  ffmpeg -loglevel error -y "${inputs[@]}" -filter_complex "vstack=inputs=${#rows[@]}" -q:v 3 "$out"
fi
echo "$out"
