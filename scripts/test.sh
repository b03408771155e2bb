#!/usr/bin/env bash
# The project's one test command (README quick start; `.ci/run` calls it).
# Installs what the tests need (scripts/setup.sh, a quick no-op when everything is there), then
# runs every test of the workspace in the release profile (the same profile as the binary, so
# the dependency tree compiles once). `cargo test` alone installs nothing.
# Tiers: without FEWVIEW_DATA, the workspace's tests (what a newcomer runs after the first
# build). With FEWVIEW_DATA set (CI sets it to ../shared/data), every tier in one build: the
# dataset tests and the GPU tests on lavapipe (the GPU code, feature `gpu` of the splat and
# human crates, is built into the same test build, so Burn compiles once; its wgpu stack alone
# takes longer to build than the first tier on two cores). FEWVIEW_GPU_TESTS=1 adds the GPU
# tier without the data.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/setup.sh

# Test arguments and build features of each tier.
ignored=()
features=()
if [ -n "${FEWVIEW_DATA:-}" ]; then
  FEWVIEW_DATA=$(cd "$FEWVIEW_DATA" && pwd)
  export FEWVIEW_DATA
  ignored=(--include-ignored)
  echo "data tests: on (FEWVIEW_DATA=$FEWVIEW_DATA)"
else
  echo "data tests: off (set FEWVIEW_DATA to ../shared/data to run them)"
fi

# The GPU code runs on the first adapter wgpu finds (Mesa's lavapipe on a machine without a
# GPU): the rasterizer's parity tests against the CPU rasterizer and a GPU training run (splat),
# and the PoseGaussian network against the CPU (human). Every CPU test keeps its CPU device:
# the code names its device, never Burn's default (a GPU in this build).
if [ -n "${FEWVIEW_DATA:-}" ] || [ "${FEWVIEW_GPU_TESTS:-0}" = 1 ]; then
  features=(--features fewview-splat/gpu,fewview-human/gpu)
  echo "GPU tests: on (feature gpu of the splat and human crates, built with the workspace)"
else
  echo "GPU tests: off (set FEWVIEW_DATA, or FEWVIEW_GPU_TESTS=1, to run them)"
fi

cargo test --release --workspace "${features[@]}" --no-fail-fast -- "${ignored[@]}" "$@"

# Without the data, the GPU tests that wait for a full run (the data tier runs them with every
# ignored test above).
if [ -z "${FEWVIEW_DATA:-}" ] && [ "${FEWVIEW_GPU_TESTS:-0}" = 1 ]; then
  cargo test --release --workspace "${features[@]}" --no-fail-fast -- --ignored gpu "$@"
fi
