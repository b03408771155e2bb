#!/usr/bin/env bash
# The GPU rasterizer's checks on a machine with an NVIDIA GPU, in one run that writes its results
# to files: the parity tests (GPU against the CPU rasterizer), `fewview bench --device gpu` on 1M
# Gaussians at about one megapixel, and gsplat's rasterization() timed on the same Gaussians and
# camera (tools/gsplat_compare.py; gsplat compiles its CUDA while the parity tests run).
#
# Build here (x86-64): `cargo build --release -p fewview --features gpu` and the splat crate's
# test binary (`cargo test --release -p fewview-splat --features gpu --no-run`), then put them,
# optionally xz-compressed, in BIN_DIR as `fewview` and `splat_tests`. Optionally also the
# network's GPU test (`cargo test --release -p fewview-human --features gpu --test gpu_network
# --no-run`) as `human_gpu_tests`.
#
#   tools/gpu_check.sh BIN_DIR OUT_DIR
#
# The machine needs the Vulkan loader (libvulkan1) and the NVIDIA driver's Vulkan ICD; gsplat
# needs PyTorch with CUDA, nvcc and the gsplat wheel on PYTHONPATH.
set -uo pipefail
here=$(dirname "$0")
bin=$1
out=$2
mkdir -p "$out"
for f in "$bin"/*.xz; do [ -e "$f" ] && xz -dkf "$f"; done
chmod +x "$bin"/fewview "$bin"/splat_tests
log() { echo "[$(date +%T)] $*" | tee -a "$out/steps.log"; }
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv >"$out/gpu.txt" 2>&1
nproc >>"$out/gpu.txt"

# The same settings for gsplat's build and its use (another TORCH_CUDA_ARCH_LIST would rebuild).
export TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=12 TORCH_EXTENSIONS_DIR=/tmp/torch_ext PYTHONUNBUFFERED=1
log "gsplat: compiling its CUDA extension in the background"
(
  timeout 300 python3 "$here/gsplat_compare.py" --build-only --json "$out/gsplat_build.json" \
    >"$out/gsplat_build.log" 2>&1
) &
build=$!

for reduction in plane grouped tree; do
  log "parity tests ($reduction reduction; plane and grouped fall back to the tree without plane sums)"
  FEWVIEW_GPU_REDUCTION=$reduction timeout 120 "$bin/splat_tests" --include-ignored --nocapture \
    --test-threads 1 gpu:: >"$out/parity_$reduction.log" 2>&1
  log "parity tests: exit $?"
done

if [ -e "$bin/human_gpu_tests" ]; then
  chmod +x "$bin/human_gpu_tests"
  log "PoseGaussian network: GPU against CPU"
  timeout 60 "$bin/human_gpu_tests" --nocapture >"$out/human_network.log" 2>&1
  log "network test: exit $?"
fi

log "waiting for the gsplat build"
wait "$build"
log "gsplat build: exit $?"

for reduction in plane grouped tree; do
  log "fewview bench --device gpu ($reduction)"
  FEWVIEW_GPU_REDUCTION=$reduction timeout 100 "$bin/fewview" bench --device gpu --only raster \
    --gaussians 1000000 --raster-size 1155x866 --runs 10 --write-scene /tmp/scene \
    --json "$out/bench_gpu_$reduction.json" >"$out/bench_$reduction.log" 2>&1
  log "bench: exit $?"
done

log "gsplat on the same scene"
timeout 200 python3 "$here/gsplat_compare.py" \
  --ply /tmp/scene/scene.ply --cameras /tmp/scene/cameras.json --json "$out/gsplat.json" \
  >"$out/gsplat.log" 2>&1
log "gsplat: exit $?"
