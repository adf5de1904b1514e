# usage: bash .gpuw/moving.sh SCENE METHOD "trees"  (frame_ms, moving camera, 1080p)
for t in $3; do
  case $t in base) P=~/site:$PWD/.gpub;; reg) P=~/site:$PWD/.gpur;; pat) P=~/site:$PWD/.gpuq;; *) P=~/site:$PWD;; esac
  PYTHONPATH=$P WARP_CACHE_PATH=~/wc_$t timeout 200 python benchmarks/frame_ms.py $1 $2 --frames 13 --camera path --tag $t --out $OUT/moving.jsonl | python3 -c "import json,sys; r=json.loads(sys.stdin.read()); print(r['tag'], r['scene'], r['method'], 'moving', round(r['frame_ms'],2), {k: round(v,2) for k,v in r['passes'].items() if v>0.5})"
done
