#!/usr/bin/env bash
# Training on a GPU machine, in one run that writes its results to files: the training-step
# benchmark on the GPU and on the CPU, then lego with all 100 training views (5000 iterations,
# the README's CPU run) with `--device gpu`, its progress lines and its metrics.
#
# Build here (x86-64): `cargo build --release -p fewview --features gpu`, and put the binary,
# optionally xz-compressed, in BIN_DIR as `fewview`. DATA is a folder holding
# `nerf_synthetic/lego` (the repository's ../shared/data, or a copy of that one scene).
#
#   tools/gpu_train_check.sh BIN_DIR DATA OUT_DIR [SECONDS] [ITERATIONS]
#
# SECONDS bounds the lego run (default 400, so that the whole script fits a 10-minute call); a
# run stopped by it leaves its last progress line in train.log and a checkpoint that `--resume`
# continues. ITERATIONS is the lego run's length (default 5000, the CPU comparison's; the
# GPU issue's figure is 30000, over several calls with `--resume`).
set -uo pipefail
bin=$1
data=$2
out=$3
limit=${4:-400}
iterations=${5:-5000}
mkdir -p "$out"
for f in "$bin"/*.xz; do [ -e "$f" ] && xz -dkf "$f"; done
chmod +x "$bin"/fewview
log() { echo "[$(date +%T)] $*" | tee -a "$out/steps.log"; }
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv >"$out/gpu.txt" 2>&1
nproc >>"$out/gpu.txt"

for device in gpu cpu; do
  log "training-step bench on the $device"
  timeout 60 "$bin/fewview" bench --device "$device" --only train --train-steps 100 \
    --json "$out/bench_train_$device.json" >"$out/bench_train_$device.log" 2>&1
  log "bench: exit $?"
done

log "lego, 100 views, $iterations iterations, --device gpu (limit ${limit} s)"
start=$(date +%s)
timeout "$limit" "$bin/fewview" train --device gpu --data "$data/nerf_synthetic/lego" \
  --n-train 100 --iterations "$iterations" --out /tmp/lego_gpu >"$out/train.out" 2>"$out/train.log"
log "train: exit $? after $(($(date +%s) - start)) s"
cp /tmp/lego_gpu/metrics.json "$out/lego_metrics.json" 2>/dev/null
cp /tmp/lego_gpu/config.json "$out/lego_config.json" 2>/dev/null
