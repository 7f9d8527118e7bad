# The GPU check, run from the repository root on a lent GPU machine with .gpu/ carried (scripts/gpu_bundle.py;
# optional packs .gpu/fitgar-pack.pt and .gpu/swingar-pack.pt from benchmarks/graph_pack.py pack, and the store
# .gpu/data/train.zarr: each step runs when its input is there, so the bundle fits the carried size):
#   bash scripts/gpu_run.sh                          # there: $OUT set, python3 with torch (CUDA)
#   DEVICE=cpu PY=.venv/bin/python OUT=/tmp/gpu-out bash scripts/gpu_run.sh   # here: the same steps, tiny sizes
# Every step runs under its own timeout within one overall deadline (BUDGET seconds), logs to $OUT/run.log and
# leaves its JSON in $OUT; a failing step does not stop the next.
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
  $PY -c "import sys, torch, numpy, zarr, igl; print(sys.version.split()[0], 'torch', torch.__version__, 'cuda', torch.version.cuda, torch.cuda.is_available(), 'numpy', numpy.__version__)" 2>&1
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
if [ "$DEVICE" = cuda ]; then
  SIZE=paper; STEPS=${STEPS:-300}; PACK_SECONDS=${PACK_SECONDS:-45}
  step cuda-tests 150 $PY -m pytest -q -p no:cacheprovider -o addopts= tests/models/test_swingar.py \
    tests/models/test_jointnet.py tests/models/layers $(ls tests/models/test_cuda*.py 2>/dev/null) \
    -k "cuda or gat_ln or lstm or gru"
  step graph-speed 150 $PY benchmarks/graph_speed.py --device cuda --swingar-vertices 11200 --fitgar-vertices 4000 \
    --threads 1 --frames 20 --batch 10 --repeats 3 --fitgar-frames 20 --name gs-cuda
  cp benchmarks/results/gs-cuda.json "$OUT/" 2>/dev/null
else
  SIZE=tiny; STEPS=${STEPS:-24}; PACK_SECONDS=${PACK_SECONDS:-5}
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
