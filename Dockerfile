# syntax=docker/dockerfile:1
# amc serve in a container: a build stage compiles the `amc` binary and the
# web page (amc-wasm + web/), a slim runtime stage carries them with ffmpeg.
#
#   docker build -t amc .
#   docker run --rm -p 8080:8080 amc
#   docker run --rm -p 8080:8080 -v "$PWD/clips:/clips:ro" amc serve --addr 0.0.0.0:8080 \
#       --web-dir /srv/amc/web --live-source /clips/flight.mp4 --live-loop
#
# The same image runs either role of a scaled-out service (compose.yaml):
#   amc serve  --addr 0.0.0.0:8080 ... --queue postgres://... --store s3://BUCKET
#   amc worker --addr 0.0.0.0:9090 ... --queue postgres://... --store s3://BUCKET

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
# out of the cached target/ within the same step.
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release -p amc-cli --bin amc \
 && cp target/release/amc /usr/local/bin/amc \
 && bash web/build.sh

FROM debian:bookworm-slim AS runtime
RUN apt-get update \
 && apt-get install -y --no-install-recommends ffmpeg ca-certificates tini \
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
# One JSON object per log line (for log collectors; never coloured).
CMD ["serve", "--addr", "0.0.0.0:8080", "--web-dir", "/srv/amc/web", "--log-json"]
