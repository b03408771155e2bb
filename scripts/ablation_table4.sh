#!/usr/bin/env bash
# The Table 4-style ablation of crates/surface/README.md: DTU scan65 narrow views 22,23,24,
# sigma 0.15, seed 0, epipolar warm-up, poses held for the first half, 240 iterations, with the
# uncertainty / patch-NCC / geometric-consistency switches. Usage: scripts/ablation_table4.sh OUT
set -euo pipefail
out="${1:?usage: $0 OUT_DIR}"
bin="${FEWVIEW_BIN:-target/release/fewview}"
data="${FEWVIEW_DATA:?set FEWVIEW_DATA to the shared data folder}"
common=(surface --data "$data/dtu/scan65" --train-views 22,23,24 --downscale 2
  --pose-noise 0.15 --seed 0 --schedule paper --pose-warmup --pose-start 0.5
  --iterations 240 --checkpoint-every 60 --mesh-resolution 64 --eval-views 1 --eval-scale 4)
declare -A rows=(
  [A]="--no-uncertainty --no-ncc --no-gc"
  [B]="--no-uncertainty --no-gc"
  [C]="--no-uncertainty --no-ncc"
  [D]="--no-uncertainty"
  [E]="--no-gc"
  [F]="--no-ncc"
  [G]=""
)
mkdir -p "$out"
for r in A B C D E F G; do
  # shellcheck disable=SC2086
  "$bin" "${common[@]}" ${rows[$r]} --out "$out/$r" > "$out/$r.log" 2>&1
  echo "$r: $(grep -o 'poses .*' "$out/$r.log" | tail -1)"
done
