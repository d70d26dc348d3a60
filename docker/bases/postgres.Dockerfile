# A stand-in for Docker Hub's postgres:15, built on the imported Debian base (build.sh) where
# Docker Hub cannot be reached: Debian's PostgreSQL 15 server, with an entry point that does what
# the official image's does for docker/compose.distributed.yaml — on an empty data volume, a
# cluster whose superuser is $POSTGRES_USER (password $POSTGRES_PASSWORD, SCRAM over TCP) and a
# database $POSTGRES_DB; then the server on all addresses, as the postgres user.
FROM debian:bookworm-slim
RUN apt-get update \
 && apt-get install -y --no-install-recommends postgresql-15 \
 && rm -rf /var/lib/apt/lists/*
ENV PATH=/usr/lib/postgresql/15/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    PGDATA=/var/lib/postgresql/data
COPY postgres-entrypoint.sh /usr/local/bin/docker-entrypoint.sh
RUN chmod 755 /usr/local/bin/docker-entrypoint.sh \
 && mkdir -p "$PGDATA" && chown postgres:postgres "$PGDATA"
VOLUME /var/lib/postgresql/data
EXPOSE 5432
STOPSIGNAL SIGINT
ENTRYPOINT ["docker-entrypoint.sh"]
CMD ["postgres"]
