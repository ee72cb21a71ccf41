#!/usr/bin/env bash
# Runs the phone's instruction set here: the tests cross-compiled for aarch64-unknown-linux-gnu (the
# ISA and `cfg(target_arch = "aarch64")` code of aarch64-linux-android and aarch64-apple-ios: NEON
# kernels, tract's arm64 kernels) and run under qemu user-mode emulation. Installs what it needs
# (Debian's qemu-user and aarch64 cross gcc, the rust target). Emulated time is not phone time:
# this checks correctness; speed is judged with `MONOTRACK_KERNELS=portable` on the host.
#
# What runs (the rest of the workspace's tests are architecture-neutral Rust, run on the host):
# core's unit tests (every kernel against its portable reference, the M3 and detector graphs),
# the M3 golden cases against the Python reference and against the recorded x86-64 outputs, the
# tracker on a synthetic clip with the shipped models (quality bounds), the fit tests, the FFI
# input fuzz test, record and replay; then the recording that record_replay's test made here (the
# NEON path) must replay on this host with `monotrack replay` (which picks the portable path) with
# every frame identical. That host CLI is $MONOTRACK_HOST_CLI where set (CI passes the one its
# test build made), else built here.
set -euo pipefail
cd "$(dirname "$0")/.."
T=aarch64-unknown-linux-gnu
if ! command -v qemu-aarch64 >/dev/null || ! command -v aarch64-linux-gnu-gcc >/dev/null; then
  echo "installing qemu-user and the aarch64 cross gcc"
  (apt-get update -qq && apt-get install -y -qq qemu-user gcc-aarch64-linux-gnu libc6-dev-arm64-cross) >/dev/null
fi
rustup target list --installed | grep -qx "$T" || rustup target add "$T"
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu"
export CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc
export AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar
echo "== aarch64 under $(qemu-aarch64 --version | head -n 1)"
# qemu runs the networks about a thousand times slower than the host: with MONOTRACK_EMULATED
# (read by tests/build.rs) the tracker's model tests take shorter clips, and the ones that track
# 360 frames or more are reported as ignored with that reason; track_synthetic (oracle
# landmarks: NCC, flow filter and fit, portable code whose kernels the unit tests cover) runs on
# the host only. One cargo call, so that every crate is built once with one feature set.
REC=$PWD/target/aarch64-recording
rm -rf "$REC" && mkdir -p "$REC"
MONOTRACK_EMULATED=1 MONOTRACK_RECORDING_OUT="$REC" cargo test --profile qemu --no-fail-fast --target "$T" \
  -p monotrack-core -p monotrack-tests -p monotrack-ffi --lib \
  --test m3_golden --test track_models --test fit_synthetic --test fit_real --test fuzz_inputs \
  --test record_replay

echo "== a recording made on aarch64 replays bit for bit on this host's portable path"
host=${MONOTRACK_HOST_CLI:-}
if [ -z "$host" ] || [ ! -x "$host" ]; then
  cargo build -q -p monotrack-cli
  host=target/debug/monotrack
fi
# The replay check the Kotlin and Swift runs use: every frame identical, at least one frame.
# shellcheck source=../bindings/tests/replay-recordings.sh
source bindings/tests/replay-recordings.sh
MONOTRACK=$host RECORDINGS=$REC passed=0 failed=0
replay_recordings record_replay
[ "$failed" -eq 0 ] && [ "$passed" -eq 1 ] &&
  grep -q '^monotrack: 8 of 8 frames identical' "$REC/record_replay.log" ||
  { echo "the aarch64 recording did not replay identically"; exit 1; }
