#!/bin/bash
# On the GPU machine: report every 60 s for up to $1 seconds, or until every job has finished.
total=$(grep -vc '^#' /tmp/runs/jobs.txt); end=$(( $(date +%s) + ${1:-540} ))
while [ "$(date +%s)" -lt "$end" ]; do
  n=$(cat /tmp/runs/done.txt 2>/dev/null | wc -l)
  echo "t=$(( $(date +%s) - $(cat /tmp/runs/start) ))s done=$n/$total" \
    "$(nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader)"
  [ "$n" -ge "$total" ] && break
  sleep 60
done
cat /tmp/runs/done.txt 2>/dev/null
