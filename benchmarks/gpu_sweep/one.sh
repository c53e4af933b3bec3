#!/bin/bash
# One generator run of a sweep: NAME FOLD EPOCHS EVAL_EVERY SEED [KEY=VALUE ...], from the
# fold's config and published denoiser, into /tmp/runs/NAME. A NAME listed in /tmp/runs/skip
# is skipped (to drop queued jobs while a sweep runs).
grep -qx "$1" /tmp/runs/skip 2>/dev/null && exit 0
name=$1 fold=$2 ep=$3 ev=$4 seed=$5; shift 5
sets=(--set generator.epochs=$ep --set generator.eval_every=$ev)
for kv in "$@"; do sets+=(--set "$kv"); done
repo=$(cd "$(dirname "$0")/../.." && pwd)
out=/tmp/runs/$name; mkdir -p "$out"
start=$(date +%s)
OMP_NUM_THREADS=1 PYTHONPATH=$repo/src python3 -c \
  "import sys; from trajpref.cli import main; sys.exit(main())" \
  train generator --config "$repo/configs/$fold.yaml" --out "$out" \
  --denoiser "$repo/models/$fold/denoiser.safetensors" --data-root /tmp/data --seed "$seed" \
  --device "${DEVICE:-cuda}" --no-progress "${sets[@]}" > "$out/train.log" 2>&1
echo "$name rc=$? seconds=$(( $(date +%s) - start ))" >> /tmp/runs/done.txt
