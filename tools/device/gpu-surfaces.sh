#!/usr/bin/env bash
# Issue 35's GPU checks on a lent GPU machine, in one call: the GPU frames against the CPU's
# (alpha cut-outs in the raster pass, normal maps, mipmapped textures, textured materials and
# lights), the GPU cast through cut-outs against the full CPU cast, and the per-vertex kernel
# against f64. Prepared here with `tools/device/prepare.sh --tests`; run with .dev and .gl
# carried: `bash tools/device/gpu-surfaces.sh`. Logs go to $OUT.
set -u
NO_SUBDIVIDE=1 . tools/device/setup.sh
nvidia-smi -L | tee "$OUT/gpu.txt"
# The test binaries find the project's assets by the path they were built at.
[ -e /work/main ] || { mkdir -p /work && ln -s "$PWD" /work/main; }
(cd client && TAILN=70 step t_gpu_frames 120 "$D/t_gpu_frames" --nocapture --test-threads 1)
(cd tests && TAILN=30 step t_cast_gpu 90 "$D/t_cast_gpu" --nocapture --test-threads 1)
(cd client && TAILN=20 step t_gpu_shading 60 "$D/t_gpu_shading" --nocapture --test-threads 1)
echo "== done" | tee -a "$OUT/summary.txt"
