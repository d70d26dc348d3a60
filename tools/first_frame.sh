#!/bin/bash
# Time to the first shaded frame of a mesh uploaded to a fresh service on loopback (issue 37
# item 2): starts `bspvt-server serve` on an empty data folder, runs `bspvt animate --mesh M
# --server URL --progressive` for one frame and prints its "first shaded frame" line (connect,
# session, set-up, draw), then stops the service. docs/benchmarks.md, "The first frame of an
# uploaded mesh".
#
#   tools/first_frame.sh MESH [BIN_DIR] [EXTRA animate flags…]
#
# BIN_DIR (default target/release) holds bspvt and bspvt-server; the service's settings come
# from the environment (BSPVT_BAKE_NICE=0, say). Port 8911; the data goes to a temporary folder.
set -euo pipefail
mesh=$(realpath "$1")
bin=$(realpath "${2:-target/release}")
shift $(( $# >= 2 ? 2 : 1 ))
tmp=$(mktemp -d)
trap 'kill "$server" 2>/dev/null || true; wait "$server" 2>/dev/null || true; rm -rf "$tmp"' EXIT
"$bin/bspvt-server" serve --data-dir "$tmp/service" --addr 127.0.0.1:8911 > "$tmp/server.log" 2>&1 &
server=$!
for _ in $(seq 100); do
  grep -q "listening on" "$tmp/server.log" 2>/dev/null && break
  sleep 0.05
done
cd "$tmp"
"$bin/bspvt" animate --mesh "$mesh" --server http://127.0.0.1:8911 --data-dir "$tmp/client" \
  --frames 1 --width 1920 --height 1080 --no-cache --no-gif --progressive --out "$tmp/frames" "$@" \
  2>&1 | grep "first shaded frame"
