# A stand-in for Docker Hub's minio/minio and minio/mc (tagged as both by build-distributed.sh),
# built on the imported Debian base where Docker Hub cannot be reached: moto's S3-compatible
# server (PyPI's `moto[server]`, the one server/tests/service_cluster.rs runs) behind a `minio`
# command that takes `minio server DIR …` as the official image does, and an `mc` with the
# three verbs docker/compose.distributed.yaml uses (`ready`, `alias set`, `mb
# --ignore-existing`). Not MinIO: moto keeps objects in memory and accepts any credentials.
FROM debian:bookworm-slim
COPY ca/ /usr/local/share/ca-certificates/
RUN apt-get update \
 && apt-get install -y --no-install-recommends ca-certificates curl python3 python3-venv \
 && update-ca-certificates \
 && rm -rf /var/lib/apt/lists/*
ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt
RUN python3 -m venv /opt/moto \
 && /opt/moto/bin/pip install --no-cache-dir 'moto[server]==5.2.1' \
 && /opt/moto/bin/moto_server --help >/dev/null
COPY minio-standin.sh /usr/local/bin/minio
COPY mc-standin.sh /usr/local/bin/mc
RUN chmod 755 /usr/local/bin/minio /usr/local/bin/mc
EXPOSE 9000
ENTRYPOINT ["minio"]
