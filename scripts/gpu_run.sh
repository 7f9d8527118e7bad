# The GPU check, run from the repository root on a lent GPU machine with .gpu/ carried (scripts/gpu_bundle.py;
# optional packs .gpu/fitgar-pack.pt and .gpu/swingar-pack.pt from benchmarks/graph_pack.py pack, and the store
# .gpu/data/train.zarr: each step runs when its input is there, so the bundle fits the carried size):
#   bash scripts/gpu_run.sh                          # there: $OUT set, python3 with torch (CUDA)
#   DEVICE=cpu PY=.venv/bin/python OUT=/tmp/gpu-out bash scripts/gpu_run.sh   # here: the same steps, tiny sizes
# Every step runs under its own timeout within one overall deadline (BUDGET seconds), logs to $OUT/run.log and
# leaves its JSON in $OUT; a failing step does not stop the next.
# LONG_SECONDS=N trains the variants of LONG_VARIANTS from the packs at once (one process each, sharing the GPU),
# N seconds each, or a variant's STEPS optimiser steps with N seconds as a cap (equal steps), the learning rate
# over each stage by LONG_SCHEDULE (cosine, the default, or constant), then the CUDA tests; curves in $OUT/long-NAME.json, weights
# in $OUT/weights/NAME/ (to be scored on the CPU machine by the library's animation). Training from the packs needs
# no wheel: a call may carry only .gpu/anny and the packs, with SKIP_TESTS=1 (the CUDA tests need the wheels).
set -u
export PYTHONUNBUFFERED=1
DEVICE=${DEVICE:-cuda}
PY=${PY:-python3}
OUT=${OUT:-/tmp/loosefit-gpu-out}
BUDGET=${BUDGET:-500}
SITE=${SITE:-/tmp/loosefit-site}
G=${G:-$PWD/.gpu}  # the bundle; set G to run from another checkout (e.g. a copy of HEAD inside it)
mkdir -p "$OUT"
LOG=$OUT/run.log
START=$SECONDS
if [ "$DEVICE" = cuda ]; then
  # training from the packs needs no wheel: a call may carry none
  compgen -G "$G/whl/*.whl" > /dev/null &&
    $PY -m pip install -q --no-index --no-deps --no-compile --target "$SITE" "$G"/whl/*.whl 2>&1 | tail -3 | tee -a "$LOG"
  export PYTHONPATH=$SITE:$PWD/src:$G  # $G holds the recorded anny package
else
  export PYTHONPATH=$PWD/src
fi
export LOOSEFIT_CACHE=/tmp/loosefit-cache
{
  echo "=== env $(date -u +%FT%TZ) DEVICE=$DEVICE budget ${BUDGET}s"
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>&1
  nproc
  $PY -c "import sys, torch, numpy; print(sys.version.split()[0], 'torch', torch.__version__, 'cuda', torch.version.cuda, torch.cuda.is_available(), 'numpy', numpy.__version__)" 2>&1
} | tee -a "$LOG"

# step NAME TIMEOUT CMD...: CMD under min(TIMEOUT, time left); logs its exit status and seconds.
step() {
  local name=$1 limit=$2; shift 2
  local left=$((BUDGET - (SECONDS - START) - 5))
  if [ "$left" -lt 15 ]; then echo "=== [$name] SKIPPED: ${left}s left" | tee -a "$LOG"; return; fi
  [ "$limit" -gt "$left" ] && limit=$left
  echo "=== [$name] start at +$((SECONDS - START))s, timeout ${limit}s: $*" | tee -a "$LOG"
  local t0=$SECONDS
  timeout -k 5 "$limit" "$@" > "$OUT/$name.log" 2>&1
  local rc=$?
  tail -25 "$OUT/$name.log" | tee -a "$LOG"
  echo "=== [$name] rc=$rc in $((SECONDS - t0))s" | tee -a "$LOG"
}
STORE=$G/data/train.zarr
CUDA_TESTS=($PY -m pytest -q -p no:cacheprovider -o addopts= tests/models/test_swingar.py tests/models/test_jointnet.py
  tests/models/layers $(ls tests/models/test_cuda*.py 2>/dev/null) -k "cuda or gat_ln or lstm or gru")
if [ "$DEVICE" = cuda ]; then
  SIZE=paper; STEPS=${STEPS:-300}; PACK_SECONDS=${PACK_SECONDS:-45}
  [ -z "${LONG_SECONDS:-}" ] && step cuda-tests 150 "${CUDA_TESTS[@]}"
  [ -z "${SKIP_SPEED:-}" ] && step graph-speed 150 $PY benchmarks/graph_speed.py --device cuda --swingar-vertices 11200 --fitgar-vertices 4000 \
    --threads 1 --frames 20 --batch 10 --repeats 3 --fitgar-frames 20 --name gs-cuda
  cp benchmarks/results/gs-cuda.json "$OUT/" 2>/dev/null
else
  SIZE=tiny; STEPS=${STEPS:-24}; PACK_SECONDS=${PACK_SECONDS:-5}
fi
# long runs at once: NAME:PACK:CONFIG[:KEY=VALUE,...[:STEPS]] each
# (SwinGar at the paper's widths takes 16-20 GiB each on this pack: three at once beside two FitGar fit an 80 GB H100,
# six beside two FitGar a 141 GB H200 with PYTORCH_CUDA_ALLOC_CONF=expandable_segments:True)
# (FitGar on the quasi-static pack, graph_pack.py pack of configs/datasets/fitgar-static.yaml, at the rate that fits it)
LONG_VARIANTS=${LONG_VARIANTS:-"swingar-a2-s0:swingar:swingar.yaml::250 swingar-a2-s1:swingar:swingar.yaml:train.seed=1:250
  swingar-gat-s0:swingar:swingar.yaml:model.alpha=null:250 fitgar-paper:fitgar-static:fitgar.yaml:train.lr=1e-3
  fitgar-cpu:fitgar-static:fitgar-cpu.yaml"}
if [ -n "${LONG_SECONDS:-}" ]; then
  echo "=== [long] start at +$((SECONDS - START))s: ${LONG_SECONDS}s each" | tee -a "$LOG"
  t0=$SECONDS
  pids=()
  for v in $LONG_VARIANTS; do
    IFS=: read -r name pack config sets steps <<< "$v"
    args=(); IFS=, read -ra kv <<< "${sets:-}"; for x in "${kv[@]}"; do args+=(--set "$x"); done
    [ -n "${steps:-}" ] && args+=(--steps "$steps")
    # SwinGar's weights are scored on the CPU machine; FitGar's curves are its scores (its weights would not fit $OUT)
    [ "$pack" = swingar ] && args+=(--save "$OUT/weights/$name")
    [ -f "$G/$pack-pack.pt" ] || { echo "=== [long] $name: no $G/$pack-pack.pt" | tee -a "$LOG"; continue; }
    OMP_NUM_THREADS=2 timeout -k 5 $((LONG_SECONDS + 150)) $PY benchmarks/graph_pack.py train --pack "$G/$pack-pack.pt" \
      --configs "$config" --seconds "$LONG_SECONDS" --evals 4 --schedule "${LONG_SCHEDULE:-cosine}" "${args[@]}" \
      --out "$OUT/long-$name.json" > "$OUT/long-$name.log" 2>&1 &
    pids+=($!)
  done
  for pid in "${pids[@]}"; do wait "$pid"; echo "=== [long] pid $pid rc=$?" | tee -a "$LOG"; done
  for f in "$OUT"/long-*.log; do echo "--- $f"; tail -3 "$f"; done | tee -a "$LOG"
  echo "=== [long] done in $((SECONDS - t0))s" | tee -a "$LOG"
  NO_PACKS=1
  # after: beside them it ran out of GPU memory (SKIP_TESTS=1: a call that carries no wheels cannot import them)
  [ "$DEVICE" = cuda ] && [ -z "${SKIP_TESTS:-}" ] && step cuda-tests 150 "${CUDA_TESTS[@]}"
fi
# the paper's widths against the CPU preset's, the same seconds each, from the packs (benchmarks/graph_pack.py)
[ -z "${NO_PACKS:-}" ] && [ -f "$G/fitgar-pack.pt" ] && step fitgar-pack $((4 * PACK_SECONDS + 40)) $PY benchmarks/graph_pack.py train \
  --pack "$G/fitgar-pack.pt" --configs fitgar.yaml,fitgar-cpu.yaml --seconds "$PACK_SECONDS" --out "$OUT/graph-pack-fitgar.json"
[ -z "${NO_PACKS:-}" ] && [ -f "$G/swingar-pack.pt" ] && step swingar-pack $((4 * PACK_SECONDS + 40)) $PY benchmarks/graph_pack.py train \
  --pack "$G/swingar-pack.pt" --configs swingar.yaml,swingar-cpu.yaml --seconds "$PACK_SECONDS" \
  --out "$OUT/graph-pack-swingar.json"
[ -d "$STORE" ] && step gpu-smoke 300 $PY benchmarks/gpu_smoke.py --store "$STORE" --device "$DEVICE" --size $SIZE \
  --steps $STEPS --out "$OUT/gpu-smoke.json"
[ "$DEVICE" = cuda ] && [ -n "${EXTRA:-}" ] && step extra 400 bash -c "$EXTRA"
echo "=== done in $((SECONDS - START))s; $OUT: $(ls "$OUT" | tr '\n' ' ')" | tee -a "$LOG"
# the device tool returns at most eight files from $OUT, each at most 16 MiB: more travel as one archive in parts
# (cat all.tgz.part-* | tar xz), beside the log
if [ "$(find "$OUT" -type f | wc -l)" -gt 8 ]; then
  tar czf "/tmp/loosefit-gpu-out.tgz" -C "$OUT" . && cp "$LOG" /tmp/loosefit-gpu-run.log && rm -rf "${OUT:?}"/* &&
    split -b 15m /tmp/loosefit-gpu-out.tgz "$OUT/all.tgz.part-" && mv /tmp/loosefit-gpu-run.log "$OUT/run.log"
fi
