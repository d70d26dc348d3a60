#!/usr/bin/env bash
# The second look after gpu-all.sh (stop 64), one call of ~3 min: (1) the GPU tree fit with
# its buffers kept and its trees read back packed (gpu_fit.rs): its tests on this device, the
# 565K bunny baked with the fit on the GPU and on the CPU (BSPVT_GPU_FIT=0), wall clock and
# `cmp`; (2) the round lights' small angles (common.wgsl `sin_rel`…): the GPU frames of the
# point, spot and sun against the CPU's, and the GPU shading tests; (3) where the frame's raster
# time goes: bench-gpu on 701K vertices at 512² and 1080p, 1 and 4 samples, with the GPU's
# clocks. Prepared as for gpu-all.sh (`tools/device/prepare.sh`; .dev and .gl carried).
set -u
NO_SUBDIVIDE=1 . tools/device/setup.sh
python3 tools/device/subdivide.py "$M/bunny.ply" /tmp/bunny_x4.ply 2
[ -e /work/main ] || { mkdir -p /work && ln -s "$PWD" /work/main; }
TAILN=3 step fit_tests 40 "$D/t_bake_lib" --test-threads 4 gpu_fit rounding_of_another
for fit in 1 0; do
  BSPVT_GPU_FIT=$fit BSPVT_GPU_TIMING=1 TAILN=2 step "bake_x4_fit$fit" 60 "$D/bspvt-server" bake \
    --mesh /tmp/bunny_x4.ply --backend gpu --out "/tmp/x4-fit$fit.bspvt" --stats "$OUT/bake-x4-fit$fit.json"
  grep -E "fitted in" "$OUT/bake_x4_fit$fit.log" | tail -3 | tee -a "$OUT/summary.txt"
done
cmp /tmp/x4-fit1.bspvt /tmp/x4-fit0.bspvt && echo "x4: GPU-fitted and CPU-fitted bakes identical" | tee -a "$OUT/summary.txt"
(cd client && TAILN=16 step t_gpu_frames_lights 40 "$D/t_gpu_frames" --test-threads 1 --nocapture point_spot_and_sun)
(cd client && TAILN=3 step t_gpu_frames 60 "$D/t_gpu_frames" --test-threads 1)
(cd client && TAILN=3 step t_gpu_shading 30 "$D/t_gpu_shading" --test-threads 1)
nvidia-smi --query-gpu=clocks.sm,clocks.max.sm,pstate --format=csv | tee -a "$OUT/summary.txt"
for s in 4 1; do
  TAILN=3 step "bench_gpu_s$s" 60 "$D/bspvt" bench-gpu --meshes bunny.ply --subdivide 2 \
    --sizes 512x512,1920x1080 --frames 16 --cpu-frames 0 --samples $s --cache /tmp/cache
done
nvidia-smi --query-gpu=clocks.sm,clocks.max.sm,pstate --format=csv | tee -a "$OUT/summary.txt"
(cd "$OUT" && tar czf /tmp/logs.tgz . && find . -mindepth 1 -not -name summary.txt -delete && mv /tmp/logs.tgz .)
echo "== done"
