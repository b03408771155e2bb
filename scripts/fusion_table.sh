#!/usr/bin/env bash
# The fusion paper's method, its alternatives and the per-photo appearance model side by side:
# plain, (a)-(e), gf as the supplement reads (its references as they are, hidden by the virtual
# view's depth), affine (plain with a colour transform per photo), gf+affine and gf with its
# references brought to one exposure and tested against each other (gf-me-occ, gf's default
# since 2026-12-06), seeds 0
# and 1, on the demo scene with a phone's exposure (0.5 EV, 5 % white balance) and its highlight
# at full strength (0.4, 40), and on LLFF fern 3-view with the same jitter; then one Markdown
# table per scene (docs/guide/fusion.md).
#
#   scripts/fusion_table.sh OUT [demo|fern|all] [SEED ...]
#
# About 5 minutes a demo run and 6-12 a fern run on 2 cores (knn-color, l1-virtual and poisson
# are the slow ones). Finished runs are kept: run it again to fill in what is missing, or with
# RESCORE=1 to score their transitions again without training.
set -euo pipefail
out="${1:?usage: $0 OUT_DIR [demo|fern|all] [SEED ...]}"
which="${2:-all}"
shift $(( $# < 2 ? $# : 2 ))
seeds=("${@:-0 1}")
read -r -a seeds <<< "${seeds[*]}"
bin="${FEWVIEW_BIN:-target/release/fewview}"
jitter=(--exposure-jitter 0.5 --white-balance-jitter 0.05)
# name, then the flags of that variant
variants=(
  "plain|--variant plain"
  "sparse-init|--variant sparse-init"
  "knn-color|--variant knn-color"
  "tv|--variant tv"
  "l1-virtual|--variant l1-virtual"
  "poisson|--variant poisson"
  "gf|--variant gf --match-exposure false --occlusion own-depth"
  "affine|--variant plain --appearance affine"
  "gf+affine|--variant gf --appearance affine --match-exposure false --occlusion own-depth"
  "gf-me-occ|--variant gf --match-exposure --occlusion meshes"
)
run_scene() {
  local scene="$1"; shift
  local runs=()
  for seed in "${seeds[@]}"; do
    for entry in "${variants[@]}"; do
      local name="${entry%%|*}" flags="${entry#*|}"
      local dir="$out/$scene/seed$seed/$name"
      if [[ -f "$dir/transition.json" && "${RESCORE:-0}" == 1 ]]; then
        # shellcheck disable=SC2086
        "$bin" fusion "$@" $flags --seed "$seed" --rescore --out "$dir" > "$dir.rescore.log" 2>&1
      elif [[ ! -f "$dir/transition.json" ]]; then
        mkdir -p "$out/$scene/seed$seed"
        # shellcheck disable=SC2086
        "$bin" fusion "$@" $flags --seed "$seed" --out "$dir" > "$dir.log" 2>&1
      fi
      runs+=("$dir")
    done
  done
  "$bin" fusion --table "${runs[@]}" | tee "$out/$scene/table.md"
}
case "$which" in
  demo) run_scene demo --demo "${jitter[@]}" --specular 0.4,40 ;;
  fern) run_scene fern --data "${FEWVIEW_DATA:?set FEWVIEW_DATA}/llff/fern" "${jitter[@]}" ;;
  all)
    run_scene demo --demo "${jitter[@]}" --specular 0.4,40
    run_scene fern --data "${FEWVIEW_DATA:?set FEWVIEW_DATA}/llff/fern" "${jitter[@]}" ;;
  *) echo "unknown scene set $which (demo, fern or all)" >&2; exit 2 ;;
esac
