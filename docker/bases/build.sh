#!/bin/sh
# Stand-ins for the Docker Hub images docker/Dockerfile starts from, built locally where Docker
# Hub cannot be reached (Debian's mirror can): `debian:bookworm-slim` from debootstrap (minbase),
# and `rust:1.95-slim-bookworm` on it (rust.Dockerfile), with this machine's extra CA
# certificates (/usr/local/share/ca-certificates) for an https-intercepting proxy. Needs root,
# debootstrap and a Docker daemon (DOCKER_HOST). docker/README.md says how it was used.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
ctx=$(mktemp -d)
trap 'rm -rf "$ctx"' EXIT
debootstrap --variant=minbase bookworm "$ctx/rootfs" http://deb.debian.org/debian >"$ctx/debootstrap.log"
rm -f "$ctx"/rootfs/var/cache/apt/archives/*.deb
tar -C "$ctx/rootfs" -c . | docker import - debian:bookworm-slim
mkdir -p "$ctx/ca"
cp /usr/local/share/ca-certificates/*.crt "$ctx/ca/" 2>/dev/null || true
cp "$here/rust.Dockerfile" "$ctx/"
rm -rf "$ctx/rootfs"
docker build -t rust:1.95-slim-bookworm -f "$ctx/rust.Dockerfile" "$ctx"
