source .gpuold/setupw.sh .gpuw6 >/dev/null
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
rm -rf ~/fdprev; mkdir -p ~/fdprev; cp -r .gpuold/fdprev/grisx ~/fdprev/; cp -r benchmarks ~/fdprev/
# A: each method alone in a fresh cache, two streams (two scenes) at a time
for s in caustic-slab benchmarks/scenes/spheres.xml; do
  ( for m in sms sms-partitioned sms-restir; do d=~/wc_cold_$(basename $s)_$m; rm -rf $d; WARP_CACHE_PATH=$d python3 .gpuold/warm2.py $s $m 2>/dev/null; done >> $OUT/cold_iso.jsonl ) &
done
# B: the tree before the loop change, compiled meanwhile
(cd ~/fdprev && WARP_CACHE_PATH=~/wc_prev PYTHONPATH=~/site:$HOME/fdprev python3 $OLDPWD/.gpuold/warm1.py caustic-slab sms-restir > /dev/null 2>&1; cd ~/fdprev && WARP_CACHE_PATH=~/wc_prev PYTHONPATH=~/site:$HOME/fdprev python3 $OLDPWD/.gpuold/warm1.py benchmarks/scenes/spheres.xml sms-restir >/dev/null 2>&1) &
wait
python3 -c "
import json
for l in open('$OUT/cold_iso.jsonl'): d=json.loads(l); print(d['scene'], d['method'], d['first_use_s'], [x[:160] for x in d['loads'] if 'sms' in x])
"
T=$PWD/.gpuold/smstime.py
WARP_CACHE_PATH=~/wc_cold_caustic-slab_sms-restir python3 $T after caustic-slab sms-restir | tee $OUT/time_after.jsonl
WARP_CACHE_PATH=~/wc_cold_spheres.xml_sms-restir python3 $T after benchmarks/scenes/spheres.xml sms-restir | tee -a $OUT/time_after.jsonl
(cd ~/fdprev && WARP_CACHE_PATH=~/wc_prev PYTHONPATH=~/site:$HOME/fdprev python3 $T before caustic-slab,benchmarks/scenes/spheres.xml sms-restir) | tee $OUT/time_before.jsonl
WARP_CACHE_PATH=~/wc_cold_caustic-slab_sms-restir python3 $T after2 caustic-slab sms-restir | tee -a $OUT/time_after.jsonl
WARP_CACHE_PATH=~/wc_cold_spheres.xml_sms-restir python3 $T after2 benchmarks/scenes/spheres.xml sms-restir | tee -a $OUT/time_after.jsonl
