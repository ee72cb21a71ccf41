#!/usr/bin/env bash
# The generated Swift (uniffi library mode, the same call as ios/build-xcframework.sh) against the
# committed snapshot in bindings/tests/swift-golden/: the check itself is the Rust test
# `bindings/uniffi-bindgen/tests/generate.rs` (part of ./test-all.sh); this script runs it alone,
# or with --update records a reviewed change of the Swift API surface (or of the C header the
# XCFramework ships) as the new snapshot. It uses the FFI library and uniffi-bindgen of the
# workspace's test build (a no-op after ./test-all.sh).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
cd "$ROOT"
GOLDEN="$ROOT/bindings/tests/swift-golden"
if [ "${1:-}" != "--update" ]; then
  exec cargo test --workspace --test generate
fi
OUT="$ROOT/target/swift-gen"
cargo test -q --workspace --no-run --message-format=json-render-diagnostics |
  python3 "$ROOT/tests/scripts/cargo_artifacts.py" > "$ROOT/target/artifacts-swift.txt"
LIB=$(awk '$1 == "cdylib" && $2 == "monotrack_ffi" {print $4}' "$ROOT/target/artifacts-swift.txt" | head -1)
BINDGEN=$(awk '$1 == "bin" && $2 == "uniffi-bindgen" {print $4}' "$ROOT/target/artifacts-swift.txt" | head -1)
[ -n "$LIB" ] && [ -n "$BINDGEN" ] || { echo "the test build made no FFI library or uniffi-bindgen"; exit 1; }
rm -rf "$OUT" && mkdir -p "$OUT"
"$BINDGEN" generate --library "$LIB" --language swift --out-dir "$OUT" --no-format
rm -rf "$GOLDEN" && mkdir -p "$GOLDEN" && cp "$OUT"/* "$GOLDEN"/
echo "swift snapshot updated: $(ls "$GOLDEN" | tr '\n' ' ')"
