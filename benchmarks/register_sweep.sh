#!/usr/bin/env bash
# Register budgets on a GPU: one kernels.py process per budget configuration, each with a kernel cache of its own.
#
#   OUT=results bash benchmarks/register_sweep.sh SCENE "P S W METHODS;P S W METHODS;..."
#
# P, S, W: GRISX_PATH_REGISTERS, GRISX_SHIFT_REGISTERS, GRISX_WALK_REGISTERS (grisx.device); METHODS: kernels.py's
# comma-separated labels. Repeat a configuration to alternate it with another in one run. Appends one JSON row per
# method to $OUT/sweep.jsonl (frame ms, phase ms, the budgets) and leaves each run's kernels JSON and log in
# $OUT/k.tgz. The twentieth session's table ("Register budgets in blocks of 64", benchmarks/README.md) came from
#   bash benchmarks/register_sweep.sh door-ajar "80 128 128 pt,restir-gi,restir-pt hybrid,restcv;64 128 80 pt,restir-gi,restir-pt hybrid,restcv;..."
set -euo pipefail
scene=$1
out=${OUT:-benchmarks/results/registers}
mkdir -p "$out/k"
IFS=';' read -ra configs <<< "$2"
for c in "${configs[@]}"; do
  read -r p s w methods <<< "$c"
  run="$out/k/r${p}_${s}_${w}_${scene}"
  mkdir -p "$run"
  GRISX_PATH_REGISTERS=$p GRISX_SHIFT_REGISTERS=$s GRISX_WALK_REGISTERS=$w WARP_CACHE_PATH="${HOME}/.cache/grisx-sweep/wc_${p}_${s}_${w}" \
    timeout 300 python3 benchmarks/kernels.py --device cuda --scene "$scene" --methods "$methods" --frames 16 --ptxas '' --out "$run" > "$run/log.txt" 2>&1 || true
  python3 - "$run/kernels_cuda.json" >> "$out/sweep.jsonl" <<'PY' || echo "no result: $run/log.txt"
import json, sys
d = json.load(open(sys.argv[1]))
for label, r in d["methods"].items():
    print(json.dumps({"scene": d["scene"], "path_registers": d["path_registers"], "shift_registers": d["shift_registers"],
                      "walk_registers": d.get("walk_registers"), "method": label, "frame_ms": r.get("frame_ms"),
                      "phase_ms": r.get("phase_ms"), "error": r.get("error")}))
PY
  tail -n 1 "$out/sweep.jsonl" | cut -c1-160
done
(cd "$out" && tar czf k.tgz k && rm -rf k)
