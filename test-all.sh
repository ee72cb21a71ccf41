#!/usr/bin/env bash
# Runs every test of the project: the Rust workspace (unit, golden, cross-crate tests; the ones that
# need ../shared/data skip with a printed reason when it is absent), then the Kotlin bindings on the
# JVM (bindings/tests/run-kotlin.sh installs kotlinc, JNA and JUnit 5 when missing).
set -euo pipefail
cd "$(dirname "$0")"
cargo test --workspace
bash bindings/tests/run-kotlin.sh
