#!/usr/bin/env bash
# The GPU checks of issues 22 and 23, run on a lent GPU machine (the device tool) in one call.
# Prepared here (no toolchain there): `tools/device/prepare.sh` fills .dev/ with the stripped
# release binaries, the GPU test binaries and the shared meshes, and .gl/ with the Vulkan
# loader; then, with both carried: `bash tools/device/gpu-check.sh`. Logs and JSON go to $OUT.
set -u
. tools/device/setup.sh
nvidia-smi -L | tee "$OUT/gpu.txt"
nproc | tee -a "$OUT/gpu.txt"

# Correctness on a real GPU: per-vertex shading against the f64 kernels, frames against the
# CPU's frames, GPU cube maps against the full CPU cast.
(cd client && TAILN=12 step t_gpu_shading 45 "$D/t_gpu_shading" --nocapture --test-threads 1)
(cd client && TAILN=20 step t_gpu_frames 60 "$D/t_gpu_frames" --nocapture --test-threads 1)
# Rays: full and adaptive CPU casts against the GPU's, same run, 16 threads.
TAILN=30 step bench_bake 90 "$D/bspvt-server" bench --meshes teapot.obj,bunny.ply,dragon_res4.ply \
  --vertices 4000 --methods default --threads 16 --casts full,adaptive,gpu --json "$OUT/bench-bake.json"
# Whole bakes: the bunny with its default ground and light on the GPU and the CPU (same
# bytes), then the 557K-vertex bunny (two midpoint subdivisions) on the GPU.
step bake_bunny_gpu 60 "$D/bspvt-server" bake --mesh "$M/bunny.ply" --backend gpu \
  --out /tmp/bunny-gpu.bspvt --stats "$OUT/bake-bunny-gpu.json"
step bake_bunny_cpu 60 "$D/bspvt-server" bake --mesh "$M/bunny.ply" --backend cpu \
  --out /tmp/bunny-cpu.bspvt --stats "$OUT/bake-bunny-cpu.json"
cmp /tmp/bunny-gpu.bspvt /tmp/bunny-cpu.bspvt && echo "bunny: GPU and CPU bakes identical" | tee -a "$OUT/summary.txt"
step bake_bunny_x4_gpu 100 "$D/bspvt-server" bake --mesh /tmp/bunny_x4.ply --backend gpu \
  --out /tmp/bunny4-gpu.bspvt --stats "$OUT/bake-bunny-x4-gpu.json"
# Frames: the GPU's per-vertex pass and whole frames against the CPU's, same run.
TAILN=14 step bench_gpu 60 "$D/bspvt" bench-gpu --meshes bunny.ply --subdivide 0,1,2 \
  --sizes 512x512,1920x1080 --frames 8 --cpu-frames 2 --cache /tmp/cache --json "$OUT/bench-gpu.json"
(cd tests && TAILN=12 step t_cast_gpu 45 "$D/t_cast_gpu" --nocapture --test-threads 1)
# Time to the first frame from the service (issue 37 item 2): the 557K bunny submitted to a
# served service on loopback and streamed at 1080p on the GPU; the stages (connect, session,
# set-up, draw) and the frames after it are printed.
"$D/bspvt-server" serve --data-dir /tmp/srv --addr 127.0.0.1:18111 > "$OUT/serve.log" 2>&1 &
SRV=$!
sleep 2
TAILN=4 step first_frame_gpu 90 "$D/bspvt" animate --mesh /tmp/bunny_x4.ply \
  --server http://127.0.0.1:18111 --progressive --frames 30 --width 1920 --height 1080 \
  --out /tmp/first-frame --no-cache --no-gif --backend gpu
kill "$SRV"
echo "== done" | tee -a "$OUT/summary.txt"
cat "$OUT/summary.txt"
