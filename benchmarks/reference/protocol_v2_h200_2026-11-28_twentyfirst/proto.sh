# usage: bash .gpuw/proto19.sh "SCENES" METHODS TAG   (Warp in ~/site)
export PYTHONPATH=~/site:$PWD WARP_CACHE_PATH=~/wcache
mkdir -p ~/wcache ~/refc
python benchmarks/protocol.py --device cuda --scenes "$1" --methods "$2" \
  --reference-spp 512 --jobs 8 --reference-cache ~/refc --out "$OUT/proto_$3" 2>&1 | grep -v "^Module\|^Warp" | grep -v "^\[" | tail -40
