#!/usr/bin/env bash
# Builds the web page into web/dist: amc-wasm for wasm32 with SIMD, its JS
# bindings (wasm-bindgen CLI at the exact version of the crate, installed if
# missing), the page's sources and mediabunny. Needs Rust (rustup), Node + npm.
set -euo pipefail
cd "$(dirname "$0")"
root="$(cd .. && pwd)"
dist="$PWD/dist"

# The wasm-bindgen CLI must match the crate's pinned version exactly.
want="$(sed -n 's/^wasm-bindgen = "=\(.*\)"/\1/p' "$root/amc-wasm/Cargo.toml")"
have="$(wasm-bindgen --version 2>/dev/null | awk '{print $2}' || true)"
if [ "$have" != "$want" ]; then
  echo "installing wasm-bindgen-cli $want (found: ${have:-none})" >&2
  cargo install wasm-bindgen-cli --version "$want"
fi
if ! rustup target list --installed 2>/dev/null | grep -qx wasm32-unknown-unknown; then
  rustup target add wasm32-unknown-unknown || {
    echo "cannot add the Rust target wasm32-unknown-unknown (needs rustup and the network): the page cannot be built" >&2
    exit 1
  }
fi

# Only the wasm target gets +simd128 (native builds of the workspace are untouched).
CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_RUSTFLAGS="-C target-feature=+simd128" \
  cargo build --release -p amc-wasm --target wasm32-unknown-unknown --manifest-path "$root/Cargo.toml"

rm -rf "$dist"
mkdir -p "$dist/pkg" "$dist/vendor"
wasm-bindgen --target web --no-typescript --out-dir "$dist/pkg" \
  "$root/target/wasm32-unknown-unknown/release/amc_wasm.wasm"

# The page needs only its runtime packages (the tests install playwright-core too).
[ -d node_modules/mediabunny ] || npm ci --omit=dev --no-audit --no-fund
cp node_modules/mediabunny/dist/bundles/mediabunny.min.mjs "$dist/vendor/mediabunny.mjs"
# The page: index.html, style.css, main.js and the ES modules it imports, worker.js (and the bench page).
cp src/*.html src/*.js src/*.css "$dist/"
echo "built $dist ($(du -sh "$dist" | cut -f1))" >&2
