# usage: bash .gpuw/cuts_ab.sh SCENE "METHODS" [trees]  (Warp in ~/site; trees: new = this tree, base = .gpub, reg = .gpur; packs .gpuw/wc_TREE.tar.xz)
sc=$1; M=$2; order=${3:-"new base"}
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
for t in $order; do mkdir -p ~/wc_$t; [ -f ~/wc_$t/.unpacked ] || { tar xJf .gpuw/wc_$t.tar.xz -C ~/wc_$t && touch ~/wc_$t/.unpacked; }; done
for t in $order; do
  case $t in base) P=~/site:$PWD/.gpub;; reg) P=~/site:$PWD/.gpur;; pat) P=~/site:$PWD/.gpuq;; *) if [ -d .gpu_$t ]; then P=~/site:$PWD/.gpu_$t; else P=~/site:$PWD; fi;; esac
  mkdir -p $OUT/$t
  PYTHONPATH=$P WARP_CACHE_PATH=~/wc_$t timeout 280 python benchmarks/kernels.py --device cuda --ptxas '' --scene $sc --methods "$M" --frames ${FRAMES:-16} --camera ${CAMERA:-static} --out $OUT/$t/$sc${CAMERA:+_$CAMERA} 2>&1 | grep -v "^  " | tail -n 40 | sed "s/^/$t $sc /"
done
