#!/usr/bin/env bash
# The GPU bake's second look (issue 23), after gpu-check.sh: the room's differing sub-rays with
# where they are, where a GPU chunk's time goes (BSPVT_GPU_TIMING), and the whole 565K-vertex
# bake. Same set-up as gpu-check.sh (tools/device/prepare.sh; .dev and .gl carried).
set -u
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
D=$PWD/.dev
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
ICD=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f "$ICD" ] && export VK_DRIVER_FILES=$ICD
for f in "$D"/*.gz; do gunzip -f "$f"; done
chmod +x "$D"/bspvt "$D"/bspvt-server "$D"/t_* 2>/dev/null
export BSPVT_ASSETS=$D/assets
M=$BSPVT_ASSETS/meshes
python3 tools/device/subdivide.py "$M/bunny.ply" /tmp/bunny_x4.ply 2
(cd tests && timeout 60 "$D/t_cast_gpu" --nocapture --test-threads 1 room 2>&1 | grep -E "room|test result" | tee "$OUT/room.txt")
BSPVT_GPU_TIMING=1 timeout 60 "$D/bspvt-server" bake --mesh "$M/bunny.ply" --backend gpu \
  --out /tmp/bunny-gpu.bspvt --stats "$OUT/bake-bunny-gpu.json" > "$OUT/bunny-timing.txt" 2>&1
grep -E "^gpu (cast|chunk)" "$OUT/bunny-timing.txt" | head -24
tail -2 "$OUT/bunny-timing.txt"
s=$(date +%s)
timeout 280 "$D/bspvt-server" bake --mesh /tmp/bunny_x4.ply --backend gpu \
  --out /tmp/bunny4-gpu.bspvt --stats "$OUT/bake-bunny-x4-gpu.json" > "$OUT/bunny-x4.txt" 2>&1
echo "x4 rc=$? after $(( $(date +%s) - s )) s"
tail -3 "$OUT/bunny-x4.txt"
