#!/usr/bin/env bash
# What a GPU machine must show for training on CUDA, in one call of under ten minutes: the CUDA
# tests, `flexff bench --training` on the thesis preset (eager, CUDA graphs, every CPU core, one
# and four trainings sharing the GPU), a short `flexff evaluate --env hardware --preset thesis`
# on CUDA (its wall time, less the epochs it skips, is the whole evaluation's but for training)
# and an example machine's evaluation on CUDA, with the GPU's busy share read all along.
#
# Run from the repository root:  OUT=folder bash docs/results/training/gpu_check.sh
# with flexff installed (pip install --no-deps -e .: its built-in FMUs are entry points) or,
# where nothing can be installed, the checkout's flexff.egg-info and the missing packages on
# PYTHONPATH.
# Settings: PYTHON (default python3), EPOCHS of the short evaluation (default 8), BUDGET in
# seconds the whole check must end within (default 580). Every phase writes to $OUT as it goes,
# so what ran is kept when the budget cuts one short. docs/results/training/gpu_check.py turns
# the files into the figures of docs/results/training/gpu-check.json.
set -u
OUT=${OUT:-gpu-check}
PY=${PYTHON:-python3}
EPOCHS=${EPOCHS:-8}
BUDGET=${BUDGET:-580}
START=$(date +%s)
WORK=$(mktemp -d)
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1

phase() { echo "$(date +%s.%N) $*" | tee -a "$OUT/phases.txt"; }
left() {  # seconds to the budget's end less $1, at least 1
    local s=$((BUDGET - ($(date +%s) - START) - ${1:-0})); echo $((s > 0 ? s : 1)); }
stamped() { "$PY" -c 'import sys, time
for line in sys.stdin: print(f"{time.time():.2f} {line}", end="", flush=True)'; }
keep() {  # the small files of the runs, packed (the recordings stay behind)
    (cd "$WORK" && find . \( -name "*.json" -o -name "*.log" -o -name "*.md" \) -size -4M \
        -print0 | tar --format=posix -czf "$OUT/results.tgz" --null -T -)
}

# the GPU's busy share [%] and memory in use [GB], every 0.1 s
"$PY" - >"$OUT/gpu.csv" <<'EOF' &
import time
import pynvml
pynvml.nvmlInit()
gpu = pynvml.nvmlDeviceGetHandleByIndex(0)
while True:
    busy = pynvml.nvmlDeviceGetUtilizationRates(gpu).gpu
    used = pynvml.nvmlDeviceGetMemoryInfo(gpu).used / 1e9
    print(f"{time.time():.2f},{busy},{used:.2f}", flush=True)
    time.sleep(0.1)
EOF
SAMPLER=$!
trap 'kill $SAMPLER 2>/dev/null; keep' EXIT

phase setup
{ nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv; nproc
  "$PY" -c "import torch, casadi, fmpy, flexff.cli; print(torch.__version__, \
torch.cuda.get_device_name())"; } 2>&1 | tee "$OUT/machine.txt"
"$PY" -m compileall -q flexff fmu cosim plant controllers learning machines tests >/dev/null

# 1. side by side (none of it timed against the rest): the CUDA tests, the hardware set's
# collection (every core) and the example drive's evaluation, training on CUDA eagerly
phase parallel
( timeout "$(left 440)" "$PY" -m pytest -q -p no:cacheprovider -rs \
    tests/learning/test_devices.py tests/learning/test_training_step.py >"$OUT/tests.txt" 2>&1
  phase "tests rc=$?" ) &
SIDE=($!)
( timeout "$(left 480)" "$PY" -m flexff data collect --set hardware -o "$WORK/hw" \
    >"$WORK/collect.log" 2>&1
  phase "collect rc=$?" ) &
SIDE+=($!)
( timeout "$(left 440)" "$PY" -m flexff evaluate --config machines/examples/drive.toml \
    --device cuda -o "$WORK/drive" 2>&1 | stamped >"$WORK/drive.log"
  phase "drive rc=${PIPESTATUS[0]}" ) &
SIDE+=($!)
wait "${SIDE[@]}"  # not the sampler, which runs on
keep

# 2. the short thesis evaluation, four trainings per GPU; its steps replayed from CUDA graphs
# where the CUDA tests passed (the default this check decides), else eager
if grep -qE "[0-9]+ passed" "$OUT/tests.txt" && \
        ! grep -qE "[0-9]+ (failed|error)" "$OUT/tests.txt"; then
    sed -i 's/cuda_graphs: bool = False/cuda_graphs: bool = True/' learning/presets.py
fi
phase "evaluate graphs=$(grep -c 'cuda_graphs: bool = True' learning/presets.py)"
timeout "$(left 210)" "$PY" -m flexff evaluate --env hardware --data "$WORK/hw" \
    --preset thesis --epochs "$EPOCHS" --device cuda -o "$WORK/eval" 2>&1 | stamped \
    >"$OUT/evaluate.log"
phase "evaluate rc=${PIPESTATUS[0]}"
keep

# 3. the training bench, alone on the machine: eager, graphs and the CPU, then sharing
phase bench
timeout "$(left)" "$PY" -m flexff bench --training "$WORK/hw" --preset thesis --no-bf16 \
    -o "$OUT/bench.json" >"$WORK/bench.log" 2>&1
phase "bench rc=$?"
