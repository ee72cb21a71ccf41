#!/usr/bin/env bash
# Runs every test of the project: the Rust workspace (unit, golden, cross-crate tests; the ones that
# need ../shared/data skip with a printed reason when it is absent), then the Kotlin bindings on the
# JVM (bindings/tests/run-kotlin.sh installs kotlinc, JNA and JUnit 5 when missing), then the
# generated Swift against its committed snapshot (bindings/tests/check-swift.sh). The kernels and
# the M3 golden cases run a second time on the portable path (MONOTRACK_KERNELS=portable: what
# an aarch64 phone computes); tests/aarch64.sh runs them on the phone's instruction set itself.
set -euo pipefail
cd "$(dirname "$0")"
# The body tests convert ../shared/data/body with numpy + h5py (tests/scripts/body_data.py).
python3 -c "import numpy, h5py" 2>/dev/null || python3 -m pip install --quiet numpy h5py \
  || echo "numpy/h5py unavailable: the body data tests will skip"
cargo test --workspace
MONOTRACK_KERNELS=portable cargo test -p monotrack-core --lib
MONOTRACK_KERNELS=portable cargo test -p monotrack-tests --test m3_golden
bash bindings/tests/run-kotlin.sh
bash bindings/tests/check-swift.sh
