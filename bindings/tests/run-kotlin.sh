#!/usr/bin/env bash
# Takes monotrack-ffi from the workspace's test build, generates the Kotlin bindings (uniffi library mode), compiles
# them with the JVM tests in bindings/tests/kotlin, runs the tests on the JVM through JNA, then
# replays the recordings the tests made (RecordingTest.kt) with `monotrack replay` of the same build,
# each of which must find every frame identical (counted as one test each), prints
# "N passed, N failed" and exits non-zero on any failure. Installs what it needs:
# kotlinc (npm package kotlin-compiler), JNA (Debian libjna-java), JUnit 5 console (Debian junit5).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
cd "$ROOT"
WORK=${KOTLIN_WORK_DIR:-$ROOT/target/kotlin-tests}
TOOLS=${KOTLIN_TOOLS_DIR:-$ROOT/target/kotlin-tools}
mkdir -p "$WORK" "$TOOLS"

need_apt=()
[ -f /usr/share/java/jna.jar ] || need_apt+=(libjna-java)
[ -f /usr/share/java/junit-platform-console-standalone.jar ] || need_apt+=(junit5)
command -v java >/dev/null || need_apt+=(default-jdk-headless)
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "installing ${need_apt[*]}"
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}") >/dev/null
fi
KOTLINC="$TOOLS/node_modules/kotlin-compiler/bin/kotlinc"
if [ ! -x "$KOTLINC" ]; then
  echo "installing kotlin-compiler (npm)"
  (cd "$TOOLS" && npm install --silent --no-audit --no-fund kotlin-compiler@2 >/dev/null)
fi
KOTLIN_LIB="$TOOLS/node_modules/kotlin-compiler/lib"

echo "== the FFI library and uniffi-bindgen of the workspace's test build"
# The same cargo call as ./test-all.sh's build (one feature set): after it, a no-op that lists
# the artifacts; run alone, it builds them.
cargo test -q --workspace --no-run --message-format=json-render-diagnostics |
  python3 "$ROOT/tests/scripts/cargo_artifacts.py" > "$WORK/artifacts.txt"
LIB=$(awk '$1 == "cdylib" && $2 == "monotrack_ffi" {print $4}' "$WORK/artifacts.txt" | head -1)
BINDGEN=$(awk '$1 == "bin" && $2 == "uniffi-bindgen" {print $4}' "$WORK/artifacts.txt" | head -1)
MONOTRACK=$(awk '$1 == "bin" && $2 == "monotrack" {print $4}' "$WORK/artifacts.txt" | head -1)
if [ -z "$LIB" ] || [ ! -f "$LIB" ] || [ -z "$BINDGEN" ] || [ -z "$MONOTRACK" ]; then
  echo "the test build made no FFI library, uniffi-bindgen or monotrack"; echo "kotlin: 0 passed, 1 failed"; exit 1
fi
LIBDIR=$(dirname "$LIB")

echo "== generating Kotlin"
rm -rf "$WORK/gen" && mkdir -p "$WORK/gen"
"$BINDGEN" generate --library "$LIB" --language kotlin --out-dir "$WORK/gen" --no-format

JNA=/usr/share/java/jna.jar
JUNIT=/usr/share/java/junit-platform-console-standalone.jar
echo "== compiling Kotlin"
# From a clean folder, so classes of a previous run can never stand in for a failed compile.
rm -rf "$WORK/classes"
set +e
"$KOTLINC" -jvm-target 17 -nowarn -cp "$JNA:$JUNIT:$KOTLIN_LIB/kotlinx-coroutines-core-jvm.jar" \
  $(find "$WORK/gen" -name '*.kt') $(find "$ROOT/bindings/tests/kotlin" -name '*.kt') \
  $(find "$ROOT/android/monotrack/src/jvmMain" "$ROOT/android/monotrack/src/jvmTest" -name '*.kt') \
  $(find "$ROOT/samples/android-bench/src" -name 'BenchSummary*.kt') \
  -d "$WORK/classes" > "$WORK/kotlinc.log" 2>&1
krc=$?
set -e
grep -v '^warning' "$WORK/kotlinc.log" || true
if [ "$krc" -ne 0 ] || [ ! -d "$WORK/classes" ]; then
  echo "kotlinc failed (exit $krc)"; echo "kotlin: 0 passed, 1 failed"; exit 1
fi

echo "== running JVM tests"
RECORDINGS="$WORK/recordings"
rm -rf "$RECORDINGS" && mkdir -p "$RECORDINGS"
set +e
java -Djna.library.path="$LIBDIR" -Dmonotrack.root="$ROOT" -Dmonotrack.recordings="$RECORDINGS" \
  -jar "$JUNIT" --disable-banner --disable-ansi-colors --details=tree \
  --class-path "$WORK/classes:$JNA:$KOTLIN_LIB/kotlin-stdlib.jar:$KOTLIN_LIB/kotlinx-coroutines-core-jvm.jar" \
  --scan-class-path "$WORK/classes" > "$WORK/junit.log" 2>&1
rc=$?
set -e
cat "$WORK/junit.log"
passed=$(sed -n 's/.*\[ *\([0-9]*\) tests successful.*/\1/p' "$WORK/junit.log" | head -1)
failed=$(sed -n 's/.*\[ *\([0-9]*\) tests failed.*/\1/p' "$WORK/junit.log" | head -1)
passed=${passed:-0}; failed=${failed:-0}
[ "$rc" -ne 0 ] && [ "$failed" -eq 0 ] && failed=1

echo "== monotrack replay of the recordings the JVM tests made"
# shellcheck source=replay-recordings.sh
source "$(dirname "${BASH_SOURCE[0]}")/replay-recordings.sh"
replay_recordings kotlin-video kotlin-live kotlin-small
[ "$passed" -eq 0 ] && [ "$failed" -eq 0 ] && failed=1
echo "kotlin: $passed passed, $failed failed"
[ "$failed" -eq 0 ]
