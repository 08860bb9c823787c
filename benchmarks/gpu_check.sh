#!/usr/bin/env bash
# The one short GPU check (under 8 minutes): on the GPU and, beside it, on the same machine's
# CPU cores (JAX_PLATFORMS=cpu), in this order of importance:
#   1. the EMPS default identification, identify("elman", EMPS) -- first call and second call
#   2. an ensemble of K = 64 members (identify(..., keys=64)) beside one fit, LuGre and ENN
#   3. the speed table (benchmarks/speed_optim.py, 30-D Rastrigin, 100 agents)
#   4. Table 1 wall times (benchmarks/table1.py, 30-D, 30 runs, MAPSO-NMDS rows and PSO)
# Results: benchmarks/results/<name>_gpu.* (GPU) and <name>_gpu_host_cpu.* (the GPU machine's
# CPU), every file naming its device; gpu_check_gpu.md lists the steps, their wall times and
# the device. With $OUT set (the device tool), everything is also packed into
# $OUT/gpu_check.tar.gz (the tool brings back at most 8 files).
#
#   bash benchmarks/gpu_check.sh            on the GPU machine
#   bash benchmarks/gpu_check.sh --dry-run  anywhere (CPU too): tiny sizes, results under
#                                           benchmarks/results/quick/gpu_check/, never over
#                                           the committed ones
#
# Inputs the GPU machine lacks travel in benchmarks/results/quick/gpu_inputs/ (git-ignored):
# DATA_EMPS.mat (else $JAXFRIC_EMPS or ../shared/data/emps/DATA_EMPS.mat) and wheels/
# (pyswarms, future, evosax, dotmap for the speed table). Prepare them once, on the
# development machine (the GPU machine reaches no registry):
#   mkdir -p benchmarks/results/quick/gpu_inputs/wheels
#   cp ../shared/data/emps/DATA_EMPS.mat benchmarks/results/quick/gpu_inputs/
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux2014_x86_64 -d benchmarks/results/quick/gpu_inputs/wheels \
#     pyswarms==1.3.0 future==1.0.0 evosax==0.3.2 dotmap==1.3.30
# Afterwards unpack the returned gpu_check.tar.gz in the repository root and commit the files.
# The device tool call:
#   run(command="bash benchmarks/gpu_check.sh", carry=["benchmarks/results/quick/gpu_inputs"],
#       timeout_s=560)
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
DRY=0
[ "${1:-}" = "--dry-run" ] && DRY=1
PY=${PYTHON:-python3}
export PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
INPUTS=benchmarks/results/quick/gpu_inputs
if [ -d "$INPUTS/wheels" ] && ls "$INPUTS"/wheels/*.whl >/dev/null 2>&1 && [ $DRY = 0 ]; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/gpu_check_site \
    "$INPUTS"/wheels/*.whl && export PYTHONPATH="$PYTHONPATH:/tmp/gpu_check_site"
fi
EMPS=${JAXFRIC_EMPS:-}
for c in "$EMPS" ../shared/data/emps/DATA_EMPS.mat "$INPUTS/DATA_EMPS.mat"; do
  [ -n "$c" ] && [ -f "$c" ] && EMPS=$c && break
done
export JAXFRIC_EMPS=$EMPS

if [ $DRY = 1 ]; then RES=benchmarks/results/quick/gpu_check; else RES=benchmarks/results; fi
mkdir -p "$RES"
TMP=$(mktemp -d)
SUMMARY="$RES/gpu_check_gpu.md"
START=$(date +%s)
BUDGET=${GPU_CHECK_BUDGET_S:-420}   # a step starts only before this; the last may add its own cap (<= 60 s)

DEVICE=$($PY - <<'EOF'
import jax, os, platform
d = jax.devices()[0]
print(f"{getattr(d, 'device_kind', d.platform)} ({d.platform}); jax {jax.__version__}; "
      f"{os.cpu_count()} CPU cores; Python {platform.python_version()}")
EOF
)
if [ $DRY = 0 ] && ! $PY -c "import jax, sys; sys.exit(0 if jax.devices()[0].platform == 'gpu' else 1)"; then
  echo "gpu_check: no GPU here ($DEVICE); use --dry-run on a CPU" >&2
  exit 2
fi
{
  echo "# GPU check ($(date -u +%Y-%m-%dT%H:%MZ))"
  echo
  echo "Device: $DEVICE. CPU rows: the same machine with JAX_PLATFORMS=cpu."
  [ $DRY = 1 ] && echo "DRY RUN: tiny sizes, not figures."
  echo "EMPS file: ${EMPS:-none (synthetic records)}"
  echo
  echo "| step | platform | exit | wall s |"
  echo "|---|---|---|---|"
} > "$SUMMARY"

# step NAME PLATFORM(gpu|cpu) TIMEOUT_S COMMAND...
STEPS=${GPU_CHECK_STEPS:-emps_identify,speed_optim,table1,ensemble}
step() {
  local name=$1 platform=$2 limit=$3; shift 3
  case ",$STEPS," in *",$name,"*) ;; *) return ;; esac
  local now=$(( $(date +%s) - START ))
  if [ $now -ge "$BUDGET" ]; then
    echo "| $name | $platform | skipped (budget) | |" >> "$SUMMARY"; return
  fi
  local t0=$(date +%s) rc
  echo "== $name ($platform, <= ${limit}s)"
  if [ "$platform" = cpu ]; then
    JAX_PLATFORMS=cpu timeout "$limit" "$@"; rc=$?
  else
    timeout "$limit" "$@"; rc=$?
  fi
  echo "| $name | $platform | $rc | $(( $(date +%s) - t0 )) |" >> "$SUMMARY"
}

# What steps 1 and 2 share: the device's name, the EMPS record and, in a dry run, a short
# record and a token budget.
cat > "$TMP/emps_common.py" <<'EOF'
import os, sys
import jax
import jaxfric
from jaxfric import rig

tag, res, dry = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
d = jax.devices()[0]
device = f"{getattr(d, 'device_kind', d.platform)} ({d.platform})"
path = os.environ.get("JAXFRIC_EMPS")
if not path:
    print("no EMPS file: step skipped"); sys.exit(0)
data = rig.emps_friction_data(rig.load_emps(path))
opts = {}
if dry:  # the first 3000 samples and a token budget: the code path, not the figures
    data = jaxfric.FrictionData.from_arrays(data.velocity[:3000], data.friction[:3000], data.dt)
    opts = {"solver": jaxfric.MAPSO(lattice_size=3, num_generations=2),
            "refine": jaxfric.GradientRefinement(method="bfgs", max_steps=5)}
EOF

# 1. the EMPS default identification (first call compiles, second call runs the same program)
cat > "$TMP/emps.py" <<'EOF'
import csv, os, sys, time, warnings
from emps_common import data, device, dry, jaxfric, opts, res, tag
rows = []
for call in ("first (compile + run)", "second (run)"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        fit = jaxfric.identify("elman", data, key=0, **opts)
        wall = time.perf_counter() - t0
    rows.append({"device": device, "call": call, "n_samples": data.n_samples, "wall_s": round(wall, 2),
                 "valid_mse_percent": fit.metrics["valid"]["mse_percent"], "dry_run": dry,
                 **{k: round(v, 2) for k, v in fit.timings.items()}})
    print(rows[-1], flush=True)
with open(os.path.join(res, f"emps_identify_{tag}.csv"), "w", newline="") as fh:
    w = csv.DictWriter(fh, fieldnames=list(rows[0]))
    w.writeheader(); w.writerows(rows)
EOF
step emps_identify gpu 100 $PY "$TMP/emps.py" gpu "$RES" $DRY
step emps_identify cpu 60 $PY "$TMP/emps.py" gpu_host_cpu "$RES" $DRY

# 2. an ensemble of K members against one fit (identify(..., keys=K) beside identify(..., key=0))
cat > "$TMP/ensemble.py" <<'EOF2'
import csv, os, sys, time, warnings
from emps_common import data, device, dry, jaxfric, opts, res, tag
k = int(sys.argv[4])
rows = []
out = os.path.join(res, f"ensemble_emps_{tag}.csv")
runs = [("lugre", "one fit", {"key": 0}), ("lugre", f"K={k}", {"key": 0, "keys": k}),
        ("elman", f"K={k}", {"key": 0, "keys": k})]  # elman's one fit: step 1
for model, label, kw in runs:
    for call in ("first", "second"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            fit = jaxfric.identify(model, data, **kw, **opts)
            wall = time.perf_counter() - t0
        rows.append({"device": device, "model": model, "run": label, "call": call,
                     "wall_s": round(wall, 2), "dry_run": dry,
                     "train_mse_percent": fit.metrics["train"]["mse_percent"],
                     "valid_mse_percent": fit.metrics["valid"]["mse_percent"]})
        print(rows[-1], flush=True)
        with open(out, "w", newline="") as fh:  # after every row: a timeout keeps what ran
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader(); w.writerows(rows)
EOF2
if [ $DRY = 1 ]; then KE=4; else KE=64; fi
step ensemble gpu 170 $PY "$TMP/ensemble.py" gpu "$RES" $DRY $KE

# 3. the speed table (30-D Rastrigin, 100 agents, 200 generations)
if [ $DRY = 1 ]; then SP=(--dim 5 --agents 16 --generations 10 --nm-evals 200 --repeats 1 --seeds 2); else
  SP=(--function rastrigin --agents 100 --generations 200 --repeats 3); fi
step speed_optim gpu 60 $PY benchmarks/speed_optim.py "${SP[@]}" --out "$RES" --tag gpu
step speed_optim cpu 50 $PY benchmarks/speed_optim.py "${SP[@]}" --out "$RES" --tag gpu_host_cpu

# 4. Table 1 wall times (the swarm rows of one function; each platform into its own folder)
if [ $DRY = 1 ]; then T1=(--quick --functions sphere --rows swarm --no-maga); else
  T1=(--dim 30 --runs 30 --functions rastrigin --rows swarm --no-maga); fi
for plat in gpu cpu; do
  tag=gpu; [ $plat = cpu ] && tag=gpu_host_cpu
  step table1 $plat 55 $PY benchmarks/table1.py "${T1[@]}" --out "$TMP/table1_$tag"
  for f in "$TMP/table1_$tag"/table1.*; do
    [ -f "$f" ] && cp "$f" "$RES/table1_${tag}.${f##*.}"
  done
done


echo >> "$SUMMARY"
echo "Whole script: $(( $(date +%s) - START )) s." >> "$SUMMARY"
cat "$SUMMARY"
if [ -n "${OUT:-}" ]; then
  tar czf "$OUT/gpu_check.tar.gz" "$RES"/*_gpu.* "$RES"/*_gpu_host_cpu.* 2>/dev/null
  cp "$SUMMARY" "$OUT/"
fi
rm -rf "$TMP"
