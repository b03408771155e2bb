#!/usr/bin/env bash
# Builds and packs what the GPU scripts need on a machine that has a GPU but no toolchain, into
# one folder of the repository (ignored by git) that a remote call can carry:
#
#   gpu_carry/bin/{fewview,splat_tests,human_gpu_tests}.xz   the binaries, compressed
#   gpu_carry/lego/nerf_synthetic/lego                       for tools/gpu_train_check.sh
#   gpu_carry/human/human                                    for tools/gpu_human_check.sh
#
#   tools/gpu_pack.sh [DATA]        DATA: the datasets folder (default $FEWVIEW_DATA)
#
# Then, on the GPU machine, from the repository root (each call within 10 minutes; a call that
# carries more than about 64 MiB may be refused, so the two data sets go in separate calls):
#
#   tools/gpu_check.sh gpu_carry/bin OUT/raster && \
#     tools/gpu_train_check.sh gpu_carry/bin gpu_carry/lego OUT/train 300
#   tools/gpu_human_check.sh gpu_carry/bin gpu_carry/human OUT/human 1 1 0
#
# Prints each part's size.
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
xz -T0 -6 -c target/release/fewview >"$out/bin/fewview.xz"
xz -T0 -6 -c "$splat_tests" >"$out/bin/splat_tests.xz"
xz -T0 -6 -c "$human_tests" >"$out/bin/human_gpu_tests.xz"
cp -r "$data/nerf_synthetic/lego" "$out/lego/nerf_synthetic/"
cp -r "$data/human" "$out/human/"
du -sh "$out/bin" "$out/lego" "$out/human"
