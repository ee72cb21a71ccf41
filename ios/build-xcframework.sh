#!/usr/bin/env bash
# Builds MonotrackFFIFFI.xcframework (the Rust static library for iPhone and the Apple-silicon
# simulator) and the generated Swift bindings for the Swift package in this folder:
#   1. cargo builds monotrack-ffi (staticlib) for aarch64-apple-ios and aarch64-apple-ios-sim;
#   2. uniffi-bindgen (library mode, the workspace's monotrack-uniffi-bindgen) generates
#      MonotrackFFI.swift (→ Sources/MonotrackFFI/), MonotrackFFIFFI.h and MonotrackFFIFFI.modulemap;
#   3. xcodebuild -create-xcframework packs each slice's library with the header and module map
#      (renamed module.modulemap, the name Clang looks for) into ios/MonotrackFFIFFI.xcframework.
#
# Needs macOS with Xcode (xcodebuild, the iOS SDKs) and rustup; it stops with a message otherwise.
# Environment: PROFILE (release-small: both slices are aarch64, whose frames run no layer in tract,
# so the size profile costs them nothing), IPHONEOS_DEPLOYMENT_TARGET (13.0).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
PROFILE=${PROFILE:-release-small}
export IPHONEOS_DEPLOYMENT_TARGET=${IPHONEOS_DEPLOYMENT_TARGET:-13.0}
TARGETS=(aarch64-apple-ios aarch64-apple-ios-sim)
OUT=ios/MonotrackFFIFFI.xcframework
GEN=ios/build/generated
SWIFT_DIR=ios/Sources/MonotrackFFI

die() { echo "build-xcframework.sh: $*" >&2; exit 1; }

[ "$(uname -s)" = Darwin ] || die "needs macOS with Xcode (found $(uname -s)); build the xcframework on a Mac"
command -v xcodebuild >/dev/null || die "xcodebuild not found: install Xcode and run 'xcode-select -s /Applications/Xcode.app'"
xcrun --sdk iphoneos --show-sdk-path >/dev/null 2>&1 || die "no iphoneos SDK: install Xcode (not only the Command Line Tools)"
command -v cargo >/dev/null || die "cargo not found (install Rust with rustup)"

for t in "${TARGETS[@]}"; do
  rustup target list --installed | grep -qx "$t" || rustup target add "$t"
done

dir=$PROFILE; [ "$PROFILE" = dev ] && dir=debug
for t in "${TARGETS[@]}"; do
  echo "== cargo rustc --crate-type staticlib $t ($PROFILE)"
  cargo rustc -p monotrack-ffi --lib --profile "$PROFILE" --target "$t" --crate-type staticlib
done
DEVICE_LIB="target/aarch64-apple-ios/$dir/libmonotrack_ffi.a"
SIM_LIB="target/aarch64-apple-ios-sim/$dir/libmonotrack_ffi.a"

echo "== uniffi-bindgen (Swift)"
rm -rf "$GEN" && mkdir -p "$GEN/headers"
cargo run -q -p monotrack-uniffi-bindgen --release -- generate --library "$DEVICE_LIB" \
  --language swift --out-dir "$GEN"
[ -f "$GEN/MonotrackFFI.swift" ] || die "uniffi-bindgen wrote no MonotrackFFI.swift (check bindings/uniffi.toml)"
cp "$GEN/MonotrackFFIFFI.h" "$GEN/headers/"
cp "$GEN/MonotrackFFIFFI.modulemap" "$GEN/headers/module.modulemap"
mkdir -p "$SWIFT_DIR"
cp "$GEN/MonotrackFFI.swift" "$SWIFT_DIR/"

echo "== xcodebuild -create-xcframework -> $OUT"
rm -rf "$OUT"
xcodebuild -create-xcframework \
  -library "$DEVICE_LIB" -headers "$GEN/headers" \
  -library "$SIM_LIB" -headers "$GEN/headers" \
  -output "$OUT"
for lib in "$DEVICE_LIB" "$SIM_LIB"; do
  echo "$lib: $(stat -f %z "$lib") bytes"
done
echo "done: $OUT, $SWIFT_DIR/MonotrackFFI.swift"
