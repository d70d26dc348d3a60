#!/bin/sh
# The distributed shape's quickstart end to end: `docker compose` brings up
# docker/compose.distributed.yaml (PostgreSQL, the S3 store, its bucket, one API instance, two
# bake workers; the bspvt-server image built first if missing), meshes are submitted with curl
# as docs/service.md's quickstart does — the tetrahedron, then the shared bunny (a worker killed
# with SIGKILL while it bakes: its leases expire and the other worker takes them) — each
# followed to `done`, its trees compared byte for byte with the same image's offline bake, and
# /healthz and /metrics read on the way. Needs a Docker daemon (DOCKER_HOST) and `docker compose`
# or `docker-compose`; run from the repository root. BSPVT_MESH overrides the bunny's path
# (default ../shared/assets/meshes/bunny.ply; skipped with a message when absent). Prints what
# it did; exits non-zero on the first failure.
set -eu
compose() {
  if docker compose version >/dev/null 2>&1; then
    docker compose -p bspvt -f docker/compose.distributed.yaml "$@"
  else
    docker-compose -p bspvt -f docker/compose.distributed.yaml "$@"
  fi
}
export BSPVT_API_KEY=smoke-secret
B=http://127.0.0.1:8080
work=$(mktemp -d)
chmod 777 "$work" # the image runs as uid 10001
cleanup() {
  [ $? = 0 ] || compose logs --tail 40 >&2 || true
  compose down -v >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
field() { sed -n "s/.*\"$1\":\"\\([^\"]*\\)\".*/\\1/p"; }
num() { sed -n "s/.*\"$1\":\\([0-9]*\\).*/\\1/p"; }
healthy() {
  i=0
  until curl -fsS -o /dev/null $B/healthz 2>/dev/null; do
    i=$((i + 1))
    [ $i -lt 240 ] || { echo "no /healthz after 120 s"; exit 1; }
    sleep 0.5
  done
}
# Submits $1 (curl -F arguments), follows the scene to done, compares its trees with the
# offline bake of $2 (bspvt-server bake arguments); $3 = "kill" kills a worker mid-bake.
bake_and_compare() {
  name=$1 form=$2 offline=$3 kill=${4:-}
  # shellcheck disable=SC2086
  id=$(curl -fsS -H "X-API-Key: $BSPVT_API_KEY" -H "Idempotency-Key: smoke-$name" $form \
    $B/v1/scenes | field id)
  echo "$name: submitted $id"
  t0=$(date +%s)
  killed=
  while :; do
    row=$(curl -fsS $B/v1/scenes/"$id")
    state=$(echo "$row" | field state)
    [ "$state" = "done" ] && break
    [ "$state" = failed ] && { echo "$row"; exit 1; }
    if [ "$kill" = kill ] && [ -z "$killed" ] && [ "$(echo "$row" | num chunks_done)" -ge 1 ]; then
      victim=$(compose ps -q worker | head -n 1)
      docker kill "$victim" >/dev/null
      killed=1
      echo "$name: SIGKILL to worker ${victim%"${victim#????????????}"} at $(echo "$row" | num chunks_done)/$(echo "$row" | num chunks_total) chunks"
    fi
    [ $(($(date +%s) - t0)) -lt 1200 ] || { echo "not done after 1200 s: $row"; exit 1; }
    sleep 1
  done
  echo "$name: done after $(($(date +%s) - t0)) s ($(echo "$row" | num chunks_total) chunks)"
  curl -fsS -o "$work/$name-served.bspvt" $B/v1/scenes/"$id"/trees
  # shellcheck disable=SC2086
  docker run --rm -v "$work:/w" bspvt-server bake $offline --out /w/"$name"-offline.bspvt 2>&1 | tail -n 1
  cmp "$work/$name-served.bspvt" "$work/$name-offline.bspvt"
  echo "$name: trees $(wc -c <"$work/$name-served.bspvt") bytes, byte-identical to the image's offline bake"
}

compose up -d --scale worker=2
healthy
echo "healthz: $(curl -fsS $B/healthz)"
echo "services: $(compose ps --services | tr '\n' ' ')"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n' >"$work/tet.obj"
code=$(curl -sS -o /dev/null -w '%{http_code}' -F mesh=@"$work/tet.obj" $B/v1/scenes)
[ "$code" = 401 ] || { echo "a submission without the key answered $code, not 401"; exit 1; }
bake_and_compare tet "-F mesh=@$work/tet.obj" "--mesh /w/tet.obj"
mesh=${BSPVT_MESH:-../shared/assets/meshes/bunny.ply}
if [ -f "$mesh" ]; then
  cp "$mesh" "$work/bunny.ply"
  bake_and_compare bunny "-F mesh=@$work/bunny.ply" "--mesh /w/bunny.ply" kill
else
  echo "skipped the bunny: $mesh not found (set BSPVT_MESH)"
fi
# The workers as the API sees them: the killed one no longer live, the chunks each baked.
{ curl -fsS $B/healthz; echo; } | tr '{' '\n' | sed -n 's/^"id":"\([^"]*\)".*"live":\([a-z]*\),.*"chunks_done":\([0-9]*\).*/worker \1: live \2, chunks done \3/p'
