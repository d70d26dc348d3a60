#!/usr/bin/env bash
# Fills .dev/ (ignored; carried to the device machine) for tools/device/gpu-check.sh: the
# stripped release binaries, the GPU test binaries and the shared meshes, gzipped; and .gl/
# with the Vulkan loader's Debian packages (the device image has no Vulkan loader).
# `prepare.sh --tests`: the GPU test binaries alone (no release build, ~14 min less), for
# tools/device/gpu-surfaces.sh.
set -euo pipefail
TESTS_ONLY=${1:-}
cd "$(dirname "$0")/../.."
grep -qx '/.dev/' .git/info/exclude 2>/dev/null || echo /.dev/ >> .git/info/exclude
grep -qx '/.gl/' .git/info/exclude 2>/dev/null || echo /.gl/ >> .git/info/exclude
rm -rf .dev && mkdir -p .dev/assets/meshes .gl
if [ "$TESTS_ONLY" != --tests ]; then
  cargo build --release --locked -p bspvt -p bspvt-server
  for b in bspvt bspvt-server; do strip -o .dev/$b target/release/$b; gzip -9 .dev/$b; done
fi
test_bin() { # package test [cargo flags…] → path of its test binary
  cargo test --locked -p "$1" --test "$2" "${@:3}" --no-run --message-format=json 2>/dev/null \
    | python3 -c "import json,sys
for l in sys.stdin:
    m=json.loads(l)
    if m.get('reason')=='compiler-artifact' and m['target']['name']=='$2' and m.get('executable'): print(m['executable'])"
}
for t in "bspvt-client gpu_shading" "bspvt-client gpu_frames" "bspvt-tests cast_gpu" \
  "bspvt-client gpu_penumbra" "bspvt-raytrace first_hit_gpu --features gpu"; do
  set -- $t
  strip -o ".dev/t_$2" "$(test_bin "$@")"
  gzip -9 ".dev/t_$2"
done
# The bake's unit tests (with the GPU): the unsure flag under skewed rounding (issue 36).
bake_lib=$(cargo test --locked -p bspvt-bake --features gpu --lib --no-run --message-format=json 2>/dev/null \
  | python3 -c "import json,sys
for l in sys.stdin:
    m=json.loads(l)
    if m.get('reason')=='compiler-artifact' and m['target']['kind']==['lib'] and m['target']['name']=='bspvt_bake' and m.get('executable'): print(m['executable'])")
strip -o .dev/t_bake_lib "$bake_lib"
gzip -9 .dev/t_bake_lib
S=${BSPVT_ASSETS:-../shared/assets}
for m in bunny.ply bunny_res2.ply bunny_res4.ply dragon_res4.ply teapot.obj; do
  cp "$S/meshes/$m" .dev/assets/meshes/
done
mkdir -p .dev/assets/env
cp "$S/env/royal_esplanade_1k.hdr" .dev/assets/env/
o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
mkdir -p /tmp/amd64/partial
if ! ls .gl/libvulkan1_*.deb >/dev/null 2>&1; then
  apt-get $o update >/dev/null
  (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
fi
du -sh .dev .gl
