#!/usr/bin/env bash
# What an app adds per ABI: the monotrack-ffi shared library (models inside) built for aarch64,
# stripped. There is no Android NDK here, so the library is linked for aarch64-unknown-linux-gnu
# (the same code as aarch64-linux-android, another libc) as a proxy, by the NDK's linker (LLVM lld,
# driven by clang) with the Android build's flags from android/cargo-config.toml: 16 KB page
# alignment and packed relocations. (A library linked this way is measured, not loaded: glibc's
# loader does not read Android's packed relocations; the tests under qemu link the usual way.)
# Prints the stripped and gzipped sizes, the LOAD segments' alignment and the share of each crate
# in the code and data (from the unstripped symbol sizes).
# PROFILE (default release-small, the profile the arm64 builds ship: tract and ndarray built for
# size; `release` for comparison) picks the cargo profile; extra cargo arguments pass through.
# Fails when a LOAD segment is aligned below 16 KB (Google Play requires 16 KB pages for apps that
# target Android 15), and, where MAX_STRIPPED_BYTES / MAX_GZIPPED_BYTES are set (CI), when the
# library is larger than that budget.
set -euo pipefail
cd "$(dirname "$0")/.."
T=aarch64-unknown-linux-gnu
PROFILE=${PROFILE:-release-small}
if ! command -v aarch64-linux-gnu-gcc >/dev/null; then
  echo "installing the aarch64 cross gcc"
  (apt-get update -qq && apt-get install -y -qq gcc-aarch64-linux-gnu libc6-dev-arm64-cross) >/dev/null
fi
if ! command -v ld.lld >/dev/null || ! command -v clang >/dev/null; then
  echo "installing clang and lld (the NDK's compiler driver and linker)"
  (apt-get update -qq && apt-get install -y -qq clang lld) >/dev/null
fi
rustup target list --installed | grep -qx "$T" || rustup target add "$T"
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=clang
export CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc
export AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar
cargo rustc -p monotrack-ffi --lib --profile "$PROFILE" --target "$T" --crate-type cdylib "$@" \
  -- -C link-arg=--target=aarch64-linux-gnu -C link-arg=-fuse-ld=lld \
  -C link-arg=-Wl,-z,max-page-size=16384 -C link-arg=-Wl,--pack-dyn-relocs=android
tdir=${CARGO_TARGET_DIR:-target}
dir="$tdir/$T/$PROFILE"
[ "$PROFILE" = dev ] && dir="$tdir/$T/debug"
lib="$dir/libmonotrack_ffi.so"
out="$tdir/size-aarch64"; mkdir -p "$out"
aarch64-linux-gnu-strip -o "$out/libmonotrack_ffi.so" "$lib"
stripped=$(stat -c %s "$out/libmonotrack_ffi.so")
gz=$(gzip -9 -c "$out/libmonotrack_ffi.so" | wc -c)
awk -v p="$PROFILE" -v s="$stripped" -v g="$gz" 'BEGIN {
  printf "aarch64 libmonotrack_ffi.so (%s profile, stripped): %d bytes (%.1f MB), gzipped %d bytes (%.1f MB)\n", p, s, s / 1e6, g, g / 1e6 }'
echo "LOAD segment alignment:"
aligns=$(aarch64-linux-gnu-readelf -lW "$out/libmonotrack_ffi.so" | awk '$1 == "LOAD" {print $NF}')
echo "$aligns" | sed 's/^/  /'
status=0
for a in $aligns; do
  if [ $((a)) -lt 16384 ]; then echo "FAILED: a LOAD segment aligned to $a, below 16 KB"; status=1; fi
done
budget() { # name value limit
  [ -n "$3" ] || return 0
  if [ "$2" -gt "$3" ]; then
    echo "FAILED: $1 $2 bytes, over its budget of $3"; status=1
  else
    awk -v n="$1" -v v="$2" -v l="$3" 'BEGIN {printf "%s within its budget: %d of %d bytes (%.1f %% left)\n", n, v, l, 100 * (l - v) / l}'
  fi
}
budget "stripped library" "$stripped" "${MAX_STRIPPED_BYTES:-}"
budget "gzipped library" "$gz" "${MAX_GZIPPED_BYTES:-}"
echo "per crate (symbol bytes, unstripped; the rest is ELF tables and unnamed data):"
aarch64-linux-gnu-nm --size-sort -S -C -t d "$lib" | awk '
  { size = $2 + 0; name = $4; for (i = 5; i <= NF; i++) name = name " " $i
    sub(/^</, "", name); sub(/^_</, "", name)
    crate = name; sub(/::.*/, "", crate); sub(/ .*/, "", crate)
    if (crate !~ /^[a-z_][a-z0-9_]*$/) crate = "(other)"
    by[crate] += size; total += size }
  END { for (c in by) printf "%12d %5.1f%%  %s\n", by[c], 100 * by[c] / total, c }' | sort -rn | awk 'NR <= 15'
exit $status
