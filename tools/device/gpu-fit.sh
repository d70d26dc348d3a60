#!/usr/bin/env bash
# Issue 36 item 1 on a lent GPU: the tree fit on the GPU (server/bake/src/gpu_fit.rs, fit.wgsl).
# Same set-up as gpu-check.sh (tools/device/prepare.sh here first; .dev and .gl carried); one
# call: `bash tools/device/gpu-fit.sh` (about 5 min on an H200).
# 1. The GPU fit's tests against the CPU fit, on this device's own rounding.
# 2. The 565K- and 2.26M-vertex bunnies (2 and 3 subdivisions, default ground) baked with
#    `--backend gpu`, the trees fitted on the GPU and then (BSPVT_GPU_FIT=0) on the CPU: wall
#    clock from start to file written, faces the GPU left to the CPU, and `cmp` of the files.
set -u
. tools/device/setup.sh
step fit-tests 240 "$D/t_bake_lib" --nocapture --test-threads 1 gpu_fit
python3 tools/device/subdivide.py "$M/bunny.ply" /tmp/bunny_x8.ply 3
for m in x4 x8; do
  for fit in 1 0; do
    s=$(date +%s.%N)
    BSPVT_GPU_FIT=$fit BSPVT_GPU_TIMING=1 timeout 400 "$D/bspvt-server" bake --mesh /tmp/bunny_$m.ply \
      --backend gpu --out /tmp/bunny-$m-fit$fit.bspvt --stats "$OUT/bake-$m-fit$fit.json" \
      > "$OUT/bake-$m-fit$fit.txt" 2>&1
    rc=$?
    e=$(python3 -c "import time;print(f'{time.time()-$s:.1f}')")
    left=$(grep -h "again on the CPU" "$OUT/bake-$m-fit$fit.txt" \
      | awk '{f+=$4; r+=$10} END {print r+0 " of " f+0 " faces left to the CPU"}')
    echo "bunny_$m BSPVT_GPU_FIT=$fit rc=$rc ${e} s; $left" | tee -a "$OUT/summary.txt"
  done
  cmp /tmp/bunny-$m-fit1.bspvt /tmp/bunny-$m-fit0.bspvt \
    && echo "bunny_$m: GPU-fitted and CPU-fitted bakes identical" | tee -a "$OUT/summary.txt"
done
grep -h '"fit_thread_seconds_per_vertex"\|"seconds"' "$OUT"/bake-*.json | head -8
