#!/usr/bin/env bash
# The 32-bit phones' side (armeabi-v7a): core's frame and kernel tests cross-compiled for
# armv7-unknown-linux-gnueabihf (32-bit usize, the same code as armv7-linux-androideabi) and run
# under qemu. They hold the size arithmetic of frame descriptions (checked in u64, the same bounds
# on every target: image::frame's tests) and the portable kernels to the same results as on 64-bit
# targets. Installs Debian's qemu-user and armhf cross gcc and the rust target when missing.
set -euo pipefail
cd "$(dirname "$0")/.."
T=armv7-unknown-linux-gnueabihf
if ! command -v qemu-arm >/dev/null || ! command -v arm-linux-gnueabihf-gcc >/dev/null; then
  echo "installing qemu-user and the armhf cross gcc"
  (apt-get update -qq && apt-get install -y -qq qemu-user gcc-arm-linux-gnueabihf libc6-dev-armhf-cross) >/dev/null
fi
rustup target list --installed | grep -qx "$T" || rustup target add "$T"
export CARGO_TARGET_ARMV7_UNKNOWN_LINUX_GNUEABIHF_LINKER=arm-linux-gnueabihf-gcc
export CARGO_TARGET_ARMV7_UNKNOWN_LINUX_GNUEABIHF_RUNNER="qemu-arm -L /usr/arm-linux-gnueabihf"
export CC_armv7_unknown_linux_gnueabihf=arm-linux-gnueabihf-gcc
export AR_armv7_unknown_linux_gnueabihf=arm-linux-gnueabihf-ar
echo "== armv7 under $(qemu-arm --version | head -n 1)"
cargo test --profile qemu-armv7 --target "$T" -p monotrack-core --lib -- image:: kernels:: camera::
