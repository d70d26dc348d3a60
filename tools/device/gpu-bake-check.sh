#!/usr/bin/env bash
# The GPU bake's second look (issue 23), after gpu-check.sh: the room's differing sub-rays with
# where they are, where a GPU chunk's time goes (BSPVT_GPU_TIMING), and the whole 565K-vertex
# bake. Same set-up as gpu-check.sh (tools/device/prepare.sh; .dev and .gl carried).
set -u
. tools/device/setup.sh
(cd tests && timeout 60 "$D/t_cast_gpu" --nocapture --test-threads 1 room 2>&1 | grep -E "room|test result" | tee "$OUT/room.txt")
# Issue 36: the unsure flag under this device's own rounding and skewed rounding, and the
# bytes of a GPU and a CPU bake of the 148K-vertex bunny (they differed in one byte before).
timeout 60 "$D/t_bake_lib" --nocapture rounding_of_another 2>&1 | grep -E "room|test result" | tee "$OUT/rounding.txt"
python3 tools/device/subdivide.py "$M/bunny.ply" /tmp/bunny_x1.ply 1
for b in gpu cpu; do
  timeout 120 "$D/bspvt-server" bake --mesh /tmp/bunny_x1.ply --backend $b --out /tmp/bunny1-$b.bspvt \
    --stats "$OUT/bake-bunny-x1-$b.json" > "$OUT/bunny-x1-$b.txt" 2>&1; echo "x1 $b rc=$?"
done
cmp /tmp/bunny1-gpu.bspvt /tmp/bunny1-cpu.bspvt && echo "x1: GPU and CPU bakes identical"
grep -h recast_per_vertex "$OUT/bake-bunny-x1-gpu.json"
BSPVT_GPU_TIMING=1 timeout 60 "$D/bspvt-server" bake --mesh "$M/bunny.ply" --backend gpu \
  --out /tmp/bunny-gpu.bspvt --stats "$OUT/bake-bunny-gpu.json" > "$OUT/bunny-timing.txt" 2>&1
grep -E "^gpu (cast|chunk)" "$OUT/bunny-timing.txt" | head -16
timeout 60 "$D/bspvt-server" bench --meshes bunny.ply --vertices 4000 --methods default \
  --threads 16 --casts adaptive,gpu --json "$OUT/bench-bake.json" 2>&1 | grep -E "^\| bunny"
tail -2 "$OUT/bunny-timing.txt"
s=$(date +%s)
timeout 180 "$D/bspvt-server" bake --mesh /tmp/bunny_x4.ply --backend gpu \
  --out /tmp/bunny4-gpu.bspvt --stats "$OUT/bake-bunny-x4-gpu.json" > "$OUT/bunny-x4.txt" 2>&1
echo "x4 rc=$? after $(( $(date +%s) - s )) s"
tail -3 "$OUT/bunny-x4.txt"
