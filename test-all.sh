#!/usr/bin/env bash
# Runs every test of the project: the Rust workspace (unit, golden, cross-crate tests; the ones that
# need ../shared/data skip with a printed reason when it is absent), then the Kotlin bindings on the
# JVM (bindings/tests/run-kotlin.sh installs kotlinc, JNA and JUnit 5 when missing), then the
# generated Swift against its committed snapshot (bindings/tests/check-swift.sh).
set -euo pipefail
cd "$(dirname "$0")"
# The body tests convert ../shared/data/body with numpy + h5py (tests/scripts/body_data.py).
python3 -c "import numpy, h5py" 2>/dev/null || python3 -m pip install --quiet numpy h5py \
  || echo "numpy/h5py unavailable: the body data tests will skip"
cargo test --workspace
bash bindings/tests/run-kotlin.sh
bash bindings/tests/check-swift.sh
