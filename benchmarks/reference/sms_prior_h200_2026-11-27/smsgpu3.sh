source .gpuold/setupw.sh .gpuw6 >/dev/null
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
python3 -c "import warp; print(warp.__version__)"
rm -rf ~/fdbase ~/fdold; mkdir -p ~/fdbase ~/fdold; cp -r .gpuold/fdbase/grisx ~/fdbase/; cp -r .gpuold/fdold/grisx ~/fdold/
cp -r benchmarks ~/fdbase/; cp -r benchmarks ~/fdold/
S="caustic-slab reflective-plane caustic-slab-plane benchmarks/scenes/spheres.xml"
M=sms,sms-partitioned,sms-restir
t0=$(date +%s)
for s in $S; do
  (WARP_CACHE_PATH=~/wc_new python3 .gpuold/warm1.py $s $M >> $OUT/cold_new.jsonl 2>$OUT/err_new_$(basename $s).txt) &
  (cd ~/fdbase && WARP_CACHE_PATH=~/wc_base PYTHONPATH=~/site:$HOME/fdbase python3 $OLDPWD/.gpuold/warm1.py $s $M >> $OUT/cold_base.jsonl 2>$OUT/err_base_$(basename $s).txt) &
done
(WARP_CACHE_PATH=~/wc_new python3 .gpuold/warm1.py benchmarks/scenes/spheres.xml pt >> $OUT/cold_new_pt.jsonl 2>&1) &
(cd ~/fdold && WARP_CACHE_PATH=~/wc_old PYTHONPATH=~/site:$HOME/fdold python3 $OLDPWD/.gpuold/warm1.py benchmarks/scenes/spheres.xml sms,sms-partitioned,sms-restir,pt >> $OUT/cold_old.jsonl 2>$OUT/err_old.txt) &
wait; echo "compile wall $(( $(date +%s) - t0 )) s"
cat $OUT/cold_*.jsonl
T=$PWD/.gpuold/smstime.py; SC=caustic-slab,reflective-plane,caustic-slab-plane,benchmarks/scenes/spheres.xml
WARP_CACHE_PATH=~/wc_new python3 $T after $SC sms-partitioned,sms-restir | tee $OUT/time_after.jsonl
(cd ~/fdbase && WARP_CACHE_PATH=~/wc_base PYTHONPATH=~/site:$HOME/fdbase python3 $T before $SC sms-partitioned,sms-restir) | tee $OUT/time_before.jsonl
WARP_CACHE_PATH=~/wc_new python3 $T after2 $SC sms-partitioned | tee $OUT/time_after2.jsonl
