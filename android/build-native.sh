#!/usr/bin/env bash
# Builds the monotrack native library for Android and generates its Kotlin bindings:
#   1. `cargo ndk` cross-compiles monotrack-ffi for arm64-v8a, armeabi-v7a and x86_64 into
#      android/monotrack/src/main/jniLibs/<abi>/libmonotrack_ffi.so (16 KB page-aligned, see
#      android/cargo-config.toml);
#   2. uniffi-bindgen (library mode, the workspace's monotrack-uniffi-bindgen) reads the bindings'
#      metadata from the arm64 library and writes the Kotlin package io.monotrack into
#      android/monotrack/build/generated/uniffi (not committed; the Gradle module compiles it).
#   3. checks that every 64-bit library's LOAD segments are 16 KB aligned (when llvm-readelf is found).
#
# Needs: rustup, cargo-ndk (`cargo install cargo-ndk`), an Android NDK (ANDROID_NDK_HOME, or
# ANDROID_HOME/ndk/<version>; r26+ recommended). Run from anywhere; Gradle's :monotrack:buildNative
# task runs it before preBuild unless -Pmonotrack.skipNative=true.
# Environment: PROFILE (release), ABIS ("arm64-v8a armeabi-v7a x86_64"), MIN_SDK (24).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
# The Cargo profile per ABI: `release-small` for arm64-v8a, whose frames run no layer in tract
# (its size profile costs them nothing and saves 1.8 MB); `release` for the others, where tract
# still runs layers. PROFILE in the environment sets one profile for every ABI.
ABIS=${ABIS:-"arm64-v8a armeabi-v7a x86_64"}
profile_for() {
  if [ -n "${PROFILE:-}" ]; then echo "$PROFILE"
  elif [ "$1" = arm64-v8a ]; then echo release-small
  else echo release; fi
}
# Must equal minSdk in android/monotrack/build.gradle.kts (the NDK API level the library links against).
MIN_SDK=${MIN_SDK:-24}
JNI_DIR=android/monotrack/src/main/jniLibs
GEN_DIR=android/monotrack/build/generated/uniffi

die() { echo "build-native.sh: $*" >&2; exit 1; }

command -v cargo >/dev/null || die "cargo not found (install Rust with rustup)"
cargo ndk --version >/dev/null 2>&1 || die "cargo-ndk not found: cargo install cargo-ndk"
if [ -z "${ANDROID_NDK_HOME:-}" ] && [ -z "${ANDROID_NDK_ROOT:-}" ] && [ ! -d "${ANDROID_HOME:-/nonexistent}/ndk" ]; then
  die "no Android NDK: set ANDROID_NDK_HOME, or install one with sdkmanager 'ndk;27.2.12479018'"
fi

declare -A TRIPLE=([arm64-v8a]=aarch64-linux-android [armeabi-v7a]=armv7-linux-androideabi
                   [x86_64]=x86_64-linux-android [x86]=i686-linux-android)
for abi in $ABIS; do
  t=${TRIPLE[$abi]:-}; [ -n "$t" ] || die "unknown ABI $abi"
  rustup target list --installed | grep -qx "$t" || rustup target add "$t"
done

# One cargo ndk run per profile, with the ABIs that take it.
for profile in $(for abi in $ABIS; do profile_for "$abi"; done | sort -u); do
  targets=()
  for abi in $ABIS; do
    [ "$(profile_for "$abi")" = "$profile" ] && targets+=(-t "$abi")
  done
  echo "== cargo ndk (${targets[*]}, API $MIN_SDK, $profile)"
  cargo ndk --platform "$MIN_SDK" "${targets[@]}" -o "$JNI_DIR" \
    build --config android/cargo-config.toml --profile "$profile" -p monotrack-ffi --lib
done

first_abi=${ABIS%% *}
dir=$(profile_for "$first_abi"); [ "$dir" = dev ] && dir=debug
LIB="target/${TRIPLE[$first_abi]}/$dir/libmonotrack_ffi.so"
[ -f "$LIB" ] || die "expected $LIB after the build"

echo "== uniffi-bindgen (Kotlin) -> $GEN_DIR"
rm -rf "$GEN_DIR" && mkdir -p "$GEN_DIR"
cargo run -q -p monotrack-uniffi-bindgen --release -- generate --library "$LIB" \
  --language kotlin --out-dir "$GEN_DIR" --no-format

READELF=$(command -v llvm-readelf || true)
if [ -z "$READELF" ]; then
  for ndk in "${ANDROID_NDK_HOME:-}" "${ANDROID_NDK_ROOT:-}" "${ANDROID_HOME:-}"/ndk/*; do
    c=$(ls "$ndk"/toolchains/llvm/prebuilt/*/bin/llvm-readelf 2>/dev/null | head -1 || true)
    [ -n "$c" ] && { READELF=$c; break; }
  done
fi
if [ -n "$READELF" ]; then
  for abi in $ABIS; do
    case $abi in arm64-v8a|x86_64) ;; *) continue ;; esac
    so="$JNI_DIR/$abi/libmonotrack_ffi.so"
    # Every LOAD segment's alignment (last column) must be at least 2**14.
    for align in $("$READELF" -lW "$so" | awk '$1=="LOAD" {print $NF}'); do
      [ $((align)) -ge 16384 ] || die "$so has a LOAD segment aligned to $align, not 16 KB"
    done
    echo "$abi: 16 KB aligned, $(stat -c %s "$so" 2>/dev/null || stat -f %z "$so") bytes"
  done
else
  echo "llvm-readelf not found: 16 KB alignment not checked"
fi
echo "done: $JNI_DIR, $GEN_DIR"
