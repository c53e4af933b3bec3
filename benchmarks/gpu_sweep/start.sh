#!/bin/bash
# On the GPU machine: unpack the data, then run every line of JOBS (default: the newest
# jobs_*.txt), P at a time (default 15), in a new process session so that the sweep outlives
# the device call that started it (it lasts while the machine stays warm).
here=$(cd "$(dirname "$0")" && pwd)
jobs=${JOBS:-$(ls "$here"/jobs_*.txt | tail -1)}
bash "$here/unpack_data.sh" /tmp/data
mkdir -p /tmp/runs; date +%s > /tmp/runs/start; cp "$jobs" /tmp/runs/jobs.txt
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
python3 -c "import torch; print('torch', torch.__version__)"
setsid nohup bash -c "grep -v '^#' /tmp/runs/jobs.txt | xargs -P ${P:-15} -L 1 bash $here/one.sh" \
  > /tmp/runs/xargs.log 2>&1 < /dev/null &
