#!/usr/bin/env bash
# The project's one test command (README quick start; `.ci/run` calls it).
# Installs what the tests need (scripts/setup.sh, a quick no-op when everything is there), then
# runs every test of the workspace in the release profile (the same profile as the binary, so
# the dependency tree compiles once). `cargo test` alone installs nothing.
# Tiers: without FEWVIEW_DATA, the workspace's tests (what a newcomer runs after the first
# build). With FEWVIEW_DATA set (CI sets it to ../shared/data), every tier: the dataset tests
# and the GPU tests on lavapipe, whose build of Burn's wgpu stack alone takes longer than the
# first tier on two cores. FEWVIEW_GPU_TESTS=1 adds the GPU tier without the data.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/setup.sh

extra=()
if [ -n "${FEWVIEW_DATA:-}" ]; then
  FEWVIEW_DATA=$(cd "$FEWVIEW_DATA" && pwd)
  export FEWVIEW_DATA
  extra+=(--include-ignored)
  echo "data tests: on (FEWVIEW_DATA=$FEWVIEW_DATA)"
else
  echo "data tests: off (set FEWVIEW_DATA to ../shared/data to run them)"
fi

cargo test --release --workspace --no-fail-fast -- "${extra[@]}" "$@"

# The GPU code (feature `gpu`, off in the workspace build), on the first adapter wgpu finds
# (Mesa's lavapipe on a machine without a GPU): the rasterizer's parity tests against the CPU
# rasterizer and a GPU training run (splat), and the PoseGaussian network against the CPU
# (human). Only the targets that hold GPU tests are built.
if [ -z "${FEWVIEW_DATA:-}" ] && [ "${FEWVIEW_GPU_TESTS:-0}" != 1 ]; then
  echo "GPU tests: off (set FEWVIEW_DATA, or FEWVIEW_GPU_TESTS=1, to run them)"
  exit 0
fi
echo "GPU tests: feature gpu, splat and human crates"
cargo test --release -p fewview-splat -p fewview-human \
  --features fewview-splat/gpu,fewview-human/gpu \
  --lib --test gpu_training --test gpu_network -- --include-ignored gpu "$@"
