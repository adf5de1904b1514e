# usage: bash .gpuw/cuts_ab.sh SCENE "METHODS" [order]  (Warp in ~/site; .gpub = the tree before; packs in .gpuw)
sc=$1; M=$2; order=${3:-"new base"}
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
for t in new base; do mkdir -p ~/wc_$t; [ -f ~/wc_$t/.unpacked ] || { tar xJf .gpuw/wc_$t.tar.xz -C ~/wc_$t && touch ~/wc_$t/.unpacked; }; done
for t in $order; do
  if [ $t = base ]; then P=~/site:$PWD/.gpub; else P=~/site:$PWD; fi
  mkdir -p $OUT/$t
  PYTHONPATH=$P WARP_CACHE_PATH=~/wc_$t timeout 280 python benchmarks/kernels.py --device cuda --ptxas '' --scene $sc --methods "$M" --frames 16 --out $OUT/$t/$sc 2>&1 | grep -v "^  " | tail -n 40 | sed "s/^/$t $sc /"
done
