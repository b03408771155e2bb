#!/usr/bin/env bash
# The Table 4-style ablations (docs/experiments.md) on DTU scan65 narrow views 22,23,24,
# sigma 0.15, seed 0, with the uncertainty / patch-NCC / geometric-consistency switches.
#
#   scripts/ablation_table4.sh OUT [cpu|short]
#
# cpu (default): the CLI's default CPU schedule (warm-up, poses held for 75 %, then refined at
#   1e-4 -> 1e-5), 2000 iterations; about 15 minutes a row on 2 cores.
# short: the session-9 table: the paper's pose learning rate after the warm-up, poses held for
#   the first half of 240 iterations.
set -euo pipefail
out="${1:?usage: $0 OUT_DIR [cpu|short]}"
mode="${2:-cpu}"
bin="${FEWVIEW_BIN:-target/release/fewview}"
data="${FEWVIEW_DATA:?set FEWVIEW_DATA to the shared data folder}"
common=(surface --data "$data/dtu/scan65" --train-views 22,23,24 --downscale 2
  --pose-noise 0.15 --seed 0 --mesh-resolution 64 --eval-views 1 --eval-scale 4)
case "$mode" in
  cpu) common+=(--iterations 2000 --checkpoint-every 250) ;;
  short) common+=(--schedule paper --pose-warmup on --pose-start 0.5 --iterations 240
    --checkpoint-every 60) ;;
  *) echo "unknown mode $mode (cpu or short)" >&2; exit 2 ;;
esac
declare -A rows=(
  [A]="--no-loss uncertainty,ncc,gc"
  [B]="--no-loss uncertainty,gc"
  [C]="--no-loss uncertainty,ncc"
  [D]="--no-loss uncertainty"
  [E]="--no-loss gc"
  [F]="--no-loss ncc"
  [G]=""
)
mkdir -p "$out"
for r in A B C D E F G; do
  # shellcheck disable=SC2086
  "$bin" "${common[@]}" ${rows[$r]} --out "$out/$r" > "$out/$r.log" 2>&1
  echo "$r: $(grep -o 'poses .*' "$out/$r.log" | tail -1)"
done
