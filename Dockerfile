# syntax=docker/dockerfile:1
# amc serve in a container: a build stage compiles the `amc` binary (stripped)
# and the web page (amc-wasm + web/), an ffmpeg stage compiles an ffmpeg with
# only what amc uses (docker/build-ffmpeg.sh), and a slim runtime stage
# carries them.
#
#   docker build -t amc .
#   docker build --build-arg FFMPEG=debian -t amc .   # Debian's full ffmpeg instead
#   docker run --rm -p 8080:8080 amc
#   docker run --rm -p 8080:8080 -v "$PWD/clips:/clips:ro" amc serve --addr 0.0.0.0:8080 \
#       --web-dir /srv/amc/web --live-source /clips/flight.mp4 --live-loop
#
# The same image runs either role of a scaled-out service (compose.yaml):
#   amc serve  --addr 0.0.0.0:8080 ... --queue postgres://... --store s3://BUCKET
#   amc worker --addr 0.0.0.0:9090 ... --queue postgres://... --store s3://BUCKET

# minimal: the ffmpeg built below (an image of 135 MB); debian: Debian's
# ffmpeg package, every codec, device and filter (563 MB; docs/service.md).
ARG FFMPEG=minimal

FROM rust:1-bookworm AS build
WORKDIR /src
RUN apt-get update \
 && apt-get install -y --no-install-recommends nodejs npm \
 && rm -rf /var/lib/apt/lists/*
# The page's tools, each in a layer of its own before the sources, so that an
# edit does not reinstall them: the wasm32 target, the wasm-bindgen CLI at the
# exact version amc-wasm pins (--locked), and the page's runtime npm packages
# (not the test-only playwright-core).
RUN rustup target add wasm32-unknown-unknown
COPY amc-wasm/Cargo.toml amc-wasm/Cargo.toml
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    cargo install --locked wasm-bindgen-cli \
      --version "$(sed -n 's/^wasm-bindgen = "=\(.*\)"/\1/p' amc-wasm/Cargo.toml)"
COPY web/package.json web/package-lock.json web/
RUN cd web && npm ci --omit=dev --no-audit --no-fund
COPY . .
# BuildKit cache mounts keep the crate registry and target/ between builds,
# so an edit rebuilds only what changed. The binary and the page are copied
# out of the cached target/ within the same step. The binary is built without
# the release profile's line tables (Cargo.toml keeps them for profiling and
# backtraces) and its debug info stripped: 19 MB instead of 96. The symbol
# table stays, so a logged panic's backtrace still names its functions.
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    CARGO_PROFILE_RELEASE_DEBUG=0 CARGO_PROFILE_RELEASE_STRIP=debuginfo \
    cargo build --release -p amc-cli --bin amc \
 && cp target/release/amc /usr/local/bin/amc \
 && bash web/build.sh

# ffmpeg from Debian's source (with Debian's patches) of the runtime's
# release, configured with --disable-everything plus the decoders, encoders,
# formats, filters and protocols amc uses (listed in the script), its libav*
# linked in statically.
FROM debian:bookworm-slim AS ffmpeg-build
WORKDIR /usr/src
RUN sed -i 's/^Types: deb$/Types: deb deb-src/' /etc/apt/sources.list.d/debian.sources \
 && apt-get update \
 && apt-get install -y --no-install-recommends build-essential dpkg-dev nasm \
      pkg-config xz-utils libx264-dev libvpx-dev libopus-dev libdav1d-dev \
      libsrt-gnutls-dev libvidstab-dev libgnutls28-dev zlib1g-dev \
 && apt-get source ffmpeg \
 && rm -rf /var/lib/apt/lists/*
COPY docker/build-ffmpeg.sh /usr/src/
RUN cd ffmpeg-*/ && sh /usr/src/build-ffmpeg.sh /opt/ffmpeg

# The runtime's base, by --build-arg FFMPEG (only the one named is built).
FROM debian:bookworm-slim AS runtime-minimal
RUN apt-get update \
 && apt-get install -y --no-install-recommends \
      libx264-164 libvpx7 libopus0 libdav1d6 libsrt1.5-gnutls libvidstab1.1 \
 && rm -rf /var/lib/apt/lists/*
COPY --from=ffmpeg-build /opt/ffmpeg/bin/ffmpeg /opt/ffmpeg/bin/ffprobe /usr/local/bin/

FROM debian:bookworm-slim AS runtime-debian
RUN apt-get update \
 && apt-get install -y --no-install-recommends ffmpeg \
 && rm -rf /var/lib/apt/lists/*

FROM runtime-${FFMPEG} AS runtime
RUN apt-get update \
 && apt-get install -y --no-install-recommends ca-certificates tini \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --create-home --home-dir /srv/amc amc
COPY --from=build /usr/local/bin/amc /usr/local/bin/amc
COPY --from=build /src/web/dist /srv/amc/web
USER amc
WORKDIR /srv/amc
# 8080: amc serve; 9090: amc worker's /healthz and /metrics.
EXPOSE 8080 9090
# tini forwards SIGTERM so `docker stop` shuts the service down gracefully
# (running jobs cancelled, ffmpeg children killed, scratch files removed; a
# worker hands its running job back to the queue).
ENTRYPOINT ["/usr/bin/tini", "--", "amc"]
# One JSON object per log line (for log collectors; never coloured). On a
# public address amc serve wants keys (docs/security.md): mount the file made
# by `amc keys new NAME ROLES --append amc_keys` at /run/secrets/amc_keys
#   docker run -p 8080:8080 -v "$PWD/amc_keys:/run/secrets/amc_keys:ro" amc
# and give the service a certificate (--tls-cert/--tls-key) or put it behind
# a TLS-terminating proxy: keys travel in every request.
CMD ["serve", "--addr", "0.0.0.0:8080", "--web-dir", "/srv/amc/web", "--log-json", \
     "--auth-keys", "/run/secrets/amc_keys"]
