#!/bin/sh
# Stand-ins for the Docker Hub images docker/compose.distributed.yaml names besides bspvt-server,
# built on the imported Debian base (build.sh first) where Docker Hub cannot be reached:
# `postgres:15` from Debian's PostgreSQL 15 (postgres.Dockerfile), and `minio/minio` and
# `minio/mc` from moto's S3 server and an `mc` of three verbs (minio.Dockerfile; not MinIO).
# The compose file then runs unchanged. Needs a Docker daemon (DOCKER_HOST).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
ctx=$(mktemp -d)
trap 'rm -rf "$ctx"' EXIT
mkdir -p "$ctx/ca"
cp /usr/local/share/ca-certificates/*.crt "$ctx/ca/" 2>/dev/null || true
cp "$here"/postgres.Dockerfile "$here"/postgres-entrypoint.sh "$here"/minio.Dockerfile \
  "$here"/minio-standin.sh "$here"/mc-standin.sh "$ctx/"
docker build -t postgres:15 -f "$ctx/postgres.Dockerfile" "$ctx"
docker build -t minio/minio -f "$ctx/minio.Dockerfile" "$ctx"
docker tag minio/minio minio/mc
