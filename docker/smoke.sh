#!/bin/sh
# The container's quickstart end to end: `docker compose` brings up docker/compose.yaml (the
# image docker/Dockerfile builds; built first if missing), a mesh is submitted with curl as
# docs/service.md's quickstart does, its bake followed to `done`, its trees downloaded and
# compared byte for byte with the same image's offline bake (`bspvt-server bake`); then the
# service is stopped (SIGTERM) and brought up again from its volume, and serves the same bytes.
# Needs a Docker daemon (DOCKER_HOST) and `docker compose` or `docker-compose`; run from the
# repository root. Prints what it did; exits non-zero on the first failure.
set -eu
compose() {
  if docker compose version >/dev/null 2>&1; then docker compose "$@"; else docker-compose "$@"; fi
}
export BSPVT_API_KEY=smoke-secret
B=http://127.0.0.1:8080
work=$(mktemp -d)
chmod 777 "$work" # the image runs as uid 10001
cleanup() {
  compose -f docker/compose.yaml down -v >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
field() { sed -n "s/.*\"$1\":\"\\([^\"]*\\)\".*/\\1/p"; }
healthy() {
  i=0
  until curl -fsS -o /dev/null $B/healthz 2>/dev/null; do
    i=$((i + 1))
    [ $i -lt 120 ] || { echo "no /healthz after 60 s"; compose -f docker/compose.yaml logs; exit 1; }
    sleep 0.5
  done
}

compose -f docker/compose.yaml up -d
healthy
echo "healthz: $(curl -fsS $B/healthz)"
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n' >"$work/tet.obj"
# Writes need the key.
code=$(curl -sS -o /dev/null -w '%{http_code}' -F mesh=@"$work/tet.obj" $B/v1/scenes)
[ "$code" = 401 ] || { echo "a submission without the key answered $code, not 401"; exit 1; }
id=$(curl -fsS -H "X-API-Key: $BSPVT_API_KEY" -H 'Idempotency-Key: smoke-1' -F mesh=@"$work/tet.obj" \
  $B/v1/scenes | field id)
echo "submitted: $id"
t0=$(date +%s)
while :; do
  state=$(curl -fsS $B/v1/scenes/"$id" | field state)
  [ "$state" = "done" ] && break
  [ "$state" = failed ] && { curl -fsS $B/v1/scenes/"$id"; exit 1; }
  [ $(($(date +%s) - t0)) -lt 600 ] || { echo "not done after 600 s: $state"; exit 1; }
  sleep 1
done
echo "done after $(($(date +%s) - t0)) s"
curl -fsS -o "$work/served.bspvt" $B/v1/scenes/"$id"/trees
docker run --rm -v "$work:/w" bspvt-server bake --mesh /w/tet.obj --out /w/offline.bspvt >/dev/null
cmp "$work/served.bspvt" "$work/offline.bspvt"
echo "trees: $(wc -c <"$work/served.bspvt") bytes, byte-identical to the image's offline bake"
# Stopped and started again: the volume keeps the scene.
compose -f docker/compose.yaml stop
compose -f docker/compose.yaml up -d
healthy
curl -fsS -o "$work/again.bspvt" $B/v1/scenes/"$id"/trees
cmp "$work/served.bspvt" "$work/again.bspvt"
echo "after a stop and a start: the same scene, the same bytes"
