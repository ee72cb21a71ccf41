#!/usr/bin/env bash
# Takes monotrack-ffi from the workspace's test build, generates the Swift bindings (uniffi library
# mode, as ios/build-xcframework.sh does), builds them with every wrapper file of
# ios/Sources/Monotrack (their Apple-only parts sit behind `#if canImport(...)`) and the XCTest
# target ios/Tests/MonotrackTests in a Linux SwiftPM package (target/swift-tests/pkg), runs
# `swift test` against the real library, then replays the recordings the tests made
# (RecordingTests.swift) with `monotrack replay` of the same build on the host, each of which must
# find every frame identical (counted as one test each), prints "swift: N passed, N failed" and
# exits non-zero on any failure.
#
# Swift for Linux comes from Debian trixie (package swiftlang): the script makes a trixie root with
# debootstrap in target/swift-root (once: about 3 min and 2.6 GB; reused while its marker file says
# it is complete with the same packages), mounts /proc, /dev, /sys and binds the repository at its
# own path there (unmounted on exit), and runs swift inside it with chroot. Needs root, debootstrap
# (installed with apt when missing) and the Debian mirror (DEBIAN_MIRROR, deb.debian.org by default).
# The host's library (glibc 2.36) loads under trixie's newer glibc. Logs: target/test-all/swift-*.log.
# `run-swift.sh --remove-root` deletes the root (CI, for the disk), refusing while anything is
# mounted in it.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
cd "$ROOT"
WORK=${SWIFT_WORK_DIR:-$ROOT/target/swift-tests}
LOGS=${SWIFT_LOG_DIR:-$ROOT/target/test-all}
SYSROOT=${SWIFT_ROOT_DIR:-$ROOT/target/swift-root}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
# libc6-dev: without it the link fails (crti.o); libjpeg-turbo-progs: djpeg decodes the sample
# image (Foundation on Linux decodes no images).
PKGS=(swiftlang libc6-dev libstdc++-14-dev libjpeg-turbo-progs)
MARKER="$SYSROOT/.monotrack-swift-root"
mkdir -p "$WORK" "$LOGS"
fail() { echo "$1"; echo "swift: 0 passed, 1 failed"; exit 1; }
[ "$(id -u)" -eq 0 ] || fail "needs root (debootstrap, mount, chroot)"

# One run at a time: a second run's exit would unmount what the first one uses.
exec 9> "$WORK/.lock"
flock 9

MOUNTS=()
cleanup() {
  local i
  for ((i = ${#MOUNTS[@]} - 1; i >= 0; i--)); do
    umount "${MOUNTS[$i]}" 2>/dev/null || umount -l "${MOUNTS[$i]}" 2>/dev/null || true
  done
  MOUNTS=()
}
trap cleanup EXIT
trap 'exit 130' INT TERM
# Mounts $2 (a path inside the root) from $1 (a host path, or "proc").
mount_in() {
  local dir="$SYSROOT$2"
  mkdir -p "$dir"
  mountpoint -q "$dir" && return 0
  if [ "$1" = proc ]; then mount -t proc proc "$dir"; else mount --bind "$1" "$dir"; fi
  MOUNTS+=("$dir")
}
# Nothing may stay mounted below the root when it is removed: rm would descend into it.
mounted_below() { awk -v r="$SYSROOT/" 'index($2, r) == 1 {print $2}' /proc/self/mounts; }

if [ "${1:-}" = --remove-root ]; then
  [ -z "$(mounted_below)" ] || { echo "still mounted below $SYSROOT: $(mounted_below | tr '\n' ' ')"; exit 1; }
  rm -rf --one-file-system "$SYSROOT"
  exit 0
fi

want="trixie ${PKGS[*]}"
if [ ! -f "$MARKER" ] || [ "$(cat "$MARKER")" != "$want" ]; then
  t0=$(date +%s)
  echo "== making the trixie root with Swift in $SYSROOT (once)"
  [ -z "$(mounted_below)" ] || fail "still mounted below $SYSROOT: $(mounted_below | tr '\n' ' ')"
  command -v debootstrap >/dev/null || {
    echo "installing debootstrap"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap) >/dev/null
  }
  rm -rf --one-file-system "$SYSROOT"
  debootstrap --variant=minbase trixie "$SYSROOT" "$MIRROR" > "$LOGS/swift-debootstrap.log" 2>&1 ||
    { tail -20 "$LOGS/swift-debootstrap.log"; fail "debootstrap failed (log: $LOGS/swift-debootstrap.log)"; }
  cp /etc/resolv.conf "$SYSROOT/etc/resolv.conf" 2>/dev/null || true
  mount_in proc /proc; mount_in /dev /dev; mount_in /sys /sys
  chroot "$SYSROOT" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin DEBIAN_FRONTEND=noninteractive \
    sh -c "apt-get update -qq && apt-get install -y -qq --no-install-recommends ${PKGS[*]} && apt-get clean" \
    > "$LOGS/swift-apt.log" 2>&1 || { tail -20 "$LOGS/swift-apt.log"; fail "installing Swift in the root failed (log: $LOGS/swift-apt.log)"; }
  cleanup
  echo "$want" > "$MARKER"
  echo "root made in $(( $(date +%s) - t0 )) s"
fi

echo "== the FFI library and uniffi-bindgen of the workspace's test build"
# The same cargo call as ./test-all.sh's build (one feature set): after it, a no-op that lists
# the artifacts; run alone, it builds them.
cargo test -q --workspace --no-run --message-format=json-render-diagnostics |
  python3 "$ROOT/tests/scripts/cargo_artifacts.py" > "$WORK/artifacts.txt" || fail "the test build failed"
LIB=$(awk '$1 == "cdylib" && $2 == "monotrack_ffi" {print $4}' "$WORK/artifacts.txt" | head -1)
BINDGEN=$(awk '$1 == "bin" && $2 == "uniffi-bindgen" {print $4}' "$WORK/artifacts.txt" | head -1)
MONOTRACK=$(awk '$1 == "bin" && $2 == "monotrack" {print $4}' "$WORK/artifacts.txt" | head -1)
if [ -z "$LIB" ] || [ ! -f "$LIB" ] || [ -z "$BINDGEN" ] || [ -z "$MONOTRACK" ]; then
  fail "the test build made no FFI library, uniffi-bindgen or monotrack"
fi
LIBDIR=$(dirname "$LIB")
case "$LIBDIR" in "$ROOT"/*) ;; *) fail "the FFI library is outside the repository ($LIB): the root sees the repository only" ;; esac

echo "== generating Swift"
GEN="$WORK/gen"
rm -rf "$GEN" && mkdir -p "$GEN"
"$BINDGEN" generate --library "$LIB" --language swift --out-dir "$GEN" --no-format
for f in MonotrackFFI.swift MonotrackFFIFFI.h MonotrackFFIFFI.modulemap; do
  [ -f "$GEN/$f" ] || fail "uniffi-bindgen wrote no $f"
done

# The package: the C module (generated header and module map), the generated Swift, and the
# wrapper and test folders of ios/ through links (nothing copied that could go stale).
# Files are replaced only when they changed, so that a warm run rebuilds only what did.
PKG="$WORK/pkg"
mkdir -p "$PKG/Sources/MonotrackFFIFFI" "$PKG/Sources/MonotrackFFI" "$PKG/Tests"
put() { cmp -s "$1" "$2" || cp "$1" "$2"; }
put "$GEN/MonotrackFFIFFI.h" "$PKG/Sources/MonotrackFFIFFI/MonotrackFFIFFI.h"
put "$GEN/MonotrackFFIFFI.modulemap" "$PKG/Sources/MonotrackFFIFFI/module.modulemap"
put "$GEN/MonotrackFFI.swift" "$PKG/Sources/MonotrackFFI/MonotrackFFI.swift"
ln -sfn "$ROOT/ios/Sources/Monotrack" "$PKG/Sources/Monotrack"
ln -sfn "$ROOT/ios/Tests/MonotrackTests" "$PKG/Tests/MonotrackTests"
cat > "$GEN/Package.swift" <<EOF
// swift-tools-version:5.9
// Written by bindings/tests/run-swift.sh: ios/Package.swift for Linux, over the host library.
import PackageDescription

let package = Package(
    name: "Monotrack",
    targets: [
        .systemLibrary(name: "MonotrackFFIFFI", path: "Sources/MonotrackFFIFFI"),
        .target(
            name: "MonotrackFFI",
            dependencies: ["MonotrackFFIFFI"],
            path: "Sources/MonotrackFFI",
            linkerSettings: [
                .linkedLibrary("monotrack_ffi"),
                .unsafeFlags(["-L", "$LIBDIR", "-Xlinker", "-rpath", "-Xlinker", "$LIBDIR"]),
            ]
        ),
        .target(name: "Monotrack", dependencies: ["MonotrackFFI"], path: "Sources/Monotrack"),
        .testTarget(name: "MonotrackTests", dependencies: ["Monotrack", "MonotrackFFI"], path: "Tests/MonotrackTests"),
    ]
)
EOF
put "$GEN/Package.swift" "$PKG/Package.swift"

mount_in proc /proc; mount_in /dev /dev; mount_in /sys /sys; mount_in "$ROOT" "$ROOT"
# Inside the repository, so the root and the host see the same files.
RECORDINGS="$WORK/recordings"
rm -rf "$RECORDINGS" && mkdir -p "$RECORDINGS"
in_root() {
  chroot "$SYSROOT" /usr/bin/env -i HOME=/root LANG=C.UTF-8 \
    PATH=/usr/libexec/swift/bin:/usr/bin:/bin LD_LIBRARY_PATH="$LIBDIR" \
    MONOTRACK_ROOT="$ROOT" MONOTRACK_SAMPLE_PPM="$WORK/astronaut.ppm" \
    MONOTRACK_RECORDINGS="$RECORDINGS" "$@"
}
# The sample image as binary PPM (RGB), which the tests read where ImageIO is missing.
in_root djpeg -pnm -outfile "$WORK/astronaut.ppm" "$ROOT/samples/data/astronaut.jpg" ||
  fail "djpeg could not decode samples/data/astronaut.jpg"

echo "== swift build (the generated bindings, ios/Sources/Monotrack, ios/Tests/MonotrackTests)"
set +e
in_root sh -c "cd '$PKG' && swift build --build-tests" > "$LOGS/swift-build.log" 2>&1
brc=$?
set -e
grep -E 'error:|(Sources/Monotrack|Tests/MonotrackTests)/.*warning:' "$LOGS/swift-build.log" | sort -u || true
[ "$brc" -eq 0 ] || { tail -40 "$LOGS/swift-build.log"; fail "swift build failed (exit $brc; log: $LOGS/swift-build.log)"; }

echo "== swift test"
set +e
in_root sh -c "cd '$PKG' && swift test --skip-build" > "$LOGS/swift-test.log" 2>&1
rc=$?
set -e
cat "$LOGS/swift-test.log"
# XCTest's last summary ("Executed N tests, with M failures ...") counts failed assertions; the
# failed tests are its "Test Case '...' failed" lines.
total=$(sed -n 's/.*Executed \([0-9]*\) tests\{0,1\}, with [0-9]* failures\{0,1\}.*/\1/p' "$LOGS/swift-test.log" | tail -1)
total=${total:-0}
failed=$(grep -cE "^Test Case '.*' failed" "$LOGS/swift-test.log" || true)
passed=$(( total - failed ))
[ "$rc" -ne 0 ] && [ "$failed" -eq 0 ] && failed=1

echo "== monotrack replay of the recordings the XCTests made"
# shellcheck source=replay-recordings.sh
source "$(dirname "${BASH_SOURCE[0]}")/replay-recordings.sh"
replay_recordings swift-video swift-live swift-small
[ "$passed" -eq 0 ] && [ "$failed" -eq 0 ] && failed=1
echo "swift: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
