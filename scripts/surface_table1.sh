#!/usr/bin/env bash
# The surface paper's Table 1 protocol: the default `fewview surface` command on each DTU scan, both
# triplets (narrow 22,23,24 and wide 22,25,28) and seeds 0, 1, 2 at 400 x 300 with sigma = 0.15
# pose noise, then one Markdown table beside the paper's rows (`fewview surface --table`).
# Finished runs are kept and skipped, so an interrupted protocol goes on where it stopped.
#
#   scripts/surface_table1.sh OUT [SCAN_DIR...]     (default: $FEWVIEW_DATA/dtu/scan37 and scan65)
#
# DOWNSCALE (default 2: 400 x 300) sets the resolution; extra flags for every run (e.g.
# --no-masks) go in SURFACE_FLAGS. Each run takes 20-40 minutes on 2 cores: the default set is
# 12 runs.
set -euo pipefail
out="${1:?usage: $0 OUT_DIR [SCAN_DIR...]}"
shift
scans=("$@")
if [[ ${#scans[@]} -eq 0 ]]; then
  scans=("${FEWVIEW_DATA:?set FEWVIEW_DATA or name the scans}/dtu/scan37" "$FEWVIEW_DATA/dtu/scan65")
fi
bin="${FEWVIEW_BIN:-target/release/fewview}"
read -r -a flags <<< "${SURFACE_FLAGS:-}"
runs=()
for scan in "${scans[@]}"; do
  name=$(basename "$scan")
  for triplet in narrow:22,23,24 wide:22,25,28; do
    for seed in 0 1 2; do
      run="$out/$name/${triplet%%:*}/seed$seed"
      if [[ ! -f "$run/metrics.json" ]]; then
        mkdir -p "$run"
        "$bin" surface --data "$scan" --train-views "${triplet#*:}" --downscale "${DOWNSCALE:-2}" --seed "$seed" \
          ${flags[@]+"${flags[@]}"} --out "$run" > "$run.log" 2>&1 \
          || { echo "failed: $run (see $run.log)" >&2; continue; }
      fi
      runs+=("$run")
    done
  done
done
"$bin" surface --table "${runs[@]}" | tee "$out/table1.md"
