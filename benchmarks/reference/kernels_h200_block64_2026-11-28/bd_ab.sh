# usage: bash .gpuw/bd_ab.sh "SCENES" "METHODS" "BDS" [MATCH]   (Warp in ~/site); BD 0 = the tree's own launches
M=$2; BDS=$3; export BD_MATCH=${4:-.}
export PYTHONPATH=~/site:$PWD WARP_CACHE_PATH=~/wcache
i=0
for sc in $1; do for b in $BDS; do
  i=$((i+1)); mkdir -p $OUT/r${i}_bd$b
  BD=$b timeout 280 python .gpuw/bd.py --device cuda --ptxas '' --scene $sc --methods "$M" --frames ${FRAMES:-16} --camera ${CAMERA:-static} --out $OUT/r${i}_bd$b/$sc 2>&1 | grep -i "error\|Trace" | tail -n 5
  echo "r$i bd$b $sc done $SECONDS"
done; done
