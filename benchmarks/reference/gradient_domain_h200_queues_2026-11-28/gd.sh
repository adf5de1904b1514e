# usage: bash .gpuw/gd.sh SCENE
mkdir -p ~/wc_gd; [ -f ~/wc_gd/.unpacked ] || { tar xJf .gpuw/wc_gd.tar.xz -C ~/wc_gd && touch ~/wc_gd/.unpacked; }
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
PYTHONPATH=~/site:$PWD WARP_CACHE_PATH=~/wc_gd timeout ${GD_TIMEOUT:-540} python benchmarks/gradient_domain.py --device cuda --scenes $1 --frames 8 --eval-frames 2 --calibration-frames 3 --ref-spp 256 --out $OUT/gd_$1 2>&1 | tail -n 12
