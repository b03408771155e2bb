#!/usr/bin/env bash
# The human method on a GPU machine, in one run that writes its results to files: the network
# trained with `--device gpu` for a fixed time on each preset (steps per second from its log),
# then the CPU-preset run evaluated (table.md, metrics.json, the per-frame timing line) and its
# weights brought back.
#
# Build here (x86-64): `cargo build --release -p fewview --features gpu`, and put the binary,
# optionally xz-compressed, in BIN_DIR as `fewview`. DATA is a folder holding `human/` (the
# repository's ../shared/data, or a copy of that capture).
#
#   tools/gpu_human_check.sh BIN_DIR DATA OUT_DIR [CPU_PRESET_MINUTES] [PAPER_PRESET_MINUTES] [EVAL]
#
# The defaults (3 and 2 minutes, and about 3 for the evaluation) fit a 10-minute call; EVAL 0
# skips the evaluation (the steps per second only). A run stopped by its budget keeps a
# checkpoint that `human train --resume` continues.
set -uo pipefail
bin=$1
data=$2
out=$3
cpu_minutes=${4:-3}
paper_minutes=${5:-2}
evaluate=${6:-1}
mkdir -p "$out"
for f in "$bin"/*.xz; do [ -e "$f" ] && xz -dkf "$f"; done
chmod +x "$bin"/fewview
log() { echo "[$(date +%T)] $*" | tee -a "$out/steps.log"; }
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv >"$out/gpu.txt" 2>&1
nproc >>"$out/gpu.txt"

# Steps, and steps per second over all but the first (which prepares frames), from a run's log.
rate() {
  python3 - "$1" <<'PY'
import json, sys
steps = [json.loads(l) for l in open(sys.argv[1])]
s = [x["seconds"] for x in steps[1:]]
print(f"{len(steps)} steps, {len(s) / sum(s):.3f} steps/s after the first" if s else "no steps")
PY
}

for preset in cpu paper; do
  minutes=$cpu_minutes
  [ "$preset" = paper ] && minutes=$paper_minutes
  run=/tmp/human_$preset
  log "human train --preset $preset --device gpu for $minutes min"
  timeout $((minutes * 60 + 120)) "$bin/fewview" human train --device gpu --preset "$preset" \
    --data "$data/human" --out "$run" --iterations 1000000 --max-minutes "$minutes" \
    --checkpoint-every 500 >"$out/train_$preset.out" 2>"$out/train_$preset.log"
  log "train: exit $?; $(rate "$run/train_log.jsonl" 2>&1)"
  cp "$run/train_log.jsonl" "$out/train_log_$preset.jsonl" 2>/dev/null
done

if [ "$evaluate" = 0 ]; then
  log "done (no evaluation asked)"
  exit 0
fi
log "human eval of the cpu-preset run (inference on the CPU)"
timeout 300 "$bin/fewview" human eval --run /tmp/human_cpu --data "$data/human" \
  --out "$out/eval_cpu" >"$out/eval_cpu.out" 2>"$out/eval_cpu.log"
log "eval: exit $?"
mkdir -p "$out/run_cpu"
cp /tmp/human_cpu/{network.fvh,state.bin,split.json} "$out/run_cpu/" 2>/dev/null
log "done"
