#!/usr/bin/env bash
# Runs every test of the project from one build: the Rust workspace (unit, golden, cross-crate and
# CLI tests, the committed fuzz corpora), the kernels and the M3 golden cases a second time on the
# portable path (MONOTRACK_KERNELS=portable: the choices an aarch64 phone makes; the same test
# executables, run again), then the generated Kotlin on the
# JVM (bindings/tests/run-kotlin.sh, against the FFI library this build made), the generated Swift
# with ios/'s wrappers and XCTests on Linux (bindings/tests/run-swift.sh, against the same library;
# its first run makes a Debian trixie root with Swift in target/swift-root), and the docs' generated
# tables against the metrics files they are written from (tests/scripts/docs_tables.py). Ends with a summary:
# how many tests passed, failed and were ignored, and why. Tests that need ../shared/data are
# ignored, with that reason, where it is absent (a fresh clone); where it is present none may be.
# tests/aarch64.sh and tests/armv7.sh run tests on the phones' instruction sets under qemu.
set -uo pipefail
cd "$(dirname "$0")"
start=$(date +%s)
LOGS=target/test-all
mkdir -p "$LOGS"
# The body tests convert ../shared/data/body with numpy + h5py (tests/scripts/body_data.py).
python3 -c "import numpy, h5py" 2>/dev/null || python3 -m pip install --quiet numpy h5py \
  || echo "numpy/h5py could not be installed: the body data tests will fail"

echo "== building every test (once: every run below reuses this build)"
cargo test --workspace --no-run --message-format=json-render-diagnostics > "$LOGS/artifacts.json" ||
  { echo "the test build failed"; exit 1; }
python3 tests/scripts/cargo_artifacts.py < "$LOGS/artifacts.json" > "$LOGS/artifacts.txt"
built=$(date +%s)

echo "== the Rust tests"
cargo test --workspace --no-fail-fast 2>&1 | tee "$LOGS/rust.log"
rust_rc=${PIPESTATUS[0]}

echo "== the kernels and M3's golden cases on the portable path (MONOTRACK_KERNELS=portable)"
exe() { awk -v t="$1" -v k="$2" '$1 == "test" && $2 == t && $3 == k {print $4}' "$LOGS/artifacts.txt"; }
portable_rc=0
core_tests=$(exe monotrack_core lib) golden=$(exe m3_golden test)
if [ -z "$core_tests" ] || [ -z "$golden" ]; then
  echo "the core unit tests or m3_golden were not built"; portable_rc=1; : > "$LOGS/portable.log"
else
  # As cargo runs them: from their package's folder.
  # Less the tests of the native x86-64 forms (named the_avx…), which the portable path does not
  # run (libtest reports them as filtered out).
  (cd core && MONOTRACK_KERNELS=portable "$core_tests" --skip the_avx) 2>&1 | tee "$LOGS/portable.log"
  [ "${PIPESTATUS[0]}" -eq 0 ] || portable_rc=1
  # --include-ignored: the test that compares the portable path is ignored on the native run.
  (cd tests && MONOTRACK_KERNELS=portable "$golden" --include-ignored) 2>&1 | tee -a "$LOGS/portable.log"
  [ "${PIPESTATUS[0]}" -eq 0 ] || portable_rc=1
fi

echo "== the Kotlin bindings on the JVM"
bash bindings/tests/run-kotlin.sh 2>&1 | tee "$LOGS/kotlin.log"
kotlin_rc=${PIPESTATUS[0]}

echo "== the Swift bindings and ios/ wrappers on Linux (swift test)"
bash bindings/tests/run-swift.sh 2>&1 | tee "$LOGS/swift.log"
swift_rc=${PIPESTATUS[0]}

echo "== the docs' generated tables against their metrics files (tests/scripts/docs_tables.py)"
{ python3 tests/scripts/docs_tables.py --check && python3 tests/scripts/docs_tables.py --self-test; } \
  2>&1 | tee "$LOGS/docs.log"
docs_rc=${PIPESTATUS[0]}

end=$(date +%s)
data=${MONOTRACK_SHARED_DATA:-../shared/data}
strict=(); [ -d "$data" ] && strict=(--no-data-ignored)
echo
echo "== summary: $(( (end - start) / 60 )) min $(( (end - start) % 60 )) s ($(( (built - start) / 60 )) min $(( (built - start) % 60 )) s of it building); shared data: $([ -d "$data" ] && echo "present ($data)" || echo "absent (the tests that need it are ignored)")"
python3 tests/scripts/test_summary.py "native=$LOGS/rust.log" "portable path=$LOGS/portable.log" "${strict[@]}"
summary_rc=$?
grep -h '^kotlin: ' "$LOGS/kotlin.log" | tail -1 || echo "kotlin: no result line"
grep -h '^swift: ' "$LOGS/swift.log" | tail -1 || echo "swift: no result line"
grep -h -E '^docs( self-test)?: ' "$LOGS/docs.log" || echo "docs: no result line"
status=0
for v in rust_rc portable_rc kotlin_rc swift_rc docs_rc summary_rc; do
  [ "${!v}" -eq 0 ] || { echo "FAILED: ${v%_rc}"; status=1; }
done
[ "$status" -eq 0 ] && echo "all passed"
exit "$status"
