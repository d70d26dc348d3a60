#!/bin/sh
# `minio server DIR [--console-address …]` for the minio/minio stand-in (minio.Dockerfile):
# moto's S3 server on port 9000 (DIR and the console are ignored: moto keeps objects in memory).
set -eu
[ "${1:-}" = server ] || { echo "the minio stand-in runs only 'minio server DIR'" >&2; exit 2; }
echo "stand-in minio/minio: moto_server (moto 5.2.1) on :9000 (objects in memory)"
exec /opt/moto/bin/moto_server -H 0.0.0.0 -p 9000
