# usage: bash .gpuw/ncu_pt.sh TAG   (Warp in ~/site; AOT cubins in .gpuw/wcache_cap.tar.xz)
export PYTHONPATH=~/site:$PWD WARP_CACHE_PATH=~/wcache
mkdir -p ~/wcache && tar xJf .gpuw/wcache_cap.tar.xz -C ~/wcache
NCU=$(command -v ncu || ls /usr/local/cuda*/bin/ncu /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | head -1)
echo "ncu: $NCU"
[ -z "$NCU" ] && exit 3
python .gpuw/ncu_drive.py >/dev/null 2>&1   # warm the kernel cache outside the profiler
$NCU --target-processes all --kernel-name "regex:sample_pass|initial_pass|settle_pass|spatial_canonical_pass|spatial_merge_pass|temporal_canonical_pass|temporal_merge_pass" \
  --launch-count 9 --section SpeedOfLight --section LaunchStats --section Occupancy --section WarpStateStats --section MemoryWorkloadAnalysis \
  --metrics l1tex__t_requests_pipe_lsu_mem_local_op_ld.sum,l1tex__t_requests_pipe_lsu_mem_local_op_st.sum,l1tex__t_sectors_pipe_lsu_mem_global_op_ld.sum,l1tex__t_requests_pipe_lsu_mem_global_op_ld.sum,smsp__thread_inst_executed_per_inst_executed.ratio \
  --csv --page details python .gpuw/ncu_drive.py > $OUT/ncu_$1.csv 2> $OUT/ncu_$1.err
echo rc $?; tail -5 $OUT/ncu_$1.err; wc -l $OUT/ncu_$1.csv
