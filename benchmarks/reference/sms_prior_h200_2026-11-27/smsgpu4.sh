export PYTHONPATH=~/site:$PWD PYTHONUNBUFFERED=1
(WARP_CACHE_PATH=~/wc_new LABEL=after python3 .gpuold/smsbias.py cuda sms,sms-partitioned 75 256 > $OUT/bias_after.txt 2>&1) &
(cp .gpuold/smsbias.py ~/fdold/ && cd ~/fdold && WARP_CACHE_PATH=~/wc_old LABEL=before OUT=$OUT PYTHONPATH=~/site:$HOME/fdold python3 smsbias.py cuda sms,sms-partitioned 75 256 > $OUT/bias_before.txt 2>&1) &
wait
grep -v Warn $OUT/bias_after.txt | tail -4; grep -v Warn $OUT/bias_before.txt | tail -4
