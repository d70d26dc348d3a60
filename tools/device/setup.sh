# Sourced by the device checks (gpu-check.sh, gpu-bake-check.sh) on the lent GPU machine: the
# Vulkan loader from .gl/, NVIDIA's ICD, the binaries and meshes of .dev/ unpacked (set by
# tools/device/prepare.sh here). Sets OUT, D (the .dev folder) and M (its meshes), and
# defines `step`.
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
[ -n "${NO_SUBDIVIDE:-}" ] || python3 tools/device/subdivide.py "$M/bunny.ply" /tmp/bunny_x4.ply 2

# Runs a check: `step NAME TIMEOUT COMMAND...` logs to $OUT/NAME.log and appends its exit
# status, seconds and last TAILN lines (6) to $OUT/summary.txt.
step() {
  local name=$1 t=$2; shift 2
  local s=$(date +%s.%N)
  timeout "$t" "$@" > "$OUT/$name.log" 2>&1
  local rc=$?
  local e=$(python3 -c "import time;print(f'{time.time()-$s:.1f}')")
  echo "== $name rc=$rc ${e}s" | tee -a "$OUT/summary.txt"
  tail -n "${TAILN:-6}" "$OUT/$name.log" | tee -a "$OUT/summary.txt"
}
