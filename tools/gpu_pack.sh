#!/usr/bin/env bash
# Builds and packs what the GPU scripts need on a machine that has a GPU but no toolchain, into
# one folder of the repository (ignored by git) that a remote call can carry:
#
#   gpu_carry/bin/{fewview,splat_tests,human_gpu_tests}.xz   the binaries, stripped, compressed
#   gpu_carry/lego/nerf_synthetic/lego                       for tools/gpu_train_check.sh
#   gpu_carry/human/human                                    for tools/gpu_human_check.sh
#
#   tools/gpu_pack.sh [DATA]        DATA: the datasets folder (default $FEWVIEW_DATA)
#
# A remote call carries the repository's tracked files (about 23 MB) and what it names, 64 MiB
# in all, so the work goes in three calls, each within 10 minutes and naming what it needs:
#
#   1. bin/fewview.xz, bin/splat_tests.xz (and gsplat's wheel):
#        tools/gpu_check.sh gpu_carry/bin OUT/raster
#   2. bin/fewview.xz, lego:
#        tools/gpu_train_check.sh gpu_carry/bin gpu_carry/lego OUT/train 300
#   3. bin/fewview.xz, bin/human_gpu_tests.xz (the human capture does not fit beside them):
#        xz -dkf gpu_carry/bin/*.xz && chmod +x gpu_carry/bin/{fewview,human_gpu_tests}
#        gpu_carry/bin/human_gpu_tests --nocapture
#        gpu_carry/bin/fewview bench --device gpu --only human --human-frames 20 --json OUT/h.json
#
# tools/gpu_human_check.sh (training on the capture itself) needs a call of its own with
# fewview and the capture, over the limit today. Prints each part's size.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
data=${1:-${FEWVIEW_DATA:?give the datasets folder or set FEWVIEW_DATA}}
out=$root/gpu_carry
cd "$root"

# The path of the test binary cargo names for a `--no-run` build (the last executable it lists).
test_binary() {
  cargo test --release "$@" --no-run --message-format=json 2>/dev/null |
    python3 -c '
import json, sys
paths = [m["executable"] for m in map(json.loads, sys.stdin)
         if m.get("reason") == "compiler-artifact" and m.get("executable")]
print(paths[-1])'
}

cargo build --release -p fewview --features gpu
splat_tests=$(test_binary -p fewview-splat --features gpu --lib)
human_tests=$(test_binary -p fewview-human --features gpu --test gpu_network)

rm -rf "$out"
mkdir -p "$out/bin" "$out/lego/nerf_synthetic" "$out/human"
pack() {
  local stripped
  stripped=$(mktemp)
  strip -o "$stripped" "$1"
  xz -T0 -9e -c "$stripped" >"$out/bin/$2.xz"
  rm -f "$stripped"
}
pack target/release/fewview fewview
pack "$splat_tests" splat_tests
pack "$human_tests" human_gpu_tests
cp -r "$data/nerf_synthetic/lego" "$out/lego/nerf_synthetic/"
cp -r "$data/human" "$out/human/"
du -sh "$out"/bin/* "$out/lego" "$out/human"
