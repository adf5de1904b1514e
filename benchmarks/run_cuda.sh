#!/usr/bin/env bash
# Reproduce the CUDA tables of the closing notes: every benchmark with --device cuda.
#   bash benchmarks/run_cuda.sh OUT_DIR [GROUP ...]
# GROUP: theory (toys, conditional, gradient, control_variates, manifold), poisson,
#        scene (scene.py, pt.py), restir (restir_every_scene.py, restir_gi.py, restir_pt.py),
#        gradients (gradient_domain.py: seed 000's equal-time comparison at 1920x1080, moving camera),
#        suffix (suffix_restir.py: Suffix ReSTIR vs ReSTIR PT and MMIS, 1920x1080, camera path),
#        study (grisx bench render), caustics (sms_scenes.py: seed 003's Table 1 and equal time), multigpu (multi_gpu_reference.py: needs 2 GPUs, not in the default groups).
# Default: all groups. Each script writes its JSON and PNG into OUT_DIR.
set -euo pipefail
out=${1:-benchmarks/results/cuda}
shift || true
groups=${*:-theory poisson scene restir gradients suffix study caustics}
mkdir -p "$out"
py=${PYTHON:-python3}
for g in $groups; do
  case $g in
    theory)
      $py benchmarks/toys.py --device cuda --max-trials 10000000 --out "$out"
      $py benchmarks/conditional.py --device cuda --out "$out"
      $py benchmarks/gradient.py --device cuda --out "$out"
      $py benchmarks/control_variates.py --device cuda --out "$out"
      $py benchmarks/manifold.py --device cuda --out "$out" ;;
    poisson)
      $py benchmarks/poisson.py --device cuda --out "$out" ;;
    scene)
      $py benchmarks/scene.py --device cuda --out "$out"
      $py benchmarks/pt.py --device cuda --out "$out" ;;
    restir)
      $py benchmarks/restir_every_scene.py --device cuda --jobs 9 --out "$out"
      $py benchmarks/restir_gi.py --device cuda --out "$out"
      $py benchmarks/restir_pt.py --device cuda --out "$out" ;;
    gradients)
      $py benchmarks/gradient_domain.py --device cuda --out "$out" ;;
    suffix)
      $py benchmarks/suffix_restir.py --device cuda --out "$out" ;;
    study)
      $py -m grisx bench render cornell-box door-ajar --method pt --method restir-di --method restir-gi --method restir-pt \
          --budget 5 --res 640x360 --device cuda --out "$out/study" ;;
    caustics)
      $py benchmarks/sms_scenes.py --device cuda --width 1920 --height 1080 --frames 16 --budget 5 --ref-spp 4096 --ref-method sms-partitioned --out "$out" ;;
    multigpu)
      $py benchmarks/multi_gpu_reference.py --devices cuda:0,cuda:1 --spp 4096 --out "$out/multi_gpu" ;;
    *) echo "run_cuda.sh: unknown group '$g'" >&2; exit 2 ;;
  esac
done
