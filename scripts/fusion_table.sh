#!/usr/bin/env bash
# The fusion paper's method and its alternatives side by side: plain and (a)-(f), seed 0, on the demo
# scene and on LLFF fern 3-view, then one Markdown table per scene (README, "Gradient-domain
# fusion").
#
#   scripts/fusion_table.sh OUT [demo|fern|all]
#
# About 5 minutes a demo run and 8-10 a fern run on 2 cores (the knn-color and poisson variants
# are slower).
set -euo pipefail
out="${1:?usage: $0 OUT_DIR [demo|fern|all]}"
which="${2:-all}"
bin="${FEWVIEW_BIN:-target/release/fewview}"
variants=(plain sparse-init knn-color tv l1-virtual poisson gf)
run_scene() {
  local scene="$1"; shift
  mkdir -p "$out/$scene"
  local runs=()
  for v in "${variants[@]}"; do
    if [[ ! -f "$out/$scene/$v/transition.json" ]]; then
      "$bin" fusion "$@" --variant "$v" --seed 0 --out "$out/$scene/$v" > "$out/$scene/$v.log" 2>&1
    fi
    runs+=("$out/$scene/$v")
  done
  "$bin" fusion --table "${runs[@]}" | tee "$out/$scene/table.md"
}
case "$which" in
  demo) run_scene demo --demo ;;
  fern) run_scene fern --data "${FEWVIEW_DATA:?set FEWVIEW_DATA}/llff/fern" ;;
  all)
    run_scene demo --demo
    run_scene fern --data "${FEWVIEW_DATA:?set FEWVIEW_DATA}/llff/fern" ;;
  *) echo "unknown scene set $which (demo, fern or all)" >&2; exit 2 ;;
esac
