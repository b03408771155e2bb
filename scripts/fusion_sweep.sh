#!/usr/bin/env bash
# Where plain splats' transitions fail: the demo scene under the conditions of real captures
# (per-photo exposure and white balance, vignetting, strong highlights, a mirror floor, wide
# baselines, fewer SH bands, more views), plain against gf, seed 0, then one Markdown table
# (docs/guide/fusion.md, "Photos that disagree, and where plain transitions fail").
#
#   scripts/fusion_sweep.sh OUT [CONDITION ...]
#
# With RESCORE=1, finished runs are not trained again but their transitions scored again
# (`fusion --rescore`), e.g. after a change of the scores.
# About 4-6 minutes a run on 2 cores; 11 conditions x 2 variants.
set -euo pipefail
out="${1:?usage: $0 OUT_DIR [CONDITION ...]}"
shift
bin="${FEWVIEW_BIN:-target/release/fewview}"
jitter=(--exposure-jitter 0.5 --white-balance-jitter 0.05)
declare -A conditions=(
  [base]=""
  [jitter]="${jitter[*]}"
  [jitter-vignetting]="${jitter[*]} --vignetting 0.4"
  [specular-0.4]="--specular 0.4,40"
  [specular-0.6]="--specular 0.6,40"
  [jitter-specular-0.4]="${jitter[*]} --specular 0.4,40"
  [jitter-specular-0.6]="${jitter[*]} --specular 0.6,40"
  [jitter-mirror]="${jitter[*]} --mirror-floor 0.4"
  [jitter-wide]="${jitter[*]} --baseline-scale 2"
  [jitter-sh1]="${jitter[*]} --sh-degree 1"
  [jitter-5-views]="${jitter[*]} --train-views 2,6,11,16,21"
)
order=(base jitter jitter-vignetting specular-0.4 specular-0.6 jitter-specular-0.4
  jitter-specular-0.6 jitter-mirror jitter-wide jitter-sh1 jitter-5-views)
if [[ $# -gt 0 ]]; then order=("$@"); fi
runs=()
for c in "${order[@]}"; do
  [[ -v "conditions[$c]" ]] || { echo "unknown condition $c" >&2; exit 2; }
  for v in plain gf; do
    # gf as the supplement reads it (the sweep's figures predate gf's default of 2026-12-06).
    extra=""
    [[ $v == gf ]] && extra="--match-exposure false --occlusion own-depth"
    dir="$out/$c/$v"
    if [[ -f "$dir/transition.json" && "${RESCORE:-0}" == 1 ]]; then
      # shellcheck disable=SC2086
      "$bin" fusion --demo ${conditions[$c]} --variant "$v" $extra --seed 0 --rescore --out "$dir" \
        > "$out/$c/$v.rescore.log" 2>&1
    elif [[ ! -f "$dir/transition.json" ]]; then
      mkdir -p "$out/$c"
      # shellcheck disable=SC2086
      "$bin" fusion --demo ${conditions[$c]} --variant "$v" $extra --seed 0 --out "$dir" \
        > "$out/$c/$v.log" 2>&1
    fi
    runs+=("$dir")
  done
done
"$bin" fusion --table "${runs[@]}" | tee "$out/table.md"
