# A stand-in for Docker Hub's rust:1.95-slim-bookworm, built on the imported Debian base
# (docker/bases/build.sh) where Docker Hub cannot be reached: gcc and the C library headers
# (the bundled SQLite and zstd are C), and Rust 1.95.0 by rustup, as the official image has;
# plus the build machine's own extra CAs (ca/: a TLS-intercepting egress proxy's), without
# which nothing here can fetch over https.
FROM debian:bookworm-slim
COPY ca/ /usr/local/share/ca-certificates/
RUN apt-get update \
 && apt-get install -y --no-install-recommends ca-certificates=2023* curl=7.88.* gcc=4:12.* libc6-dev=2.36-* \
 && update-ca-certificates \
 && rm -rf /var/lib/apt/lists/*
ENV RUSTUP_HOME=/usr/local/rustup CARGO_HOME=/usr/local/cargo PATH=/usr/local/cargo/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
RUN curl -fsSL https://static.rust-lang.org/rustup/dist/x86_64-unknown-linux-gnu/rustup-init \
      -o /tmp/rustup-init \
 && chmod +x /tmp/rustup-init \
 && /tmp/rustup-init -y --no-modify-path --profile minimal --default-toolchain 1.95.0 \
 && rm /tmp/rustup-init \
 && rustc --version
