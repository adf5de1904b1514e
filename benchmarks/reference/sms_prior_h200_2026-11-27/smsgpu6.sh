export PYTHONPATH=~/site:$PWD WARP_CACHE_PATH=~/wc_t1 PYTHONUNBUFFERED=1
for s in caustic-slab reflective-plane caustic-slab-plane benchmarks/scenes/spheres.xml; do
  n=$(basename $s .xml); mkdir -p $OUT/$n
  (python3 benchmarks/sms_scenes.py --device cuda --width 1920 --height 1080 --frames 8 --budget 2 --ref-spp 2048 --scenes $s --out $OUT/$n > $OUT/$n/log.txt 2>&1) &
done
wait
for s in caustic-slab reflective-plane caustic-slab-plane spheres; do tail -3 $OUT/$s/log.txt; done
