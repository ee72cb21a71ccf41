#!/usr/bin/env bash
# Generates the Swift bindings (uniffi library mode, the same call as ios/build-xcframework.sh) and
# compares them with the committed snapshot in bindings/tests/swift-golden/. There is no Swift
# toolchain on the project's Linux machines, so the generated Swift is never compiled here: this
# check catches every change of the Swift API surface (and of the C header the XCFramework ships),
# which must then be reviewed and the snapshot updated with `--update`.
# Prints "swift: N passed, N failed" and exits non-zero on a mismatch.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
cd "$ROOT"
GOLDEN="$ROOT/bindings/tests/swift-golden"
OUT="$ROOT/target/swift-gen"
# The whole workspace, as `cargo test --workspace` built it: same feature set, so nothing rebuilds.
cargo build -q --workspace --lib
TARGET_DIR=$(cargo metadata -q --format-version 1 --no-deps |
  python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
rm -rf "$OUT" && mkdir -p "$OUT"
cargo run -q -p monotrack-uniffi-bindgen -- generate --library "$TARGET_DIR/debug/libmonotrack_ffi.so" \
  --language swift --out-dir "$OUT" --no-format
if [ "${1:-}" = "--update" ]; then
  rm -rf "$GOLDEN" && mkdir -p "$GOLDEN" && cp "$OUT"/* "$GOLDEN"/
  echo "swift snapshot updated: $(ls "$GOLDEN" | tr '\n' ' ')"
  exit 0
fi
passed=0; failed=0
for f in "$GOLDEN"/*; do
  name=$(basename "$f")
  if diff -u "$f" "$OUT/$name" > "$OUT/$name.diff"; then
    passed=$((passed + 1))
  else
    failed=$((failed + 1)); echo "MISMATCH $name (run bindings/tests/check-swift.sh --update after review):"
    head -40 "$OUT/$name.diff"
  fi
done
for f in "$OUT"/*.swift "$OUT"/*.h "$OUT"/*.modulemap; do
  [ -e "$GOLDEN/$(basename "$f")" ] || { failed=$((failed + 1)); echo "NEW FILE $(basename "$f") not in the snapshot"; }
done
# The public surface the iOS wrappers (ios/Sources/Monotrack) rely on must exist.
for sym in "func processFrame(" "func processImage(" "func reset()" "class FaceTracker" "func runBenchmark(" "enum MonotrackError"; do
  if grep -q "$sym" "$OUT"/*.swift; then passed=$((passed + 1)); else failed=$((failed + 1)); echo "MISSING in generated Swift: $sym"; fi
done
echo "swift: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
