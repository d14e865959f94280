#!/usr/bin/env bash
# Fetches tinybvh's single header (version 1.6.8, as vendored by the `tinybvh-rs` crate
# 0.1.0-beta.3 on crates.io) into target/tinybvh/ for the benches' `tinybvh` feature, and prints
# the variable to export:
#   bash benches/peers/tinybvh_fetch.sh && export TINYBVH_DIR=$PWD/target/tinybvh
#   cargo bench --features embree,tinybvh --bench trace -- --noplot
set -euo pipefail
cd "$(dirname "$0")/../.."
work=target/tinybvh-fetch
mkdir -p "$work/src" target/tinybvh
cat > "$work/Cargo.toml" <<'TOML'
[package]
name = "tinybvh-fetch"
version = "0.0.0"
edition = "2021"
publish = false
[workspace]
[dependencies]
tinybvh-rs = "=0.1.0-beta.3"
TOML
echo "fn main() {}" > "$work/src/main.rs"
cargo fetch --manifest-path "$work/Cargo.toml" >/dev/null
header=$(find "${CARGO_HOME:-$HOME/.cargo}/registry/src" -path "*tinybvh-rs-0.1.0-beta.3/ffi/tinybvh/tiny_bvh.h" | head -n 1)
[ -n "$header" ] || { echo "tiny_bvh.h not found in the cargo registry" >&2; exit 1; }
cp "$header" target/tinybvh/tiny_bvh.h
grep -q "TINY_BVH_VERSION_MINOR	6" target/tinybvh/tiny_bvh.h || echo "warning: not tinybvh 1.6" >&2
echo "export TINYBVH_DIR=$PWD/target/tinybvh"
