# usage: bash .gpuw/proto18b.sh SCENES TAG   (Warp in ~/site; AOT cubins in .gpuw/wc_new.tar.xz)
export PYTHONPATH=~/site:$PWD WARP_CACHE_PATH=~/wcache
mkdir -p ~/wcache ~/refc && [ -f ~/wcache/.unpacked ] || { tar xJf .gpuw/wc_new.tar.xz -C ~/wcache && touch ~/wcache/.unpacked; }
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
python benchmarks/protocol.py --device cuda --scenes "$1" --methods "pt,restir-gi" \
  --reference-spp 512 --jobs 8 --reference-cache ~/refc --out "$OUT/proto_$2" 2>&1 | grep -v "^Module\|^Warp" | grep -v "^\[" | tail -40
