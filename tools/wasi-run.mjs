#!/usr/bin/env node
// Runs a wasm32-wasip1 program (a Rust test binary) under Node's WASI, as a
// cargo runner: the core's unit tests built as WebAssembly with `simd128`
// exercise the browser's row kernels against the scalar reference, as the
// native tests do the AVX2 and AVX-512 ones.
//
//   CARGO_TARGET_WASM32_WASIP1_RUNNER="node tools/wasi-run.mjs" \
//   CARGO_TARGET_WASM32_WASIP1_RUSTFLAGS="-C target-feature=+simd128" \
//     cargo test --release -p amc-core --lib --target wasm32-wasip1
//
// The program sees no files (WASI_DIR=DIR preopens DIR as its working
// directory, e.g. for criterion's reports) and exits with its own status.
import { WASI } from 'node:wasi';
import { readFileSync } from 'node:fs';

const [file, ...args] = process.argv.slice(2);
if (!file) {
  console.error('usage: node tools/wasi-run.mjs PROGRAM.wasm [ARGS...]');
  process.exit(2);
}
process.removeAllListeners('warning'); // Node calls its WASI experimental.
const wasi = new WASI({
  version: 'preview1',
  args: [file, ...args],
  env: {},
  preopens: process.env.WASI_DIR ? { '.': process.env.WASI_DIR } : {},
  returnOnExit: true,
});
const module = await WebAssembly.compile(readFileSync(file));
const instance = await WebAssembly.instantiate(module, wasi.getImportObject());
process.exitCode = wasi.start(instance);
