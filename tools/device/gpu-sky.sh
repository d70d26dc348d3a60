#!/usr/bin/env bash
# The sky's cells on a lent GPU (issue 37 item 3), one call: the frames against the CPU's, then
# bench-sky's CPU and GPU rows in the same run on the bunny subdivided to 176K vertices at
# 1024² (the first frame: every visible vertex's terms; the map turning: one gather a frame;
# the camera moving: the terms every frame). Prepared as for gpu-check.sh
# (`tools/device/prepare.sh`, .dev/ and .gl/ carried). Logs and results go to $OUT.
set -u
NO_SUBDIVIDE=1 . tools/device/setup.sh
nvidia-smi -L | tee "$OUT/gpu.txt"
# The test binaries find the project's assets by the path they were built at.
[ -e /work/main ] || { mkdir -p /work && ln -s "$PWD" /work/main; }
(cd client && TAILN=20 step t_gpu_frames_sky 120 "$D/t_gpu_frames" sky bspvt_env --nocapture --test-threads 1)
TAILN=16 step bench_sky_gpu 300 "$D/bspvt" bench-sky --mesh "$M/bunny.ply" --subdivide 176000 \
  --size 1024 --pieces 1 --cells 12 --lobes 4 --spp 16 --frames 5 --gpu --cache /tmp/cache \
  --out "$OUT/bench-sky-gpu"
echo "== done" | tee -a "$OUT/summary.txt"
cat "$OUT/summary.txt"
