#!/usr/bin/env bash
# Cross-builds monotrack-ffi as a static library for the phone targets that this machine can build:
# aarch64-linux-android and aarch64-apple-ios. Installs what it needs (rust targets, clang for
# tract's assembly kernels), prints the library size per target, exits non-zero on any failure.
# `--check` (CI) runs clippy for those targets instead, in one cargo call: every build script
# (tract's assembly kernels compiled for each triple) and every cfg of the code, without the
# codegen and archiving that would repeat the aarch64 build of bindings/size-aarch64.sh (no code
# here or in core depends on target_os).
#
# There is no Android NDK or Apple SDK here: the C parts (tract's hand-written kernels) are compiled
# by plain clang for the target triple, which is enough for a staticlib; apps link it with their own
# NDK / Xcode toolchain. With an NDK present use `cargo ndk` instead (see android/README.md).
set -euo pipefail
cd "$(dirname "$0")/.."
TARGETS=${TARGETS:-"aarch64-linux-android aarch64-apple-ios"}
PROFILE=${PROFILE:-release-small}

if ! command -v clang >/dev/null; then
  echo "installing clang"; (apt-get update -qq && apt-get install -y -qq clang) >/dev/null
fi
for t in $TARGETS; do
  rustup target list --installed | grep -qx "$t" || rustup target add "$t"
done

export CC_aarch64_linux_android=clang
export AR_aarch64_linux_android=llvm-ar
export CFLAGS_aarch64_linux_android="--target=aarch64-linux-android21"
export CC_aarch64_apple_ios=clang
export AR_aarch64_apple_ios=llvm-ar
export CFLAGS_aarch64_apple_ios="--target=arm64-apple-ios13.0"
export SDKROOT=${SDKROOT:-/tmp}
command -v llvm-ar >/dev/null || { for v in 19 18 17 16 15 14; do
  if command -v llvm-ar-$v >/dev/null; then
    export AR_aarch64_linux_android=llvm-ar-$v AR_aarch64_apple_ios=llvm-ar-$v; break; fi; done; }

if [ "${1:-}" = "--check" ]; then
  args=(); for t in $TARGETS; do args+=(--target "$t"); done
  exec cargo clippy -p monotrack-ffi --lib "${args[@]}" -- -D warnings
fi

status=0
for t in $TARGETS; do
  echo "== $t"
  # Only the staticlib: the crate's cdylib would need the platform linker (NDK / Xcode).
  if cargo rustc -p monotrack-ffi --lib --profile "$PROFILE" --target "$t" --crate-type staticlib; then
    lib="target/$t/$PROFILE/libmonotrack_ffi.a"
    printf '%s: %s (%s bytes)\n' "$t" "$lib" "$(stat -c %s "$lib")"
  else
    echo "FAILED: $t"; status=1
  fi
done
exit $status
