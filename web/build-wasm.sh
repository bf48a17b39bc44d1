#!/usr/bin/env bash
# Builds web/dist/psao.wasm: crates/psao-wasm (the compact decoder and client state behind a
# C ABI) for wasm32-unknown-unknown, optimised for size, without debug info or symbols, with
# the checkout and Cargo's home remapped so that a clone in another folder (same Rust
# toolchain and Cargo.lock) gets the same bytes. Its own target dir (target/wasm) keeps these
# flags from invalidating the native build. Needs `rustup target add wasm32-unknown-unknown`.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cargo_home=${CARGO_HOME:-$HOME/.cargo}
export RUSTFLAGS="--remap-path-prefix=$root=/psao --remap-path-prefix=$cargo_home=/cargo -C strip=symbols"
export CARGO_PROFILE_RELEASE_DEBUG=0
export CARGO_PROFILE_RELEASE_LTO=true
export CARGO_PROFILE_RELEASE_CODEGEN_UNITS=1
export CARGO_PROFILE_RELEASE_OPT_LEVEL=3
cd "$root"
cargo build --release --locked --target wasm32-unknown-unknown -p psao-wasm --target-dir target/wasm
cp target/wasm/wasm32-unknown-unknown/release/psao_wasm.wasm web/dist/psao.wasm
ls -l web/dist/psao.wasm
