#!/usr/bin/env bash
# rt-penumbra's shadow rays on a lent GPU (issue 37 item 4), one call: the GPU's closest hits
# and frames against the CPU's, then bench-penumbra's CPU and GPU rows in the same run at
# 1024² (the blur and the shading stay on the CPU; BSPVT_GPU_TIMING splits each batch of rays
# into upload, GPU and read-back). Prepared as for gpu-check.sh (`tools/device/prepare.sh`,
# .dev/ and .gl/ carried). Logs and results go to $OUT.
set -u
NO_SUBDIVIDE=1 . tools/device/setup.sh
nvidia-smi -L | tee "$OUT/gpu.txt"
# The test binaries find the project's assets by the path they were built at.
[ -e /work/main ] || { mkdir -p /work && ln -s "$PWD" /work/main; }
(cd proto/raytrace && TAILN=8 step t_first_hit_gpu 60 "$D/t_first_hit_gpu" --nocapture --test-threads 1)
(cd client && TAILN=10 step t_gpu_penumbra 60 "$D/t_gpu_penumbra" --nocapture --test-threads 1)
BSPVT_GPU_TIMING=1 TAILN=24 step bench_penumbra_gpu 300 "$D/bspvt" bench-penumbra \
  --scenes plate-small,teapot,bunny --meshes-dir "$M" --base-only --size 1024 --ref-spp 64 \
  --frames 5 --gpu --out "$OUT/bench-penumbra-gpu"
# The whole method as `--backend gpu` draws it (the unshadowed shading from the GPU's frames).
for b in cpu gpu; do
  TAILN=2 step "render_rt_penumbra_$b" 120 "$D/bspvt" render --mesh "$M/bunny.ply" \
    --method rt-penumbra --backend "$b" --width 1920 --height 1080 --frames 8 --out "/tmp/rt-$b.png"
done
echo "== done" | tee -a "$OUT/summary.txt"
cat "$OUT/summary.txt"
