# usage: bash .gpuw/gd_ab.sh SCENE   (pair-reuse ablations beside ours and B.1)
mkdir -p ~/wc_gd; [ -f ~/wc_gd/.unpacked ] || { tar xJf .gpuw/wc_gd.tar.xz -C ~/wc_gd && touch ~/wc_gd/.unpacked; }
PYTHONPATH=~/site:$PWD WARP_CACHE_PATH=~/wc_gd timeout ${GD_TIMEOUT:-270} python benchmarks/gradient_domain.py --device cuda --scenes $1 --frames 8 --eval-frames 2 --calibration-frames 3 --ref-spp 256 --methods ${GD_METHODS:-ours ours-no-pair-spatial ours-no-pair-temporal B.1} --out $OUT/gdab_$1 2>&1 | grep -v "^Module\|^Warp" | tail -n 9
